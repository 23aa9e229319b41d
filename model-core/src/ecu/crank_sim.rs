//! The engine's side of the crank and cam inputs: the edges a trigger wheel and the cam sync
//! tooth produce while the crankshaft turns. The plant side of a bench (the host's HIL run,
//! the task tests) uses it to feed [`super::frame::SensorFrame`]s or the decoder, so there is
//! one wheel simulation, written against the same [`TriggerWheel`] the decoder is calibrated
//! with.

use super::board::{Edge, EdgeSource};
use super::ehvva_task::{TriggerWheel, CYCLE_DEG};

/// A crankshaft turning a trigger wheel; the cam sync tooth sits at a cycle angle the caller
/// gives each step (it moves with the cam phaser).
#[derive(Clone, Copy, Debug)]
pub struct CrankSignal {
    pub wheel: TriggerWheel,
    /// Unwrapped crank angle (deg); the cycle angle is this modulo 720.
    pub theta_deg: f64,
    /// The cam edge's cycle angle at the end of the last step (NaN before the first): the
    /// phaser moves the edge while the crank turns, so a step's crossing is judged from where
    /// the edge was at its start to where it is at its end.
    cam_prev_cycle_deg: f64,
}

impl CrankSignal {
    /// A wheel at crank angle `theta_deg`, the cam edge not yet placed.
    pub const fn new(wheel: TriggerWheel, theta_deg: f64) -> Self {
        Self {
            wheel,
            theta_deg,
            cam_prev_cycle_deg: f64::NAN,
        }
    }

    /// Turns the crank for `dt_us` at `rpm` starting at time `t0_us`, and writes the edges
    /// crossed into `out` in time order (timestamps interpolated within the step): the wheel's
    /// teeth when `crank_ok`, the cam edge at `cam_cycle_deg` when `cam_ok`. A tooth and the
    /// cam edge at the same angle come tooth first. Returns how many edges were crossed, which
    /// is more than `out.len()` when some did not fit.
    ///
    /// The cam edge moves from its angle at the last step's end to `cam_cycle_deg` during the
    /// step (linearly): it is crossed once per cycle however the phaser moves it, as long as
    /// it moves slower than the crank. Judging both ends of the step at the new angle missed
    /// the edge whenever an advancing phaser moved it behind a crank that had just reached it.
    pub fn advance(
        &mut self,
        rpm: f64,
        dt_us: u32,
        cam_cycle_deg: f64,
        crank_ok: bool,
        cam_ok: bool,
        t0_us: u32,
        out: &mut [Edge],
    ) -> usize {
        let cycle = f64::from(CYCLE_DEG);
        // The edge's motion during the step, the shorter way round the cycle.
        let cam0 = if self.cam_prev_cycle_deg.is_finite() {
            self.cam_prev_cycle_deg
        } else {
            cam_cycle_deg
        };
        let mut cam_move = (cam_cycle_deg - cam0) % cycle;
        if cam_move > 0.5 * cycle {
            cam_move -= cycle;
        } else if cam_move < -0.5 * cycle {
            cam_move += cycle;
        }
        self.cam_prev_cycle_deg = cam_cycle_deg;
        let theta0 = self.theta_deg;
        let theta1 = theta0 + rpm.max(0.0) * 6.0 * (f64::from(dt_us) * 1e-6);
        self.theta_deg = theta1;
        if theta1 <= theta0 || theta1.is_nan() {
            return 0;
        }
        // The crank's angle past the edge, at the step's start and end.
        let (psi0, psi1) = (theta0 - cam0, theta1 - (cam0 + cam_move));
        let cycles_before = libm::floor(psi0 / cycle);
        let cycles_after = libm::floor(psi1 / cycle);
        let mut cam = (cam_ok && cycles_after > cycles_before).then(|| {
            // Where in the step the crank meets the edge; the edge's angle there.
            let s = (cycles_after * cycle - psi0) / (psi1 - psi0);
            cam0 + s * cam_move + cycles_after * cycle
        });
        let mut n = 0;
        let mut emit = |angle: f64, source: EdgeSource, n: &mut usize| {
            if let Some(slot) = out.get_mut(*n) {
                let dt = (angle - theta0) / (theta1 - theta0) * f64::from(dt_us);
                *slot = Edge {
                    source,
                    t_us: t0_us.wrapping_add(dt as u32),
                };
            }
            *n += 1;
        };
        if crank_ok {
            let tooth = f64::from(self.wheel.tooth_deg());
            let total = i64::from(self.wheel.teeth_total);
            let present = total - i64::from(self.wheel.teeth_missing);
            let first = libm::floor(theta0 / tooth) as i64 + 1;
            let last = libm::floor(theta1 / tooth) as i64;
            for j in first..=last {
                if j.rem_euclid(total) >= present {
                    continue;
                }
                let angle = j as f64 * tooth;
                if let Some(c) = cam.filter(|c| *c < angle) {
                    emit(c, EdgeSource::CamSync, &mut n);
                    cam = None;
                }
                emit(angle, EdgeSource::CrankTooth, &mut n);
            }
        }
        if let Some(c) = cam {
            emit(c, EdgeSource::CamSync, &mut n);
        }
        n
    }

    /// The crank angle in the 720-degree cycle.
    pub fn cycle_deg(&self) -> f64 {
        // f64::rem_euclid is std-only; this is its definition.
        let cycle = f64::from(CYCLE_DEG);
        let r = self.theta_deg % cycle;
        if r < 0.0 {
            r + cycle
        } else {
            r
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ecu::frame::{SensorFrame, MAX_EDGES};

    #[test]
    fn gives_58_teeth_per_revolution_and_one_cam_edge_per_cycle() {
        let mut e = CrankSignal::new(TriggerWheel::sixty_minus_two(), 1.0);
        let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
        let (mut teeth, mut cams, mut t_us) = (0, [0u32; 4], 0u32);
        let mut n_cams = 0;
        // Two cycles at 3000 rpm (40 ms each), 50 µs steps.
        for _ in 0..1600 {
            let n = e.advance(3000.0, 50, 430.0, true, true, t_us, &mut edges);
            assert!(n <= MAX_EDGES);
            assert!(edges[..n].windows(2).all(|w| w[0].t_us <= w[1].t_us));
            for ed in &edges[..n] {
                match ed.source {
                    EdgeSource::CrankTooth => teeth += 1,
                    EdgeSource::CamSync => {
                        cams[n_cams] = ed.t_us;
                        n_cams += 1;
                    }
                }
            }
            t_us += 50;
        }
        assert_eq!(teeth, 4 * 58);
        assert_eq!(n_cams, 2);
        // 720 deg at 18 deg/ms: 40 ms apart; the first at (430 - 1) deg / 18 deg/ms.
        assert!((cams[1] - cams[0]) as i64 - 40_000 <= 1);
        assert!((cams[0] as f64 - 429.0 / 0.018).abs() <= 1.0, "{}", cams[0]);
    }

    /// The regression: the crank reaches the edge at the end of one step, the phaser advances
    /// it by 0.1 deg behind the crank during the next. The edge passed the sensor once; judged
    /// at the new angle only, both steps saw none (a `CamLost` on a healthy engine, seen in
    /// `run` as the loop advanced the cam).
    #[test]
    fn an_edge_the_phaser_moves_behind_the_crank_is_still_crossed() {
        let mut e = CrankSignal::new(TriggerWheel::sixty_minus_two(), 432.40);
        let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
        // 0.39 deg in 50 µs: 1300 rpm.
        let rpm = 0.39 / 6.0 / 50e-6;
        let n1 = e.advance(rpm, 50, 432.80, false, true, 0, &mut edges);
        assert_eq!(n1, 0, "the crank stops short of the edge");
        let n2 = e.advance(rpm, 50, 432.70, false, true, 50, &mut edges);
        assert_eq!(n2, 1);
        assert_eq!(edges[0].source, EdgeSource::CamSync);
        // Met where 432.79 + 0.39 s = 432.80 - 0.1 s: s = 0.0204, 1 µs into the step.
        assert!((50..=52).contains(&edges[0].t_us), "{}", edges[0].t_us);
    }

    proptest::proptest! {
        /// However the phaser moves the edge (up to 400 deg/s of cam phase either way, far
        /// faster than the phaser's 100-200 deg/s) and wherever the steps fall, the edge is
        /// crossed exactly as often as the crank passes it, and the edges come in time order.
        #[test]
        fn the_cam_edge_is_crossed_once_per_pass(
            rpm in 600.0f64..6000.0,
            theta0 in 0.0f64..720.0,
            cam0 in 380.0f64..460.0,
            rate_deg_per_s in -400.0f64..400.0,
            dt_us in 20u32..200,
        ) {
            let mut e = CrankSignal::new(TriggerWheel::sixty_minus_two(), theta0);
            let mut edges = [SensorFrame::NO_EDGE; 64];
            let (mut cams, mut t_us) = (0i64, 0u32);
            let mut cam = cam0;
            let steps = (0.2e6 / f64::from(dt_us)) as u32;
            for _ in 0..steps {
                cam += rate_deg_per_s * f64::from(dt_us) * 1e-6;
                let n = e.advance(rpm, dt_us, cam, true, true, t_us, &mut edges);
                proptest::prop_assert!(n <= edges.len());
                proptest::prop_assert!(edges[..n].windows(2).all(|w| w[0].t_us <= w[1].t_us));
                cams += edges[..n].iter().filter(|x| x.source == EdgeSource::CamSync).count() as i64;
                t_us += dt_us;
            }
            let passes = libm::floor((e.theta_deg - cam) / 720.0) - libm::floor((theta0 - cam0) / 720.0);
            proptest::prop_assert_eq!(cams, passes as i64);
        }
    }

    #[test]
    fn overflow_is_counted_and_signals_can_be_cut() {
        let mut e = CrankSignal::new(TriggerWheel::sixty_minus_two(), 1.0);
        let mut edges = [SensorFrame::NO_EDGE; 2];
        // 6000 rpm for 1 ms = 36 deg = 6 teeth: two written, six counted.
        assert_eq!(e.advance(6000.0, 1000, 430.0, true, true, 0, &mut edges), 6);
        assert!(edges.iter().all(|x| x.source == EdgeSource::CrankTooth && x.t_us > 0));
        // A whole cycle with the crank signal lost: only the cam edge; with both lost: nothing.
        assert_eq!(e.advance(6000.0, 20_000, 430.0, false, true, 1000, &mut edges), 1);
        assert_eq!(edges[0].source, EdgeSource::CamSync);
        assert_eq!(e.advance(6000.0, 20_000, 430.0, false, false, 21_000, &mut edges), 0);
    }
}
