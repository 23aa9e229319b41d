//! How the EHVVA geometry of `EhvvaParams::paper_default` was fitted (issue #14): a (1+1)
//! evolution strategy in log space over the 16 geometry parameters the paper does not print,
//! minimising Σ (rel_err/tolerance)² over the paper-check rows the geometry moves (Table 3,
//! Sec. 2/Fig. 2, Fig. 8, Table 4 times, Fig. 10's closing), with a steep penalty beyond 85 % of
//! a row's tolerance. Starts from the current defaults.
//!
//! `cargo run --release -p hil-host --example ehvva_fit -- [iterations] [seed]` (about 10 ms per
//! evaluation; 4000 iterations in 40 s); prints the parameters and the rows.

use hil_host::paper_check::{ehvva_rows, Row};
use model_core::ehvva::EhvvaParams;

const NAMES: [&str; 16] = [
    "mass_kg",
    "area_top_mm2",
    "area_bottom_mm2",
    "spring_n_per_mm",
    "spring_preload_mm",
    "area_main_mm2",
    "area_top_orifice_mm2",
    "area_top_switch_orifice_mm2",
    "area_top_notch_mm2",
    "snub_top_len_mm",
    "area_bottom_port_mm2",
    "area_bottom_notch_mm2",
    "area_bottom_min_mm2",
    "snub_bottom_len_mm",
    "friction_n_per_m_s",
    "area_main_return_mm2",
];

fn get(p: &EhvvaParams) -> [f64; 16] {
    [
        p.mass_kg,
        p.area_top_mm2,
        p.area_bottom_mm2,
        p.spring_n_per_mm,
        p.spring_preload_mm,
        p.area_main_mm2,
        p.area_top_orifice_mm2,
        p.area_top_switch_orifice_mm2,
        p.area_top_notch_mm2,
        p.snub_top_len_mm,
        p.area_bottom_port_mm2,
        p.area_bottom_notch_mm2,
        p.area_bottom_min_mm2,
        p.snub_bottom_len_mm,
        p.friction_n_per_m_s,
        p.area_main_return_mm2,
    ]
}
fn set(p: &mut EhvvaParams, x: &[f64; 16]) {
    p.mass_kg = x[0];
    p.area_top_mm2 = x[1];
    p.area_bottom_mm2 = x[2];
    p.spring_n_per_mm = x[3];
    p.spring_preload_mm = x[4];
    p.area_main_mm2 = x[5];
    p.area_top_orifice_mm2 = x[6];
    p.area_top_switch_orifice_mm2 = x[7];
    p.area_top_notch_mm2 = x[8];
    p.snub_top_len_mm = x[9];
    p.area_bottom_port_mm2 = x[10];
    p.area_bottom_notch_mm2 = x[11];
    p.area_bottom_min_mm2 = x[12];
    p.snub_bottom_len_mm = x[13].min(1.5);
    p.friction_n_per_m_s = x[14];
    p.area_main_return_mm2 = x[15];
}
fn used(r: &Row) -> bool {
    !(r.id.contains(".cd.") || r.id.contains("_delay_ms") || r.id.contains("opening_faster"))
}
fn cost(x: &[f64; 16]) -> (f64, usize) {
    let mut p = EhvvaParams::paper_default();
    set(&mut p, x);
    match ehvva_rows(&p, false) {
        Err(_) => (1e9, 99),
        Ok(rows) => {
            let mut c = 0.0;
            let mut fails = 0;
            for r in rows.iter().filter(|r| used(r)) {
                let e = r.rel_err / r.tolerance;
                c += e * e
                    + if e.abs() > 0.85 {
                        60.0 * (e.abs() - 0.85).powi(2)
                    } else {
                        0.0
                    };
                if !r.pass {
                    fails += 1;
                }
            }
            (c, fails)
        }
    }
}
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.next().max(1e-12), self.next());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}
fn main() {
    let iters: usize = std::env::args().nth(1).map_or(2000, |a| a.parse().unwrap());
    let seed: u64 = std::env::args().nth(2).map_or(7, |a| a.parse().unwrap());
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ seed);
    let mut best = get(&EhvvaParams::paper_default());

    let (mut bc, mut bf) = cost(&best);
    println!("start cost {bc:.3} fails {bf}");
    let mut sigma = 0.15;
    let mut succ = 0usize;
    for it in 0..iters {
        let mut x = best;
        let k = 1 + (rng.next() * 4.0) as usize;
        for _ in 0..k {
            let mut i = (rng.next() * 16.0) as usize;
            if std::env::var("FIX_MAIN").is_ok() && i == 5 {
                i = 15;
            }
            x[i] *= (sigma * rng.normal()).exp();
        }
        x[13] = x[13].min(1.5);
        let (c, f) = cost(&x);
        if c < bc {
            best = x;
            bc = c;
            bf = f;
            succ += 1;
        }
        if it % 100 == 99 {
            sigma = if succ > 20 {
                sigma * 1.3
            } else if succ < 5 {
                (sigma * 0.7).max(0.01)
            } else {
                sigma
            };
            succ = 0;
            println!("it {it} cost {bc:.3} fails {bf} sigma {sigma:.3}");
        }
    }
    for (n, v) in NAMES.iter().zip(best) {
        println!("{n}: {v:.4}");
    }
    let mut p = EhvvaParams::paper_default();
    set(&mut p, &best);
    for r in ehvva_rows(&p, false).unwrap() {
        println!(
            "{:<45} {:>8.3} {:>8.3} {:+6.1}% {}",
            r.id,
            r.paper,
            r.model,
            100.0 * r.rel_err,
            if r.pass { "ok" } else { "FAIL" }
        );
    }
}
