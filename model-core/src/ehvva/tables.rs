//! The calibrated varying parameters of Sec. 5.2 as lookup tables: actuation delay td(Ph, T)
//! for valve opening (VO) and closing (VC) (Fig. 4, Table 4), main-valve time constant
//! τp(Ph, T) (Fig. 5 top) and mean discharge coefficient Cd(T) (Fig. 5 bottom, Table 4), with
//! the diagnosis effect knobs `viscosity`, `pressure-delay` and `direction-delay` applied.

use super::params::{EhvvaError, EhvvaParams};
use crate::lut::{Lut1, Lut2};
use crate::real::Real;

/// Temperature at which the `viscosity` baseline freezes Cd (the paper's reference 22 °C).
pub const CD_REFERENCE_TEMP_C: f64 = 22.0;

/// Lower bound on Cd: keeps the orifice terms finite whatever a fitted table says.
const CD_MIN: f64 = 0.05;
/// Lower bound on τp: the implicit first-order update stays exact-enough and the 1/τp
/// scheduling parameter θ1 stays below 100 per ms.
const TAU_MIN_MS: f64 = 0.01;

/// Tables and effect gains, converted to the model's number type.
#[derive(Clone, Copy, Debug)]
pub struct EhvvaTables<R: Real> {
    td_open: Lut2<R, 4, 5>,
    td_close: Lut2<R, 4, 5>,
    tau: Lut2<R, 2, 3>,
    cd: Lut1<R, 4>,
    cd_reference: R,
    p_nominal: R,
    gain_viscosity: R,
    gain_pressure_delay: R,
    gain_direction_delay: R,
}

impl<R: Real> EhvvaTables<R> {
    pub fn new(params: &EhvvaParams) -> Result<Self, EhvvaError> {
        params.validate()?;
        let t = &params.tables;
        let td_open = Lut2::new(t.td_p_supply_mpa, t.td_temp_c, t.td_open_ms)
            .map_err(|e| EhvvaError::Table("tables.td_open_ms", e))?;
        let td_close = Lut2::new(t.td_p_supply_mpa, t.td_temp_c, t.td_close_ms)
            .map_err(|e| EhvvaError::Table("tables.td_close_ms", e))?;
        let tau = Lut2::new(t.tau_p_supply_mpa, t.tau_temp_c, t.tau_ms)
            .map_err(|e| EhvvaError::Table("tables.tau_ms", e))?;
        let cd = Lut1::new(t.cd_temp_c, t.cd).map_err(|e| EhvvaError::Table("tables.cd", e))?;
        let cd_reference = cd.eval(R::from_f64(CD_REFERENCE_TEMP_C));
        Ok(Self {
            td_open,
            td_close,
            tau,
            cd,
            cd_reference,
            p_nominal: R::from_f64(params.delay_nominal_p_supply_mpa),
            gain_viscosity: R::from_f64(params.effect_viscosity),
            gain_pressure_delay: R::from_f64(params.effect_pressure_delay),
            gain_direction_delay: R::from_f64(params.effect_direction_delay),
        })
    }

    /// Mean effective discharge coefficient Cd(T) (Table 4), with the `viscosity` effect gain.
    pub fn cd(&self, temp_c: R) -> R {
        let table = self.cd.eval(temp_c);
        (self.cd_reference + self.gain_viscosity * (table - self.cd_reference))
            .max(R::from_f64(CD_MIN))
    }

    /// Actuation delay td(Ph, T) in ms (Fig. 4, eq. (11)) for the opening (`true`, VO) or
    /// closing (`false`, VC) edge, with the `pressure-delay` and `direction-delay` gains. The
    /// firmware advances each valve event by this delay.
    pub fn t_delay_ms(&self, p_supply_mpa: R, temp_c: R, opening: bool) -> R {
        let (open, close) = self.t_delay_pair_ms(p_supply_mpa, temp_c);
        if opening {
            open
        } else {
            close
        }
    }

    /// `(VO, VC)` delays at once (both are needed every step by the models).
    pub fn t_delay_pair_ms(&self, p_supply_mpa: R, temp_c: R) -> (R, R) {
        let p_eff = self.p_nominal + self.gain_pressure_delay * (p_supply_mpa - self.p_nominal);
        let vo = self.td_open.eval(p_eff, temp_c);
        let vc = self.td_close.eval(p_eff, temp_c);
        let half = R::from_f64(0.5);
        let mean = half * (vo + vc);
        let half_split = self.gain_direction_delay * half * (vo - vc);
        (
            (mean + half_split).max(R::ZERO),
            (mean - half_split).max(R::ZERO),
        )
    }

    /// Main-valve outlet pressure time constant τp(Ph, T) in ms (eq. (10), Fig. 5 top).
    pub fn tau_p_ms(&self, p_supply_mpa: R, temp_c: R) -> R {
        self.tau
            .eval(p_supply_mpa, temp_c)
            .max(R::from_f64(TAU_MIN_MS))
    }
}

/// Host convenience: td(Ph, T) in f64 straight from a parameter set.
pub fn t_delay_ms(
    params: &EhvvaParams,
    p_supply_mpa: f64,
    temp_c: f64,
    opening: bool,
) -> Result<f64, EhvvaError> {
    Ok(EhvvaTables::<f64>::new(params)?.t_delay_ms(p_supply_mpa, temp_c, opening))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tables() -> EhvvaTables<f64> {
        EhvvaTables::new(&EhvvaParams::paper_default()).unwrap()
    }

    #[test]
    fn table4_values_at_5_mpa() {
        let t = tables();
        for (temp, cd, vo, vc) in [
            (-20.0, 0.21, 4.2, 4.0),
            (22.0, 0.40, 3.7, 3.0),
            (60.0, 0.65, 3.5, 3.0),
            (100.0, 0.70, 3.2, 3.0),
        ] {
            assert!((t.cd(temp) - cd).abs() < 1e-12, "Cd({temp})");
            assert!(
                (t.t_delay_ms(5.0, temp, true) - vo).abs() < 1e-9,
                "VO delay at {temp}"
            );
            assert!(
                (t.t_delay_ms(5.0, temp, false) - vc).abs() < 0.05,
                "VC delay at {temp}"
            );
        }
    }

    #[test]
    fn delay_falls_with_pressure_and_vc_below_vo() {
        let t = tables();
        for temp in [-20.0, 0.0, 22.0, 60.0, 100.0] {
            let mut last_vo = f64::MAX;
            let mut last_vc = f64::MAX;
            for i in 0..=30 {
                let p = 5.0 + 0.1 * i as f64;
                let (vo, vc) = t.t_delay_pair_ms(p, temp);
                assert!(
                    vo < last_vo + 1e-12 && vc < last_vc + 1e-12,
                    "not falling at {p} MPa"
                );
                assert!(vc < vo, "VC not below VO at {p} MPa, {temp} °C");
                last_vo = vo;
                last_vc = vc;
            }
        }
        // Steeper below 0 °C than above (Fig. 4).
        let slope_cold = (t.t_delay_ms(6.0, -20.0, true) - t.t_delay_ms(6.0, 0.0, true)) / 20.0;
        let slope_warm = (t.t_delay_ms(6.0, 0.0, true) - t.t_delay_ms(6.0, 100.0, true)) / 100.0;
        assert!(slope_cold > 1.5 * slope_warm);
    }

    #[test]
    fn tau_p_linear_in_pressure_mean_near_0_1_ms() {
        let t = tables();
        let mut sum = 0.0;
        for i in 0..=30 {
            let p = 5.0 + 0.1 * i as f64;
            sum += t.tau_p_ms(p, 22.0);
        }
        let mean = sum / 31.0;
        assert!((mean - 0.1).abs() < 0.015, "mean τp {mean}");
        let mid = t.tau_p_ms(6.5, 22.0);
        assert!((mid - 0.5 * (t.tau_p_ms(5.0, 22.0) + t.tau_p_ms(8.0, 22.0))).abs() < 1e-12);
        // Nearly flat in temperature.
        assert!((t.tau_p_ms(6.0, -20.0) / t.tau_p_ms(6.0, 100.0) - 1.0).abs() < 0.1);
    }

    #[test]
    fn effects_off_give_the_baseline() {
        let mut p = EhvvaParams::paper_default();
        p.effect_viscosity = 0.0;
        p.effect_pressure_delay = 0.0;
        p.effect_direction_delay = 0.0;
        let t = EhvvaTables::<f64>::new(&p).unwrap();
        assert!((t.cd(-20.0) - 0.40).abs() < 1e-12 && (t.cd(100.0) - 0.40).abs() < 1e-12);
        let (vo5, vc5) = t.t_delay_pair_ms(5.0, 22.0);
        let (vo8, vc8) = t.t_delay_pair_ms(8.0, 22.0);
        assert_eq!(vo5, vo8);
        assert_eq!(vc5, vc8);
        assert_eq!(vo5, vc5);
        // At the nominal pressure the one delay is the mean of VO and VC.
        let full = tables();
        let (vo7, vc7) = full.t_delay_pair_ms(7.0, 22.0);
        assert!((vo5 - 0.5 * (vo7 + vc7)).abs() < 1e-12);
        // Gains in between scale continuously.
        p.effect_viscosity = 0.5;
        let half = EhvvaTables::<f64>::new(&p).unwrap();
        assert!((half.cd(-20.0) - 0.5 * (0.40 + 0.21)).abs() < 1e-12);
    }

    #[test]
    fn bad_gain_is_named() {
        let mut p = EhvvaParams::paper_default();
        p.effect_snubber = -1.0;
        assert_eq!(
            EhvvaTables::<f64>::new(&p).err(),
            Some(EhvvaError::InvalidParameter("effect_snubber"))
        );
        let mut p = EhvvaParams::paper_default();
        p.tables.td_temp_c[2] = -30.0;
        assert!(matches!(
            EhvvaTables::<f64>::new(&p),
            Err(EhvvaError::Table("tables.td_open_ms", _))
        ));
    }
}
