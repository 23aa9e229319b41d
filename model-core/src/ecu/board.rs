//! The small hardware traits the ECU tasks are written against. The ECU board (embassy-stm32)
//! and an emulated board implement them; the tests here implement them with recording doubles.
//!
//! Time is a free-running 32-bit microsecond counter (a 32-bit timer at 1 MHz on the ECU): it
//! wraps every 71.6 minutes, so times are only ever compared by [`elapsed_us`] (wrapping
//! difference), never by `<`.

/// Microseconds from `since` to `now` on the wrapping 32-bit clock. Correct for intervals
/// below 2^32 µs; an instant "in the future" shows up as a huge elapsed time, so callers that
/// may see one use [`until_us`].
pub fn elapsed_us(now_us: u32, since_us: u32) -> u32 {
    now_us.wrapping_sub(since_us)
}

/// Microseconds from `now` until `at`, 0 when `at` is already past (within half the wrap).
pub fn until_us(now_us: u32, at_us: u32) -> u32 {
    let d = at_us.wrapping_sub(now_us);
    if d > u32::MAX / 2 {
        0
    } else {
        d
    }
}

/// Monotonic microsecond time, the same clock as the [`Capture`] timestamps.
pub trait Clock {
    fn now_us(&self) -> u32;
}

/// One PWM output. `duty` is 0..1 (the implementation clamps); `disable` forces the pin to its
/// inactive level (valve unpowered).
pub trait PwmOut {
    fn set_duty(&mut self, duty: f32);
    fn disable(&mut self);
}

/// A low-side switch (pump relay, slow solenoid valves).
pub trait SwitchOut {
    fn set(&mut self, on: bool);
}

/// One analog input in raw ADC counts; [`AnalogScale`] turns counts into engineering units.
pub trait AnalogIn {
    fn read_counts(&mut self) -> u16;
}

/// Where a captured edge came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeSource {
    /// A tooth of the crank trigger wheel.
    CrankTooth,
    /// The camshaft sync tooth (one per engine cycle, 720 crank degrees).
    CamSync,
}

/// A captured edge with its timer timestamp.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    pub source: EdgeSource,
    pub t_us: u32,
}

/// Input capture: edges in time order, `None` when no edge is pending.
pub trait Capture {
    fn next_edge(&mut self) -> Option<Edge>;
}

/// What a solenoid driver is told to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SolenoidCmd {
    Off,
    /// Full battery voltage (the peak phase).
    Full,
    /// PWM at this duty, 0..1 (the hold phase).
    Pwm(f32),
}

/// A solenoid driver with a full-on and a PWM mode (the pilot valve's peak-and-hold stage).
pub trait SolenoidDriver {
    fn off(&mut self);
    fn full_on(&mut self);
    fn pwm(&mut self, duty: f32);

    fn apply(&mut self, cmd: SolenoidCmd) {
        match cmd {
            SolenoidCmd::Off => self.off(),
            SolenoidCmd::Full => self.full_on(),
            SolenoidCmd::Pwm(d) => self.pwm(d),
        }
    }
}

/// Why an analog reading was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnalogFault {
    /// Below the electrical window: wire open (pull-down) or shorted to ground.
    OpenOrShortToGround,
    /// Above the electrical window: shorted to the sensor supply or battery.
    ShortToSupply,
    /// Electrically fine but outside the physically plausible range.
    Implausible,
}

/// Linear conversion of one channel with its range checks: a ratiometric sensor uses only
/// `counts_min..=counts_max` (e.g. 0.25..4.75 V of 5 V) so that an open or shorted wire lands
/// outside it; the converted value must then lie in `plausible_min..=plausible_max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalogScale {
    pub counts_min: u16,
    pub counts_max: u16,
    /// Engineering value at 0 counts.
    pub offset: f32,
    /// Engineering units per count.
    pub gain_per_count: f32,
    pub plausible_min: f32,
    pub plausible_max: f32,
}

impl AnalogScale {
    /// Counts → engineering units, or the fault.
    pub fn convert(&self, counts: u16) -> Result<f32, AnalogFault> {
        if counts < self.counts_min {
            return Err(AnalogFault::OpenOrShortToGround);
        }
        if counts > self.counts_max {
            return Err(AnalogFault::ShortToSupply);
        }
        let value = self.offset + self.gain_per_count * counts as f32;
        // `!(a <= v && v <= b)` also rejects NaN from a bad calibration.
        if !(self.plausible_min <= value && value <= self.plausible_max) {
            return Err(AnalogFault::Implausible);
        }
        Ok(value)
    }

    /// The counts that give `value` (for test doubles and calibration checks), saturated to
    /// the 12-bit range.
    pub fn counts_for(&self, value: f32) -> u16 {
        let c = (value - self.offset) / self.gain_per_count + 0.5;
        c.clamp(0.0, 4095.0) as u16
    }
}

/// Recording test doubles of the traits (also usable by a simulated board on the host).
#[cfg(test)]
pub mod doubles {
    use super::*;

    /// Remembers the last duty and whether it is enabled.
    #[derive(Clone, Copy, Debug, Default)]
    pub struct FakePwm {
        pub duty: f32,
        pub enabled: bool,
    }
    impl PwmOut for FakePwm {
        fn set_duty(&mut self, duty: f32) {
            self.duty = duty.clamp(0.0, 1.0);
            self.enabled = true;
        }
        fn disable(&mut self) {
            self.duty = 0.0;
            self.enabled = false;
        }
    }

    #[derive(Clone, Copy, Debug, Default)]
    pub struct FakeSwitch {
        pub on: bool,
    }
    impl SwitchOut for FakeSwitch {
        fn set(&mut self, on: bool) {
            self.on = on;
        }
    }

    #[derive(Clone, Copy, Debug, Default)]
    pub struct FakeAnalog {
        pub counts: u16,
    }
    impl AnalogIn for FakeAnalog {
        fn read_counts(&mut self) -> u16 {
            self.counts
        }
    }

    /// A settable clock.
    #[derive(Clone, Copy, Debug, Default)]
    pub struct FakeClock {
        pub now_us: u32,
    }
    impl Clock for FakeClock {
        fn now_us(&self) -> u32 {
            self.now_us
        }
    }

    /// Edges queued by the test, handed out in order.
    #[derive(Debug, Default)]
    pub struct FakeCapture {
        pub pending: heapless::Deque<Edge, 64>,
    }
    impl Capture for FakeCapture {
        fn next_edge(&mut self) -> Option<Edge> {
            self.pending.pop_front()
        }
    }

    /// Records every command change with its time (set `now_us` before applying).
    #[derive(Debug, Default)]
    pub struct FakeSolenoid {
        pub now_us: u32,
        pub log: heapless::Vec<(u32, SolenoidCmd), 256>,
    }
    impl FakeSolenoid {
        fn record(&mut self, cmd: SolenoidCmd) {
            // The driver starts off, so an initial `Off` is no change.
            if self.current() != cmd {
                // A full log only loses later entries; tests size it for their run.
                let _ = self.log.push((self.now_us, cmd));
            }
        }
        pub fn current(&self) -> SolenoidCmd {
            self.log.last().map_or(SolenoidCmd::Off, |(_, c)| *c)
        }
    }
    impl SolenoidDriver for FakeSolenoid {
        fn off(&mut self) {
            self.record(SolenoidCmd::Off);
        }
        fn full_on(&mut self) {
            self.record(SolenoidCmd::Full);
        }
        fn pwm(&mut self, duty: f32) {
            self.record(SolenoidCmd::Pwm(duty));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0-5 V ratiometric pressure sensor on a 12-bit ADC behind a 5 V → 3.3 V divider:
    /// 0.25 V..4.75 V ↔ 0..1000 kPa.
    fn pressure_scale() -> AnalogScale {
        let counts_per_v = 4095.0 / 5.0;
        let c_lo = 0.25 * counts_per_v;
        let c_hi = 4.75 * counts_per_v;
        AnalogScale {
            counts_min: c_lo as u16,
            counts_max: c_hi as u16,
            offset: -1000.0 * c_lo / (c_hi - c_lo),
            gain_per_count: 1000.0 / (c_hi - c_lo),
            plausible_min: 0.0,
            plausible_max: 400.0,
        }
    }

    #[test]
    fn analog_range_checks_name_the_failure() {
        let s = pressure_scale();
        assert_eq!(s.convert(0), Err(AnalogFault::OpenOrShortToGround));
        assert_eq!(s.convert(4095), Err(AnalogFault::ShortToSupply));
        // 800 kPa is inside the electrical window but not plausible for this channel.
        assert_eq!(s.convert(s.counts_for(800.0)), Err(AnalogFault::Implausible));
        let v = s.convert(s.counts_for(100.0)).unwrap();
        assert!((v - 100.0).abs() < 0.3, "{v}");
        // NaN calibration never passes as a value.
        let bad = AnalogScale {
            gain_per_count: f32::NAN,
            ..s
        };
        assert_eq!(bad.convert(2000), Err(AnalogFault::Implausible));
    }

    #[test]
    fn wrapping_time_arithmetic() {
        assert_eq!(elapsed_us(5, u32::MAX - 4), 10);
        assert_eq!(until_us(u32::MAX - 4, 5), 10);
        assert_eq!(until_us(100, 50), 0);
    }
}
