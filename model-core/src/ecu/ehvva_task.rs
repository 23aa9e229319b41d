//! EHVVA task logic: crank/cam decoding, crank-angle event scheduling advanced by the
//! actuation delay td(Ph, T) (Li 2018, eq. (11), Fig. 4, Table 4), and the pilot solenoid's
//! peak-and-hold drive ([`crate::peak_hold`], Sec. 5.1), plus the lift valve (S1/S2 sleeve)
//! and snubber orifice switch valve outputs (Sec. 2).
//!
//! Why the advance: the valve starts to move td after the pilot command (the LPV model's
//! explicit delay, eq. (14)), so the command must be issued td earlier than the requested
//! crank angle: at engine speed ω the command angle is `θ_req − ω·td`. td depends on the
//! supply pressure and the oil temperature (3.2..4.2 ms at 5 MPa), i.e. 20..150 crank degrees
//! between 1000 and 6000 rpm: ignoring it would open the valve that much late. td ends where
//! the main valve's outlet pressure reaches the piston (eq. (11)); the valve's timing is read
//! where the lift passes 1 % (opening) and 99 % (closing) of the stroke (Sec. 2), 0.2..1.1 ms
//! of motion later. The advance therefore is td plus that motion
//! ([`ActuationDelay::event_advances_ms`], tabulated in [`EhvvaTables`]).
//!
//! The task is a synchronous state machine: the firmware feeds captured edges to
//! [`EhvvaTask::on_edge`] and calls [`EhvvaTask::step`] on every edge and at the returned
//! `wake_at_us` (the next command angle or the end of the peak phase), then applies the
//! outputs. All times are on the wrapping microsecond clock of [`super::board`].

use super::board::{elapsed_us, Edge, EdgeSource, SolenoidCmd};
use crate::ehvva::EhvvaTables;
use crate::peak_hold::{PeakHoldDriver, PeakHoldFault, PilotPhase, SolenoidParams};

/// Crank degrees per engine cycle (four-stroke).
pub const CYCLE_DEG: f32 = 720.0;

/// Wraps an angle into 0..720 crank degrees.
pub fn wrap_cycle_deg(a: f32) -> f32 {
    let r = a % CYCLE_DEG;
    if r < 0.0 {
        r + CYCLE_DEG
    } else {
        r
    }
}

/// The crank trigger wheel (n − m teeth) and the cam sync position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggerWheel {
    /// Tooth positions on the wheel, including the missing ones (60 for a 60-2 wheel).
    pub teeth_total: u8,
    /// Missing teeth forming the gap (2 for 60-2).
    pub teeth_missing: u8,
    /// Cycle angle of the first tooth after the gap in the first crank revolution.
    pub first_tooth_deg: f32,
    /// An interval longer than this many times the previous tooth period is the gap (the gap
    /// is (m + 1) periods; 2 sits between 1 and 3 with room for cranking accelerations).
    pub gap_ratio_min: f32,
}

impl TriggerWheel {
    /// 60-2 wheel, first tooth after the gap at cycle angle 0.
    pub const fn sixty_minus_two() -> Self {
        Self {
            teeth_total: 60,
            teeth_missing: 2,
            first_tooth_deg: 0.0,
            gap_ratio_min: 2.0,
        }
    }
    pub fn tooth_deg(&self) -> f32 {
        360.0 / self.teeth_total.max(1) as f32
    }
    fn teeth_present(&self) -> u8 {
        self.teeth_total.saturating_sub(self.teeth_missing).max(1)
    }
}

/// How much of the engine position is known.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SyncState {
    /// No gap seen yet (or lost).
    None,
    /// Gap seen: crank angle known modulo 360°.
    Crank,
    /// Cam seen: cycle angle (0..720) known.
    Full,
}

/// Tooth timestamps kept for the speed estimate.
const SPEED_HISTORY: usize = 9;
/// The speed estimate spans at least this long (1 µs capture quantization → < 0.2 %).
const SPEED_SPAN_MIN_US: u32 = 1000;

/// What the decoder knows now, for the other tasks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EngineSnapshot {
    pub sync: SyncState,
    pub rpm: f32,
    /// Synced and not yet above the run speed.
    pub cranking: bool,
    /// Cycle angle at which the last cam edge was seen (for the cam phase).
    pub cam_edge_deg: Option<f32>,
    /// Counts cam edges, so a reader sees a new measurement.
    pub cam_edge_seq: u32,
    /// The crank signal stopped while the engine was turning (cleared at the next sync).
    pub crank_lost: bool,
    /// A revolution pair passed without the cam edge (cleared at the next cam edge).
    pub cam_lost: bool,
}

/// Crank/cam decoder for an n−m wheel with one cam sync edge per cycle in the second crank
/// revolution (360..720).
#[derive(Clone, Debug)]
pub struct CrankDecoder {
    wheel: TriggerWheel,
    tooth_deg: f32,
    stall_timeout_us: u32,
    run_rpm: f32,
    sync: SyncState,
    last_tooth_us: Option<u32>,
    /// Last interval per tooth spacing, µs (gap detection).
    tooth_period_us: f32,
    have_period: bool,
    /// Index of the last tooth since the gap (0 = first tooth after the gap).
    tooth_index: u8,
    second_rev: bool,
    cam_seen_this_rev: bool,
    history_us: [u32; SPEED_HISTORY],
    history_spacing: [u8; SPEED_HISTORY],
    history_len: usize,
    deg_per_us: f32,
    running: bool,
    cam_edge_deg: Option<f32>,
    cam_edge_seq: u32,
    crank_lost: bool,
    cam_lost: bool,
    /// Gaps at the wrong tooth count or missing gaps (noise, damaged wheel).
    pub sync_errors: u32,
}

impl CrankDecoder {
    /// `stall_timeout_us`: no tooth for this long means the crank signal is lost;
    /// `run_rpm`: above it the engine counts as running (no longer cranking).
    pub fn new(wheel: TriggerWheel, stall_timeout_us: u32, run_rpm: f32) -> Self {
        Self {
            wheel,
            tooth_deg: wheel.tooth_deg(),
            stall_timeout_us,
            run_rpm,
            sync: SyncState::None,
            last_tooth_us: None,
            tooth_period_us: 0.0,
            have_period: false,
            tooth_index: 0,
            second_rev: false,
            cam_seen_this_rev: false,
            history_us: [0; SPEED_HISTORY],
            history_spacing: [0; SPEED_HISTORY],
            history_len: 0,
            deg_per_us: 0.0,
            running: false,
            cam_edge_deg: None,
            cam_edge_seq: 0,
            crank_lost: false,
            cam_lost: false,
            sync_errors: 0,
        }
    }

    /// Feeds one captured edge (edges must come in time order).
    pub fn on_edge(&mut self, edge: Edge) {
        match edge.source {
            EdgeSource::CrankTooth => self.on_tooth(edge.t_us),
            EdgeSource::CamSync => self.on_cam(edge.t_us),
        }
    }

    fn on_tooth(&mut self, t_us: u32) {
        let Some(prev) = self.last_tooth_us else {
            self.last_tooth_us = Some(t_us);
            self.push_history(t_us, 1);
            return;
        };
        let interval = elapsed_us(t_us, prev) as f32;
        if interval < 1.0 {
            return; // a bounce on the same tooth
        }
        let is_gap = self.have_period && interval > self.wheel.gap_ratio_min * self.tooth_period_us;
        let spacing;
        if is_gap {
            spacing = self.wheel.teeth_missing.saturating_add(1);
            self.on_gap();
        } else {
            spacing = 1;
            if self.sync != SyncState::None {
                self.tooth_index = self.tooth_index.saturating_add(1);
                if self.tooth_index >= self.wheel.teeth_present() {
                    // More teeth than the wheel has without a gap: position unknown.
                    self.sync_errors = self.sync_errors.saturating_add(1);
                    self.sync = SyncState::None;
                }
            }
        }
        self.tooth_period_us = interval / spacing as f32;
        self.have_period = true;
        self.last_tooth_us = Some(t_us);
        self.push_history(t_us, spacing);
        self.deg_per_us = self.speed_estimate();
        if self.sync != SyncState::None && self.rpm() > self.run_rpm {
            self.running = true;
        }
    }

    /// A revolution ended at the gap: check the tooth count and work out which revolution of
    /// the cycle starts.
    fn on_gap(&mut self) {
        let complete = self.tooth_index == self.wheel.teeth_present() - 1;
        match self.sync {
            SyncState::None => {
                self.sync = SyncState::Crank;
                self.crank_lost = false;
                self.second_rev = false;
            }
            _ if !complete => {
                // Gap at the wrong place: resynchronize on this gap, cycle half unknown.
                self.sync_errors = self.sync_errors.saturating_add(1);
                self.sync = SyncState::Crank;
                self.second_rev = false;
            }
            _ => {
                if self.cam_seen_this_rev {
                    // The cam edge lies in the second revolution: the next one is the first.
                    self.second_rev = false;
                    self.sync = SyncState::Full;
                } else if !self.second_rev {
                    // A whole observed revolution without the cam was the first one.
                    self.second_rev = true;
                    self.sync = SyncState::Full;
                } else {
                    // The second revolution passed without the cam edge.
                    self.cam_lost = true;
                    self.sync = SyncState::Crank;
                    self.second_rev = false;
                }
            }
        }
        self.tooth_index = 0;
        self.cam_seen_this_rev = false;
    }

    fn on_cam(&mut self, t_us: u32) {
        self.cam_seen_this_rev = true;
        if self.sync == SyncState::None {
            return;
        }
        if self.sync == SyncState::Full && !self.second_rev {
            // Cam edge in the first revolution contradicts the count; trust the cam.
            self.sync_errors = self.sync_errors.saturating_add(1);
        }
        self.second_rev = true;
        self.sync = SyncState::Full;
        self.cam_lost = false;
        self.cam_edge_deg = self.angle_at(t_us);
        self.cam_edge_seq = self.cam_edge_seq.wrapping_add(1);
    }

    fn push_history(&mut self, t_us: u32, spacing: u8) {
        self.history_us.copy_within(1.., 0);
        self.history_spacing.copy_within(1.., 0);
        self.history_us[SPEED_HISTORY - 1] = t_us;
        self.history_spacing[SPEED_HISTORY - 1] = spacing;
        self.history_len = (self.history_len + 1).min(SPEED_HISTORY);
    }

    /// Degrees per µs over the shortest recent span of at least [`SPEED_SPAN_MIN_US`] (or all
    /// the history): long enough that the 1 µs capture step hardly matters, short enough to
    /// follow accelerations.
    fn speed_estimate(&self) -> f32 {
        let n = self.history_len.min(SPEED_HISTORY);
        let times = &self.history_us[SPEED_HISTORY - n..];
        let spacings = &self.history_spacing[SPEED_HISTORY - n..];
        let Some(&t_last) = times.last() else { return 0.0 };
        let (mut teeth, mut span) = (0u32, 0u32);
        // Walk back from the newest tooth; each spacing belongs to the interval ending at the
        // tooth after the time it is paired with.
        for (&t, &spacing) in times.iter().rev().skip(1).zip(spacings.iter().rev()) {
            teeth += u32::from(spacing);
            span = elapsed_us(t_last, t);
            if span >= SPEED_SPAN_MIN_US {
                break;
            }
        }
        if span == 0 {
            0.0
        } else {
            teeth as f32 * self.tooth_deg / span as f32
        }
    }

    /// Cycle angle at `t_us` (after the last processed tooth), extrapolated at the present
    /// speed but never past the next expected tooth; `None` without full sync.
    pub fn angle_at(&self, t_us: u32) -> Option<f32> {
        let last = self.last_tooth_us?;
        if self.sync != SyncState::Full || !(self.deg_per_us > 0.0) {
            return None;
        }
        let base = self.wheel.first_tooth_deg
            + if self.second_rev { 360.0 } else { 0.0 }
            + self.tooth_index as f32 * self.tooth_deg;
        let to_next_teeth = if self.tooth_index.saturating_add(1) >= self.wheel.teeth_present() {
            self.wheel.teeth_missing.saturating_add(1)
        } else {
            1
        };
        let advance = (elapsed_us(t_us, last) as f32 * self.deg_per_us).min(to_next_teeth as f32 * self.tooth_deg);
        Some(wrap_cycle_deg(base + advance))
    }

    /// Checks for a stalled or lost crank signal at `now_us`; returns true when it was just
    /// declared lost (everything position-related is then forgotten).
    pub fn check_stall(&mut self, now_us: u32) -> bool {
        let Some(last) = self.last_tooth_us else { return false };
        let since = elapsed_us(now_us, last);
        // Three gap intervals without a tooth, or the absolute limit at very low speed.
        let expected = self.tooth_period_us * (self.wheel.teeth_missing as f32 + 1.0);
        let lost = since > self.stall_timeout_us || (self.have_period && since as f32 > 3.0 * expected);
        if lost {
            let was_turning = self.sync != SyncState::None || self.running;
            self.sync = SyncState::None;
            self.last_tooth_us = None;
            self.have_period = false;
            self.history_len = 0;
            self.deg_per_us = 0.0;
            self.running = false;
            self.cam_edge_deg = None;
            self.crank_lost |= was_turning;
            return was_turning;
        }
        false
    }

    pub fn sync(&self) -> SyncState {
        self.sync
    }

    /// Crank degrees per µs.
    pub fn deg_per_us(&self) -> f32 {
        self.deg_per_us
    }

    pub fn rpm(&self) -> f32 {
        // deg/µs × 1e6 µs/s × 60 s/min / 360 deg/rev
        self.deg_per_us * 166_666.67
    }

    pub fn snapshot(&self) -> EngineSnapshot {
        EngineSnapshot {
            sync: self.sync,
            rpm: if self.sync == SyncState::None { 0.0 } else { self.rpm() },
            cranking: self.sync != SyncState::None && !self.running,
            cam_edge_deg: self.cam_edge_deg,
            cam_edge_seq: self.cam_edge_seq,
            crank_lost: self.crank_lost,
            cam_lost: self.cam_lost,
        }
    }
}

/// The actuation delays (td,VO, td,VC) in ms at supply pressure and oil temperature: the LPV
/// model's delay table ([`EhvvaTables::t_delay_pair_ms`]) or any calibration the caller has.
pub trait ActuationDelay {
    fn delays_ms(&self, p_supply_mpa: f32, temp_oil_c: f32) -> (f32, f32);
    /// Pilot edge to the valve event the request means (1 % lift opening, 99 % closing),
    /// `(VO, VC)` ms: what the task advances the edges by. Default: td alone.
    fn event_advances_ms(&self, p_supply_mpa: f32, temp_oil_c: f32, lift_high: bool) -> (f32, f32) {
        let _ = lift_high;
        self.delays_ms(p_supply_mpa, temp_oil_c)
    }
}

impl ActuationDelay for EhvvaTables<f32> {
    fn delays_ms(&self, p_supply_mpa: f32, temp_oil_c: f32) -> (f32, f32) {
        self.t_delay_pair_ms(p_supply_mpa, temp_oil_c)
    }
    /// td plus the valve's own motion to the thresholds
    /// ([`EhvvaTables::t_event_advance_pair_ms`]).
    fn event_advances_ms(&self, p_supply_mpa: f32, temp_oil_c: f32, lift_high: bool) -> (f32, f32) {
        self.t_event_advance_pair_ms(p_supply_mpa, temp_oil_c, lift_high)
    }
}

/// Fixed delays (bench use, tests).
impl ActuationDelay for (f32, f32) {
    fn delays_ms(&self, _: f32, _: f32) -> (f32, f32) {
        *self
    }
}

/// Calibration of the EHVVA task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EhvvaTaskConfig {
    pub wheel: TriggerWheel,
    pub solenoid: SolenoidParams,
    /// No valve events below this speed (no reliable angle) or above the maximum.
    pub min_rpm: f32,
    pub max_rpm: f32,
    pub run_rpm: f32,
    pub stall_timeout_us: u32,
    /// The lift sleeve and the snubber switch valve only switch this long after the pilot
    /// went off (the engine valve is seated by then: td,VC + closing ≈ 4 + 3 ms).
    pub lift_switch_quiet_us: u32,
    /// Longest sleep the task asks for (it also wakes on every tooth).
    pub max_sleep_us: u32,
}

impl Default for EhvvaTaskConfig {
    /// 60-2 wheel, the default pilot coil, events from 100 to 7000 rpm, running above
    /// 500 rpm, crank lost after 200 ms, lift switching 10 ms after the pilot went off.
    fn default() -> Self {
        Self {
            wheel: TriggerWheel::sixty_minus_two(),
            solenoid: SolenoidParams::pilot_default(),
            min_rpm: 100.0,
            max_rpm: 7000.0,
            run_rpm: 500.0,
            stall_timeout_us: 200_000,
            lift_switch_quiet_us: 10_000,
            max_sleep_us: 10_000,
        }
    }
}

/// The requested valve event for the coming cycles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValveRequest {
    /// Cycle angles (0..720) at which the valve shall start to open and to close.
    pub open_deg: f32,
    pub close_deg: f32,
    /// Lift valve on: high lift S1 (7.5 mm); off: S2 (4 mm).
    pub high_lift: bool,
    /// Snubber switch valve on: soft seating (0.25 m/s instead of 0.69 m/s, Fig. 2).
    pub soft_seat: bool,
    pub enabled: bool,
}

/// Measurements and commands for one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EhvvaStepInputs {
    pub request: ValveRequest,
    pub p_supply_mpa: f32,
    pub temp_oil_c: f32,
    pub u_batt_v: f32,
    /// The supervisor's safe state: pilot off (valve closed by its spring), slow valves off.
    pub force_safe: bool,
}

/// Outputs to apply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EhvvaStepOutputs {
    pub pilot: SolenoidCmd,
    pub lift_valve_on: bool,
    pub snubber_switch_on: bool,
    /// Call `step` again at this time at the latest.
    pub wake_at_us: u32,
    pub engine: EngineSnapshot,
    /// The crank signal was lost in this step (events stopped, pilot off).
    pub crank_lost_now: bool,
    /// A new valve event started in this step; with its peak-and-hold plan's fault if any.
    pub event_started: bool,
    pub peak_fault: Option<PeakHoldFault>,
}

/// The EHVVA task state machine.
#[derive(Clone, Debug)]
pub struct EhvvaTask<D: ActuationDelay> {
    cfg: EhvvaTaskConfig,
    delay: D,
    decoder: CrankDecoder,
    pilot: PeakHoldDriver<f32>,
    /// The pilot is commanded on (between the on and off command angles).
    open_cmd: bool,
    prev_angle_deg: Option<f32>,
    last_step_us: Option<u32>,
    pilot_off_us: Option<u32>,
    lift_on: bool,
    snubber_on: bool,
}

impl<D: ActuationDelay> EhvvaTask<D> {
    pub fn new(cfg: EhvvaTaskConfig, delay: D) -> Result<Self, &'static str> {
        let pilot = PeakHoldDriver::new(cfg.solenoid)?;
        if !(cfg.min_rpm > 0.0 && cfg.max_rpm > cfg.min_rpm) {
            return Err("min_rpm/max_rpm");
        }
        if cfg.wheel.teeth_total < 4
            || cfg.wheel.teeth_missing == 0
            || cfg.wheel.teeth_missing >= cfg.wheel.teeth_total / 2
        {
            return Err("wheel");
        }
        Ok(Self {
            decoder: CrankDecoder::new(cfg.wheel, cfg.stall_timeout_us, cfg.run_rpm),
            cfg,
            delay,
            pilot,
            open_cmd: false,
            prev_angle_deg: None,
            last_step_us: None,
            pilot_off_us: None,
            lift_on: false,
            snubber_on: false,
        })
    }

    pub fn on_edge(&mut self, edge: Edge) {
        self.decoder.on_edge(edge);
    }

    pub fn decoder(&self) -> &CrankDecoder {
        &self.decoder
    }

    /// The crank angles at which the pilot is switched on and off now: the requested angles
    /// advanced by ω times the pilot-edge-to-event times (td plus the valve's motion to the
    /// 1 % / 99 % thresholds, [`ActuationDelay::event_advances_ms`]) at the lift the valve has.
    pub fn command_angles_deg(&self, req: &ValveRequest, p_supply_mpa: f32, temp_oil_c: f32) -> (f32, f32) {
        let (td_vo_ms, td_vc_ms) = self.delay.event_advances_ms(p_supply_mpa, temp_oil_c, self.lift_on);
        let deg_per_ms = self.decoder.deg_per_us() * 1000.0;
        (
            wrap_cycle_deg(req.open_deg - deg_per_ms * td_vo_ms),
            wrap_cycle_deg(req.close_deg - deg_per_ms * td_vc_ms),
        )
    }

    fn switch_pilot(&mut self, on: bool, u_batt_v: f32, now_us: u32, out: &mut EhvvaStepOutputs) {
        if on && !self.open_cmd {
            self.open_cmd = true;
            if let Some(plan) = self.pilot.set(true, u_batt_v) {
                out.event_started = true;
                out.peak_fault = plan.fault;
            }
        } else if !on && self.open_cmd {
            self.open_cmd = false;
            self.pilot.set(false, u_batt_v);
            self.pilot_off_us = Some(now_us);
        }
    }

    /// One step at `now_us` (after feeding the edges up to now).
    pub fn step(&mut self, inp: &EhvvaStepInputs, now_us: u32) -> EhvvaStepOutputs {
        let crank_lost_now = self.decoder.check_stall(now_us);
        let dt_us = self.last_step_us.map_or(0, |t| elapsed_us(now_us, t));
        self.last_step_us = Some(now_us);
        // Advance the peak timer over the time already passed, before any new event starts.
        self.pilot.tick(dt_us as f32, None);

        let mut out = EhvvaStepOutputs {
            pilot: SolenoidCmd::Off,
            lift_valve_on: false,
            snubber_switch_on: false,
            wake_at_us: now_us.wrapping_add(self.cfg.max_sleep_us),
            engine: self.decoder.snapshot(),
            crank_lost_now,
            event_started: false,
            peak_fault: None,
        };
        let rpm = self.decoder.rpm();
        let angle = self.decoder.angle_at(now_us);
        let active = !inp.force_safe && inp.request.enabled && rpm >= self.cfg.min_rpm && rpm <= self.cfg.max_rpm;
        match (active, angle) {
            (true, Some(angle)) => {
                let (on_deg, off_deg) = self.command_angles_deg(&inp.request, inp.p_supply_mpa, inp.temp_oil_c);
                if let Some(prev) = self.prev_angle_deg {
                    let travelled = wrap_cycle_deg(angle - prev);
                    // More than half a cycle "travelled" is a small backward step: nothing crossed.
                    let travelled = if travelled > 360.0 { 0.0 } else { travelled };
                    let crossed = |target: f32| {
                        let d = wrap_cycle_deg(target - prev);
                        (d > 0.0 && d <= travelled).then_some(d)
                    };
                    // Both edges in one step (a long sleep): apply them in angle order.
                    let mut edges = [(crossed(on_deg), true), (crossed(off_deg), false)];
                    if let (Some(a), Some(b)) = (edges[0].0, edges[1].0) {
                        if b < a {
                            edges.swap(0, 1);
                        }
                    }
                    for (hit, on) in edges {
                        if hit.is_some() {
                            self.switch_pilot(on, inp.u_batt_v, now_us, &mut out);
                        }
                    }
                }
                self.prev_angle_deg = Some(angle);
                // Sleep until the next command angle, rounded up so that the step lands on or
                // just after it.
                let target = if self.open_cmd { off_deg } else { on_deg };
                let d = wrap_cycle_deg(target - angle);
                let d = if d == 0.0 { CYCLE_DEG } else { d };
                let w = self.decoder.deg_per_us();
                let sleep = (d / w + 0.999).min(self.cfg.max_sleep_us as f32).max(1.0) as u32;
                out.wake_at_us = now_us.wrapping_add(sleep);
            }
            _ => {
                // No position, no request or the safe state: valve closed.
                self.switch_pilot(false, inp.u_batt_v, now_us, &mut out);
                self.prev_angle_deg = None;
            }
        }

        // End of the peak phase is the other deadline.
        if let PilotPhase::Peak { elapsed_us: in_peak_us } = self.pilot.phase() {
            let remaining = (self.pilot.last_plan().t_peak_us - in_peak_us).max(0.0);
            let peak_end = now_us.wrapping_add((remaining + 0.999).max(1.0) as u32);
            if elapsed_us(peak_end, now_us) < elapsed_us(out.wake_at_us, now_us) {
                out.wake_at_us = peak_end;
            }
        }
        out.pilot = match self.pilot.phase() {
            PilotPhase::Off => SolenoidCmd::Off,
            PilotPhase::Peak { .. } => SolenoidCmd::Full,
            PilotPhase::Hold => SolenoidCmd::Pwm(self.pilot.duty()),
        };

        // Slow valves: only while the engine valve is seated.
        if inp.force_safe {
            self.lift_on = false;
            self.snubber_on = false;
        } else if !self.open_cmd
            && self
                .pilot_off_us
                .is_none_or(|t| elapsed_us(now_us, t) >= self.cfg.lift_switch_quiet_us)
        {
            self.lift_on = inp.request.high_lift;
            self.snubber_on = inp.request.soft_seat;
        }
        out.lift_valve_on = self.lift_on;
        out.snubber_switch_on = self.snubber_on;
        out.engine = self.decoder.snapshot();
        out
    }
}

#[cfg(test)]
mod tests;
