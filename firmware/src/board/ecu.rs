//! The ECU board: STM32F405RG at 168 MHz (8 MHz crystal), embassy-stm32.
//!
//! | function                         | pin   | peripheral            |
//! |----------------------------------|-------|-----------------------|
//! | crank teeth (60-2), rising edge  | PA15  | TIM2 CH1 capture, 1 MHz, 32 bit (also the EHVVA clock) |
//! | cam sync, rising edge            | PB3   | TIM2 CH2 capture      |
//! | pilot solenoid (peak and hold)   | PB6   | TIM4 CH1 PWM 20 kHz   |
//! | EVVT motor speed command         | PB7   | TIM4 CH2 PWM 20 kHz, duty = speed / 6000 rpm |
//! | vacuum valves LPT, HPT, HPC      | PA6, PA7, PB0 | TIM3 CH1-3 PWM 300 Hz |
//! | vacuum pump relay                | PB12  | GPIO, high = on       |
//! | EHVVA lift valve (S1)            | PB13  | GPIO, high = on       |
//! | EHVVA snubber switch valve       | PB14  | GPIO, high = on       |
//! | EVVT motor driver fault          | PB15  | GPIO in, pull-up, low = fault |
//! | battery, Ph, Pl, oil T           | PC0-PC3 | ADC1 IN10-13        |
//! | tank p, ambient p                | PC4, PC5 | ADC1 IN14-15       |
//! | positions LPT, HPT, HPC          | PA1-PA3 | ADC1 IN1-3          |
//! | ECU temperature                  | -     | ADC1 IN16 (internal)  |
//! | watchdog                         | -     | IWDG, 200 ms          |
//!
//! The EVVT motor command is a PWM duty (a BLDC driver with a PWM speed input, filtered to
//! 0..3.3 V if the driver wants an analog input); the F405's DAC on PA4/PA5 would do as well.

use embassy_futures::select::select;
use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime};
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pin, Pull, Speed};
use embassy_stm32::peripherals::{ADC1, TIM2, TIM3, TIM4};
use embassy_stm32::time::{hz, khz};
use embassy_stm32::timer::input_capture::{CapturePin, InputCapture};
use embassy_stm32::timer::low_level::{CountingMode, InputCaptureMode, InputTISelection};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::timer::{Channel, GeneralInstance4Channel};
use embassy_stm32::{bind_interrupts, pac, Peri, Peripherals};
use embassy_time::Timer;
use heapless::Deque;
use model_core::ecu::board::{until_us, AnalogIn, Capture, Clock, Edge, EdgeSource, PwmOut, SolenoidDriver, SwitchOut};
use model_core::ecu::schedule::{AnalogBank, EhvvaBoard, EvvtBoard, VacuumBoard, Watchdog};
use model_core::ecu::supervisor::N_CHANNELS;

use super::EhvvaIo;

bind_interrupts!(pub struct Irqs {
    TIM2 => embassy_stm32::timer::CaptureCompareInterruptHandler<TIM2>;
});

/// The clock configuration: HSE 8 MHz → PLL 336 MHz → 168 MHz core, APB1 42 MHz (timers
/// 84 MHz), APB2 84 MHz, 48 MHz for USB.
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: embassy_stm32::time::mhz(8),
        mode: HseMode::Oscillator,
    });
    c.rcc.pll_src = PllSource::HSE;
    c.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV4;
    c.rcc.apb2_pre = APBPrescaler::DIV2;
    c.rcc.sys = Sysclk::PLL1_P;
    c
}

/// A PWM channel with a 0..1 duty, on any timer (TIM3: vacuum valves; TIM4: pilot, motor
/// command).
pub struct Pwm<T: GeneralInstance4Channel>(pub SimplePwmChannel<'static, T>);
/// The TIM4 channels (pilot, motor command).
pub type Pwm4 = Pwm<TIM4>;

fn duty_counts(max: u32, duty: f32) -> u32 {
    // NaN clamps to 0 (`as` saturates), so a bad duty never drives a valve full on.
    ((duty.clamp(0.0, 1.0) * max as f32) as u32).min(max)
}

impl<T: GeneralInstance4Channel> PwmOut for Pwm<T> {
    fn set_duty(&mut self, duty: f32) {
        let max = self.0.max_duty_cycle();
        self.0.set_duty_cycle(duty_counts(max, duty));
        self.0.enable();
    }
    fn disable(&mut self) {
        self.0.set_duty_cycle_fully_off();
    }
}

/// The pilot stage: full on = 100 % duty, hold = PWM.
impl SolenoidDriver for Pwm4 {
    fn off(&mut self) {
        self.0.set_duty_cycle_fully_off();
    }
    fn full_on(&mut self) {
        self.0.set_duty_cycle_fully_on();
        self.0.enable();
    }
    fn pwm(&mut self, duty: f32) {
        PwmOut::set_duty(self, duty);
    }
}

pub struct Switch(pub Output<'static>);
impl SwitchOut for Switch {
    fn set(&mut self, on: bool) {
        self.0.set_level(if on { Level::High } else { Level::Low });
    }
}

/// EHVVA I/O: TIM2 captures crank (CH1, awaited) and cam (CH2, polled: one edge per cycle,
/// its captured value waits in CCR2 until the next look).
pub struct EcuEhvvaIo {
    capture: InputCapture<'static, TIM2>,
    pending: Deque<Edge, 8>,
    pilot: Pwm4,
    lift: Switch,
    snubber: Switch,
}

impl Clock for EcuEhvvaIo {
    fn now_us(&self) -> u32 {
        pac::TIM2.cnt().read()
    }
}

impl Capture for EcuEhvvaIo {
    fn next_edge(&mut self) -> Option<Edge> {
        self.pending.pop_front()
    }
}

impl EcuEhvvaIo {
    fn push_sorted(&mut self, e: Edge) {
        // Keep time order: the cam edge (read after the crank edge) goes in front of a newer
        // crank edge (wrapping compare). A full queue drops the edge; the decoder's tooth
        // count catches the loss.
        let back_is_newer = self
            .pending
            .back()
            .is_some_and(|b| b.t_us != e.t_us && b.t_us.wrapping_sub(e.t_us) < u32::MAX / 2);
        if back_is_newer {
            if let Some(b) = self.pending.pop_back() {
                let _ = self.pending.push_back(e);
                let _ = self.pending.push_back(b);
                return;
            }
        }
        let _ = self.pending.push_back(e);
    }
}

impl EhvvaBoard for EcuEhvvaIo {
    type Pilot = Pwm4;
    type Switch = Switch;
    fn pilot(&mut self) -> &mut Pwm4 {
        &mut self.pilot
    }
    fn lift_valve(&mut self) -> &mut Switch {
        &mut self.lift
    }
    fn snubber_valve(&mut self) -> &mut Switch {
        &mut self.snubber
    }
}

impl EhvvaIo for EcuEhvvaIo {
    async fn wait_edge_or(&mut self, wake_at_us: u32) {
        let sleep_us = until_us(self.now_us(), wake_at_us);
        let crank = select(
            self.capture.wait_for_rising_edge(Channel::Ch1),
            Timer::after_micros(sleep_us as u64),
        )
        .await;
        if let embassy_futures::select::Either::First(t_us) = crank {
            self.push_sorted(Edge {
                source: EdgeSource::CrankTooth,
                t_us,
            });
        }
        if self.capture.get_input_interrupt(Channel::Ch2) {
            // Reading CCR2 clears the flag.
            let t_us = self.capture.get_capture_value(Channel::Ch2);
            self.push_sorted(Edge {
                source: EdgeSource::CamSync,
                t_us,
            });
        }
    }
}

/// ADC1 with the ten channels in `Channel` order.
pub struct EcuAdc {
    adc: Adc<'static, ADC1>,
    channels: [AnyAdcChannel<'static, ADC1>; N_CHANNELS],
}

pub struct EcuAnalog<'a> {
    adc: &'a mut Adc<'static, ADC1>,
    channel: Option<&'a mut AnyAdcChannel<'static, ADC1>>,
}

impl AnalogIn for EcuAnalog<'_> {
    fn read_counts(&mut self) -> u16 {
        // 112 cycles at 21 MHz: 6 µs, enough for the 10 kΩ-class sources of the dividers.
        match self.channel.as_deref_mut() {
            Some(ch) => self.adc.blocking_read(ch, SampleTime::CYCLES112),
            None => 0,
        }
    }
}

impl AnalogBank for EcuAdc {
    type In<'a> = EcuAnalog<'a>;
    fn analog(&mut self, index: usize) -> EcuAnalog<'_> {
        EcuAnalog {
            adc: &mut self.adc,
            channel: self.channels.get_mut(index),
        }
    }
}

/// All outputs of the vacuum task.
pub struct EcuVacuumIo {
    pub valves: [Pwm<TIM3>; 3],
    pub pump: Switch,
}

impl VacuumBoard for EcuVacuumIo {
    type Valve = Pwm<TIM3>;
    type Pump = Switch;
    fn valves(&mut self) -> &mut [Pwm<TIM3>; 3] {
        &mut self.valves
    }
    fn pump(&mut self) -> &mut Switch {
        &mut self.pump
    }
}

/// The EVVT task's output and the motor driver's fault pin.
pub struct EcuEvvtIo {
    pub motor: Pwm4,
    pub driver_fault_n: Input<'static>,
}

impl EvvtBoard for EcuEvvtIo {
    type Motor = Pwm4;
    fn motor(&mut self) -> &mut Pwm4 {
        &mut self.motor
    }
    /// PB15 low = fault.
    fn driver_fault(&mut self) -> bool {
        self.driver_fault_n.is_low()
    }
}

/// The IWDG (200 ms, started by `unleash`).
pub struct EcuWatchdog(pub embassy_stm32::wdg::IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>);

impl Watchdog for EcuWatchdog {
    fn pet(&mut self) {
        self.0.pet();
    }
}

/// The whole board, split by task.
pub struct EcuBoard {
    pub ehvva: EcuEhvvaIo,
    pub evvt: EcuEvvtIo,
    pub vacuum: EcuVacuumIo,
    pub adc: EcuAdc,
    pub watchdog: EcuWatchdog,
}

impl EcuBoard {
    /// Takes the peripherals; every output starts off (the safe state).
    pub fn new(p: Peripherals) -> Self {
        let mut capture = InputCapture::new(
            p.TIM2,
            Some(CapturePin::new(p.PA15, Pull::None)),
            Some(CapturePin::new(p.PB3, Pull::None)),
            None,
            None,
            Irqs,
            khz(1000),
            CountingMode::EdgeAlignedUp,
        );
        capture.set_input_ti_selection(Channel::Ch2, InputTISelection::Normal);
        capture.set_input_capture_mode(Channel::Ch2, InputCaptureMode::Rising);
        capture.enable(Channel::Ch2);

        let pwm4 = SimplePwm::new(
            p.TIM4,
            Some(PwmPin::new(p.PB6, OutputType::PushPull)),
            Some(PwmPin::new(p.PB7, OutputType::PushPull)),
            None,
            None,
            khz(20),
            CountingMode::EdgeAlignedUp,
        )
        .split();
        let pwm3 = SimplePwm::new(
            p.TIM3,
            Some(PwmPin::new(p.PA6, OutputType::PushPull)),
            Some(PwmPin::new(p.PA7, OutputType::PushPull)),
            Some(PwmPin::new(p.PB0, OutputType::PushPull)),
            None,
            hz(300),
            CountingMode::EdgeAlignedUp,
        )
        .split();
        let mut valves = [Pwm(pwm3.ch1), Pwm(pwm3.ch2), Pwm(pwm3.ch3)];
        for v in &mut valves {
            v.set_duty(0.0);
        }
        let mut pilot = Pwm(pwm4.ch1);
        pilot.off();
        let mut motor = Pwm(pwm4.ch2);
        motor.set_duty(0.0);

        let adc = Adc::new(p.ADC1);
        let temperature = adc.enable_temperature();
        let channels = [
            p.PC0.degrade_adc(),
            p.PC1.degrade_adc(),
            p.PC2.degrade_adc(),
            p.PC3.degrade_adc(),
            p.PC4.degrade_adc(),
            p.PC5.degrade_adc(),
            p.PA1.degrade_adc(),
            p.PA2.degrade_adc(),
            p.PA3.degrade_adc(),
            temperature.degrade_adc(),
        ];

        Self {
            ehvva: EcuEhvvaIo {
                capture,
                pending: Deque::new(),
                pilot,
                lift: switch(p.PB13),
                snubber: switch(p.PB14),
            },
            evvt: EcuEvvtIo {
                motor,
                driver_fault_n: Input::new(p.PB15, Pull::Up),
            },
            vacuum: EcuVacuumIo {
                valves,
                pump: switch(p.PB12),
            },
            adc: EcuAdc { adc, channels },
            watchdog: EcuWatchdog(embassy_stm32::wdg::IndependentWatchdog::new(
                p.IWDG,
                model_core::ecu::schedule::WATCHDOG_TIMEOUT_US,
            )),
        }
    }
}

/// A low-side switch output, off at start.
fn switch(pin: Peri<'static, impl Pin>) -> Switch {
    Switch(Output::new(pin, Level::Low, Speed::Low))
}

/// Drives every output to its safe level by plain register writes (no driver state, no
/// allocation), for the panic handler: PWM compare values 0 (valves unpowered: engine valve
/// closed by its spring, wastegate open by its spring, motor stopped so the phaser runs to
/// its retard stop), pump and slow valves off.
pub fn force_outputs_safe() {
    for ch in 0..3 {
        pac::TIM3.ccr(ch).write(|w| w.set_ccr(0));
    }
    for ch in 0..2 {
        pac::TIM4.ccr(ch).write(|w| w.set_ccr(0));
    }
    pac::GPIOB.bsrr().write(|w| {
        w.set_br(12, true);
        w.set_br(13, true);
        w.set_br(14, true);
    });
}
