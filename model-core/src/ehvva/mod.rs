//! Electro-hydraulic camless valve actuator (EHVVA): the models of Li, Huang, Zhu, Lou,
//! "Modeling of an electro-hydraulic variable valve actuator ... LPV", J. Dyn. Sys. Meas. Control
//! 140 (2018) 011005.
//!
//! Three models of one valve, all generic over [`crate::Real`] (f32, f64, Q32.32) and heapless:
//! - [`EhvvaReduced`]: the fifth-order nonlinear model of eq. (12) (states Pmo, L, L̇, Pl, Ph)
//!   with the explicit actuation delay td on Pmo (eq. (11)), the first-order main-valve
//!   pressure (eq. (10)), end stops at 0 and S, top and bottom snubbers as equivalent orifices
//!   (eqs. (5)-(6)) and both accumulators with pump and relief flows (eqs. (7)-(8)).
//! - [`EhvvaLpv`] and [`LpvAffine`]: the third-order LPV time-delay model of eqs. (13)-(15),
//!   with the affine matrices A0, Ai, Bi as data for controller design and a simulation that
//!   integrates A(θ), B(θ). Ph and Pl are measured inputs.
//! - [`EhvvaFull`]: the ninth-order model of eq. (9) (solenoid, pilot spool, pilot orifice with
//!   delay t0, main spool, main valve with delay t1, piston, accumulators), the reference the
//!   reduced model is checked against.
//!
//! Around them: the calibrated tables td(Ph, T) (VO, VC), τp(Ph, T), Cd(T) ([`EhvvaTables`],
//! Figs. 4-5, Table 4), the paper's test matrix ([`PAPER_TESTS`], Table 1), and an event
//! runner ([`run_event`]) that measures opening/closing times (1 % to 99 % of the stroke,
//! Sec. 2), the full closing time and the seating velocity.
//!
//! # Units
//! Lift mm, time ms, velocity mm/ms (= m/s), pressure MPa (gauge), area mm², force N
//! (MPa·mm² = N), mass kg (so a in mm/ms² = F in N / m in kg / 1000), flow mm³/ms (= cm³/s),
//! accumulator capacitance mm³/MPa, current A, voltage V, inductance mH (V/mH = A/ms).
//!
//! # Integration
//! Each model is stepped at a fixed `dt_ms` chosen at construction (the delay lines are pushed
//! once per step, so the samples must be equally spaced; 0.02 ms in the tests, at most 0.1 ms)
//! and sub-steps internally at ≤ 5 µs: pressures with a time constant (τp ≈ 0.1 ms, the coil)
//! by implicit Euler, every sliding part semi-implicitly (spring and pressure forces explicit,
//! friction and the quadratic orifice damping implicit, linearised about the current speed, so
//! the stiff snubber damping cannot destabilise the step whatever the orifice area), positions
//! by symplectic Euler, end stops by clamping, accumulators by explicit Euler (time constants
//! ≥ 10 ms). Measured over the 15 tests of Table 1 (test `number_types_agree`), the largest
//! lift deviation from the f64 run is, for f32 / Q32.32: reduced 4.5e-5 / 3.2e-5 mm, LPV
//! 1.1e-4 / 1.2e-6 mm, ninth-order 4.1e-5 / 3.2e-5 mm.
//!
//! # Parameters (`EhvvaParams::paper_default`)
//! The paper prints the lifts, the fluid, the calibrated Cd(T) and delays at 5 MPa, and the
//! measured responses, but none of the geometry. The geometry below was fitted (random search
//! on the reduced model, f64) to the paper's measured responses: Table 3 opening times, the
//! Table 4 trends, the seating velocities of Sec. 2 (0.25 vs 0.69 m/s) with the ~1 ms tail,
//! and the ~7 ms later closing at 4 MPa back pressure (Fig. 10); the remaining values are
//! engineering choices for a passenger-car intake valve. Every value not from the paper is
//! listed in docs/invented-values.md; `hil-host paper-check` shows how far the model is from each
//! published value.
//!
//! | symbol | field | value | source / reason |
//! |---|---|---|---|
//! | me | `mass_kg` | 0.183 kg | fitted; valve + piston + 1/3 spring of a car valve train is 0.1-0.2 kg |
//! | At | `area_top_mm2` | 60.8 mm² | fitted (≈ 8.7 mm piston); sets the opening force Ph·At |
//! | Ab | `area_bottom_mm2` | 4.1 mm² | fitted; annulus under the piston |
//! | ks | `spring_n_per_mm` | 7.67 N/mm | fitted; soft enough that high lift opens at 6 MPa |
//! | ds | `spring_preload_mm` | 32.9 mm | fitted; preload ks·ds = 252 N holds the valve closed against Pl(At − Ab) up to Pl ≈ 4.45 MPa, which gives Fig. 10's long tail at 4 MPa |
//! | Cf | `friction_n_per_m_s` | 0.2 N/(m/s) | fitted; small (seals), damping comes from the orifices |
//! | S1, S2 | `lift_high_mm`, `lift_low_mm` | 7.5, 4 mm | paper Sec. 3 |
//! | ρ | `density_kg_m3` | 850 kg/m³ | automatic transmission fluid (Sec. 5.3) |
//! | – | `area_main_mm2` | 11.6 mm² | fitted; main valve + top port, part of Aorit |
//! | – | `area_top_orifice_mm2` | 0.30 mm² | fitted to the 0.25 m/s seating with the switch valve on |
//! | – | `area_top_switch_orifice_mm2` | 0.33 mm² | fitted to 0.69 m/s with the switch valve off |
//! | – | `area_top_notch_mm2` | 1.86 mm² | fitted; top notch, covered linearly in the zone |
//! | Ls1 | `snub_top_len_mm` | 0.486 mm | fitted to the ~1 ms tail (Sec. 2) |
//! | – | `area_bottom_port_mm2` | 0.593 mm² | fitted; bottom port, part of Aorib |
//! | – | `area_bottom_notch_mm2` | 0.122 mm² | fitted; bottom notch |
//! | – | `area_bottom_min_mm2` | 0.0245 mm² | fitted; what is left at full lift |
//! | Ls2 | `snub_bottom_len_mm` | 1.5 mm | fitted, bounded to ≤ 1.5 mm (a zone near the stop) |
//! | Cach | `cap_high_mm3_per_mpa` | 3500 mm³/MPa | fitted; Ph drops ≈ 0.13 MPa per high-lift opening (Fig. 2 shows a visible dip) |
//! | Cacl | `cap_low_mm3_per_mpa` | 2000 mm³/MPa | same order as Cach |
//! | Qpump | `pump_flow_mm3_per_ms` | 20 mm³/ms | 1.2 l/min: refills one high-lift opening in ≈ 25 ms |
//! | – | `relief_high_mm3_per_ms_mpa` | 200 | relief/regulator gain: 10 ms pressure recovery |
//! | – | `relief_low_mm3_per_ms_mpa` | 200 | back-pressure regulation, 10 ms |
//! | td | `tables.td_*` | Table 4 at 5 MPa; Fig. 4 shape | see [`EhvvaTableData::paper_default`] |
//! | τp | `tables.tau_ms` | 0.135 → 0.075 ms over 5-8 MPa | Fig. 5 top (linear, mean ≈ 0.1 ms) |
//! | Cd | `tables.cd` | 0.21/0.40/0.65/0.70 | Table 4 |
//! | U, R, Li | `valve.coil_*` | 14 V, 2 Ω, 2 mH | port-injector-like pilot coil (as `peak_hold`) |
//! | a, b | `valve.force_*` | 0.5 mm, 2 N/A² | 98 N at 7 A, pull-in at ≈ 2.3 A |
//! | mep, ks1, ds1, xp0 | `valve.pilot_*` | 4 g, 20 N/mm, 0.5 mm, 0.25 mm | small solenoid spool |
//! | wp | `valve.pilot_area_per_mm` | 8 mm²/mm | 2 mm² open pilot orifice |
//! | mem, ks2, ds2 | `valve.main_*` | 8 g, 20 N/mm, 1 mm | main spool; 0.8 mm stroke, 12 mm² end face, 0.1 mm overlap |
//! | – | `valve.dynamic_lag_open_ms`, `..._close_ms`; `..._ms_per_mpa` | 1.19, 1.765 ms at 6.5 MPa; −0.042, +0.031 ms/MPa | measured own lag of this coil/pilot/main chain (command to main valve half open, less ln2·τp), taken off td so t0 + t1 + lag(Ph) = td |
//! | – | `delay_nominal_p_supply_mpa` | 7 MPa | where `pressure-delay` off reads td |
//!
//! # Diagnosis effects (DATA-FORMAT.md, plant `ehvva`)
//! `effect_viscosity`, `effect_pressure_delay`, `effect_direction_delay`, `effect_snubber` in
//! [`EhvvaParams`]: 0 = off (baseline), 1 = the paper's magnitude, up to 2. See the field docs
//! for what "off" means for each; [`EhvvaParams::baseline`] has all four off.
//!
//! # Deviations from the printed equations
//! - Eq. (7): the back-pressure line receives Ab·L̇ while opening and (At − Ab)·|L̇| while
//!   closing (volume balance of the two chambers); the printed (At + Ab) term reads as an
//!   extraction error.
//! - Eq. (15): B5 carries −Ab/me (the back pressure closes the valve, eq. (1)).
//! - The top snubber acts only while closing: its check valve opens at valve opening (Sec. 2).
//! - Eq. (4) and the main valve of eq. (9): see [`full`] for how the delays t0, t1 are placed.

#[cfg(test)]
pub(crate) mod envelope;
pub mod event;
pub mod full;
pub mod lpv;
pub mod params;
mod piston;
pub mod reduced;
pub mod tables;

pub use event::{mean_relative_error_pct, run_event, run_event_with, EhvvaPlant, EventMetrics, ValveEvent};
#[cfg(feature = "std")]
pub use event::{run_event_trace, EventTrace};
pub use full::EhvvaFull;
pub use lpv::{EhvvaLpv, LpvAffine, N_THETA};
pub use params::{EhvvaError, EhvvaInputs, EhvvaParams, EhvvaTableData, EhvvaValveParams, PaperTest, PAPER_TESTS};
pub use reduced::EhvvaReduced;
pub use tables::{t_delay_ms, EhvvaTables, EhvvaTablesAt, ValveMotionData, VALVE_MOTION_P_BACK_MPA};
