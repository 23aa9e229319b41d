//! The vacuum tank and its electric pump (paper Section 4, eqs. (13), (14)) and the system of
//! three actuators on one tank.

use super::*;

/// Vacuum tank and electric pump (Section 4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumTankParams {
    pub volume_l: f64,
    pub temp_amb_k: f64,
    /// Effective area of the base leakage from ambient into the tank (Sec. 3.3, eq. (3)).
    pub base_leak_area_mm2: f64,
    /// Eq. (14): ṁ = a1/(p_amb/p_tank + a2) + a3, limited at 0 (the pump cannot blow in).
    pub pump_a1_mg_s: f64,
    pub pump_a2: f64,
    pub pump_a3_mg_s: f64,
}

impl VacuumTankParams {
    /// Values read from Figs. 13-15: pump flow 800 mg/s at ratio 1 falling to 0 at ratio 7
    /// (Fig. 15: 0..8e-4 kg/s over 1..7), so the tank bottoms out near p_amb/7 ≈ 15 kPa
    /// (Fig. 14's lowest). 4 L and 0.02 mm² give a base rise of ~0.1 kPa/s at 30 kPa, with the
    /// valves adding to the 0.2-0.5 kPa/s slopes of Fig. 14.
    pub fn paper() -> Self {
        Self {
            volume_l: 4.0,
            temp_amb_k: TEMP_AMB_K,
            base_leak_area_mm2: 0.02,
            pump_a1_mg_s: 1500.0,
            pump_a2: 0.5,
            pump_a3_mg_s: -200.0,
        }
    }

    fn validate(&self) -> Result<(), VacuumParamError> {
        let bad = |name| Err(VacuumParamError::BadParameter(name));
        if !(self.volume_l.is_finite() && self.volume_l >= 0.01) {
            return bad("volume_l");
        }
        if !(self.temp_amb_k.is_finite() && self.temp_amb_k > 100.0) {
            return bad("temp_amb_k");
        }
        if !(self.base_leak_area_mm2.is_finite() && self.base_leak_area_mm2 >= 0.0) {
            return bad("base_leak_area_mm2");
        }
        if !(self.pump_a1_mg_s.is_finite() && self.pump_a1_mg_s.abs() < 1e5) {
            return bad("pump_a1_mg_s");
        }
        if !(self.pump_a2.is_finite() && self.pump_a2 > -1.0) {
            return bad("pump_a2");
        }
        if !(self.pump_a3_mg_s.is_finite() && self.pump_a3_mg_s.abs() < 1e5) {
            return bad("pump_a3_mg_s");
        }
        Ok(())
    }
}

/// Isothermal vacuum tank (eq. (13)) with its pump (eq. (14)) and base leakage.
#[derive(Clone, Copy, Debug)]
pub struct VacuumTank<R: Real> {
    /// kPa per mg: R·T/V.
    c_pressure: R,
    c_orifice: R,
    base_leak_area_mm2: R,
    a1: R,
    a2: R,
    a3: R,
    p_tank_kpa: R,
}

/// Lowest tank pressure the model accepts (keeps p_amb/p_tank finite).
const P_TANK_MIN_KPA: f64 = 1.0;
/// Tank integration step limit (slowest mode ~ seconds).
const TANK_H_MAX_S: f64 = 0.01;

impl<R: Real> VacuumTank<R> {
    pub fn new(p: &VacuumTankParams, p_tank_initial_kpa: f64) -> Result<Self, VacuumParamError> {
        p.validate()?;
        if !(p_tank_initial_kpa.is_finite() && (P_TANK_MIN_KPA..=400.0).contains(&p_tank_initial_kpa)) {
            return Err(VacuumParamError::BadParameter("p_tank_initial_kpa"));
        }
        let rt = R_AIR_J_PER_KG_K * p.temp_amb_k;
        let f = R::from_f64;
        Ok(Self {
            // kPa = R·T[J/kg] · m[mg]·1e-6 / (V[L]·1e-3) / 1e3
            c_pressure: f(rt * 1e-6 / p.volume_l),
            c_orifice: f(1e3 / libm::sqrt(rt)),
            base_leak_area_mm2: f(p.base_leak_area_mm2),
            a1: f(p.pump_a1_mg_s),
            a2: f(p.pump_a2),
            a3: f(p.pump_a3_mg_s),
            p_tank_kpa: f(p_tank_initial_kpa),
        })
    }

    pub fn p_tank_kpa(&self) -> R {
        self.p_tank_kpa
    }

    /// Pump mass flow out of the tank, eq. (14), limited at zero beyond the pump's lowest
    /// pressure.
    pub fn pump_flow_mg_s(&self, p_amb_kpa: R, p_tank_kpa: R) -> R {
        let ratio = p_amb_kpa / p_tank_kpa.max(R::from_f64(P_TANK_MIN_KPA));
        (self.a1 / (ratio + self.a2) + self.a3).max(R::ZERO)
    }

    /// Base leakage from ambient into the tank, eq. (3).
    pub fn base_leak_mg_s(&self, p_amb_kpa: R, p_tank_kpa: R) -> R {
        orifice_flow_mg_s(p_amb_kpa, p_tank_kpa, self.base_leak_area_mm2, self.c_orifice)
    }

    /// Advances eq. (13) by `dt_s` with the actuators' summed flow `inflow_mg_s` (held over the
    /// step) and returns the tank pressure. The tank is kept within [1 kPa, p_amb]: every source
    /// is at or below ambient, so anything above is integration overshoot.
    pub fn step(&mut self, pump_on: bool, inflow_mg_s: R, p_amb_kpa: R, dt_s: R) -> R {
        if !positive(dt_s) {
            return self.p_tank_kpa;
        }
        let n = substeps(dt_s, TANK_H_MAX_S);
        let h = dt_s / R::from_f64(n);
        let p_min = R::from_f64(P_TANK_MIN_KPA);
        for _ in 0..(n as u32) {
            let p = self.p_tank_kpa;
            let pump = if pump_on {
                self.pump_flow_mg_s(p_amb_kpa, p)
            } else {
                R::ZERO
            };
            let net = inflow_mg_s + self.base_leak_mg_s(p_amb_kpa, p) - pump;
            self.p_tank_kpa = (p + self.c_pressure * net * h).clamp(p_min, p_amb_kpa.max(p_min));
        }
        self.p_tank_kpa
    }
}

/// The three actuators of the two-stage system (LPT wastegate, HPT bypass, HPC bypass)
/// sharing one tank and pump (Figs. 1, 2).
#[derive(Clone, Copy, Debug)]
pub struct VacuumSystem<R: Real> {
    pub lpt: VacuumValveActuator<R>,
    pub hpt: VacuumValveActuator<R>,
    pub hpc: VacuumValveActuator<R>,
    pub tank: VacuumTank<R>,
}

/// One step's result for the whole system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumSystemOutputs<R> {
    /// LPT, HPT, HPC.
    pub actuators: [VacuumOutputs<R>; 3],
    pub p_tank_kpa: R,
    /// Pump flow at the start of the step (0 when off).
    pub pump_flow_mg_s: R,
}

impl<R: Real> VacuumSystem<R> {
    /// The paper's system: [`VacuumParams::lpt`], [`VacuumParams::hpt`], [`VacuumParams::hpc`]
    /// and [`VacuumTankParams::paper`].
    pub fn paper(p_tank_initial_kpa: f64) -> Result<Self, VacuumParamError> {
        Self::new(
            &VacuumParams::lpt(),
            &VacuumParams::hpt(),
            &VacuumParams::hpc(),
            &VacuumTankParams::paper(),
            p_tank_initial_kpa,
        )
    }

    pub fn new(
        lpt: &VacuumParams,
        hpt: &VacuumParams,
        hpc: &VacuumParams,
        tank: &VacuumTankParams,
        p_tank_initial_kpa: f64,
    ) -> Result<Self, VacuumParamError> {
        Ok(Self {
            lpt: VacuumValveActuator::new(lpt)?,
            hpt: VacuumValveActuator::new(hpt)?,
            hpc: VacuumValveActuator::new(hpc)?,
            tank: VacuumTank::new(tank, p_tank_initial_kpa)?,
        })
    }

    /// Duties in the order LPT, HPT, HPC. The actuators see the tank pressure at the start of
    /// the step; the tank then integrates their summed flow.
    pub fn step(
        &mut self,
        duties_pct: [R; 3],
        u_batt_v: R,
        p_amb_kpa: R,
        pump_on: bool,
        dt_s: R,
    ) -> VacuumSystemOutputs<R> {
        let p_tank = self.tank.p_tank_kpa();
        let input = |duty_pct| VacuumInputs {
            duty_pct,
            u_batt_v,
            p_amb_kpa,
            p_tank_kpa: p_tank,
        };
        let [d_lpt, d_hpt, d_hpc] = duties_pct;
        let outs = [
            self.lpt.step(&input(d_lpt), dt_s),
            self.hpt.step(&input(d_hpt), dt_s),
            self.hpc.step(&input(d_hpc), dt_s),
        ];
        let inflow = outs[0].flow_to_tank_mg_s + outs[1].flow_to_tank_mg_s + outs[2].flow_to_tank_mg_s;
        let pump_flow = if pump_on {
            self.tank.pump_flow_mg_s(p_amb_kpa, p_tank)
        } else {
            R::ZERO
        };
        let p_tank_new = self.tank.step(pump_on, inflow, p_amb_kpa, dt_s);
        VacuumSystemOutputs {
            actuators: outs,
            p_tank_kpa: p_tank_new,
            pump_flow_mg_s: pump_flow,
        }
    }
}
