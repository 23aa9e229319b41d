//! `identify ehvva` on a bench recording that is not the generator's layout (issue #13, "any
//! recording of a test matrix"): other supply pressures (5.5, 6.5, 7.5 MPa) and temperatures
//! (10, 45, 80 °C) than Table 1's, every event with its own dwell (6..25 ms), the events in a
//! shuffled order (conditions interleaved, not one after another), 20 kHz, the bench's noisy
//! lift, pressure and temperature channels. The events are grouped into the nine conditions
//! and td (onset and joint) and Cd come back within 5 % of the generating tables at each
//! condition, τp within 10 % (it slides along the td-τp ridge, docs/identification.md); the td
//! tables on model-core's breakpoints inside the tested range within 5 % too.

use hil_host::diagnose::ehvva::Events;
use hil_host::generate::ehvva::{log_text, run_bench, Sensors, Test};
use hil_host::generate::Rng;
use hil_host::identify::ehvva::{default_options, identify};
use hil_host::log::parse_log;
use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaReduced, EhvvaTables};

const DT_MS: f64 = 0.05;

#[test]
fn shuffled_matrix_with_other_setpoints_and_dwells_gives_the_tables() {
    let mut rng = Rng::new(31);
    let mut tests = Vec::new();
    for ph in [5.5, 6.5, 7.5] {
        for t in [10.0, 45.0, 80.0] {
            let mut at = |p_back_mpa: f64, lift_high: bool, snubber_on: bool| Test {
                inputs: EhvvaInputs {
                    p_supply_mpa: ph,
                    p_back_mpa,
                    temp_c: t,
                    lift_high,
                    snubber_on,
                },
                dwell_ms: rng.uniform(6.0, 25.0),
            };
            let mut c = vec![
                at(1.0, false, false),
                at(1.0, false, true),
                at(3.0, false, false),
                at(3.0, false, true),
            ];
            if ph > 6.0 {
                c.push(at(1.0, true, false));
            }
            tests.extend(c);
        }
    }
    for i in (1..tests.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        tests.swap(i, j);
    }
    // Not grouped by condition: the order interleaves them.
    assert!(tests
        .windows(2)
        .any(|w| w[0].inputs.p_supply_mpa != w[1].inputs.p_supply_mpa || w[0].inputs.temp_c != w[1].inputs.temp_c));
    let p = EhvvaParams::paper_default();
    let sensors = Sensors {
        lift_sigma_mm: 0.003,
        lift_lsb_mm: 0.002,
        p_sigma_mpa: 0.01,
        p_lsb_mpa: 0.005,
        temp_sigma_c: 0.3,
        temp_lsb_c: 0.1,
    };
    let cols = run_bench(&tests, DT_MS, &sensors, &mut rng, |i| {
        EhvvaReduced::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    })
    .unwrap();
    let log = parse_log("shuffled.csv", &log_text("shuffled test matrix", DT_MS, &cols), None).unwrap();
    let set = Events::from_log(&log).unwrap();
    assert_eq!(set.events.len(), tests.len());
    let id = identify(std::slice::from_ref(&set), &default_options(), &mut |_, _| {}).unwrap();
    print!("{}", id.text());
    assert_eq!(id.conditions.len(), 9, "one condition per (Ph, T)");
    let truth = EhvvaTables::<f64>::new(&p).unwrap();
    // Worst relative deviation per quantity: [td (onset and joint), Cd, τp].
    let mut worst = [(0.0f64, String::new()), (0.0, String::new()), (0.0, String::new())];
    for c in &id.conditions {
        assert!(c.events == 4 || c.events == 5, "{c:?}");
        let (vo, vc) = truth.t_delay_pair_ms(c.p_supply_mpa, c.temp_c);
        let tau = truth.tau_p_ms(c.p_supply_mpa, c.temp_c);
        let cd = truth.cd(c.temp_c);
        for (k, name, got, want) in [
            (0, "td VO joint", c.td_open_ms, vo),
            (0, "td VC joint", c.td_close_ms, vc),
            (0, "td VO onset", c.td_open_onset_ms, vo),
            (0, "td VC onset", c.td_close_onset_ms, vc),
            (1, "Cd", c.cd, cd),
            (1, "Cd pass 1", c.cd_onset, cd),
            (2, "tau_p", c.tau_p_ms, tau),
        ] {
            let r = (got / want - 1.0).abs();
            if r > worst[k].0 {
                worst[k] = (
                    r,
                    format!(
                        "{name} at {:.2} MPa, {:.1} °C: {got:.4} vs {want:.4}",
                        c.p_supply_mpa, c.temp_c
                    ),
                );
            }
        }
    }
    for (w, what) in worst.iter().zip(["td", "Cd", "tau_p"]) {
        println!("worst {what} per condition: {:.1} % ({})", 100.0 * w.0, w.1);
    }
    assert!(worst[0].0 < 0.05, "{}", worst[0].1);
    assert!(worst[1].0 < 0.05, "{}", worst[1].1);
    // τp lies on the td-τp ridge (correlation -0.99, docs/identification.md): the supply
    // set-point's noise moves it by more than td; in the generator's designed matrix (two 3 MPa
    // events per condition at dwell 8 and 20 ms) 3.2 %, here with one at a random dwell and
    // one with the switch valve on, 6.5 %.
    assert!(worst[2].0 < 0.10, "{}", worst[2].1);
    // The tables on model-core's breakpoints inside the tested range (6, 7 MPa; 22, 60 °C) are
    // bilinear between the conditions: held to the same bilinear resampling of the generating
    // tables at the tested points (what a 3×3 matrix can give at best), and printed against
    // the generating tables themselves (the resampling's own error adds to that).
    let d = id.table_data();
    let (ps, ts) = ([5.5, 6.5, 7.5], [10.0, 45.0, 80.0]);
    let bilinear = |f: &dyn Fn(f64, f64) -> f64, ph: f64, t: f64| {
        let i = if ph <= 6.5 { 0 } else { 1 };
        let j = if t <= 45.0 { 0 } else { 1 };
        let (fp, ft) = ((ph - ps[i]) / 1.0, (t - ts[j]) / 35.0);
        let a = f(ps[i], ts[j]) * (1.0 - ft) + f(ps[i], ts[j + 1]) * ft;
        let b = f(ps[i + 1], ts[j]) * (1.0 - ft) + f(ps[i + 1], ts[j + 1]) * ft;
        a * (1.0 - fp) + b * fp
    };
    let mut worst_table = (0.0f64, String::new());
    let mut worst_vs_table = 0.0f64;
    for i in 0..4 {
        for j in 0..5 {
            let (ph, t) = (d.td_p_supply_mpa[i], d.td_temp_c[j]);
            if !((5.5..=7.5).contains(&ph) && (10.0..=80.0).contains(&t)) {
                continue;
            }
            let vo = bilinear(&|p, t| truth.t_delay_pair_ms(p, t).0, ph, t);
            let vc = bilinear(&|p, t| truth.t_delay_pair_ms(p, t).1, ph, t);
            for (name, got, w, table) in [
                ("td VO", d.td_open_ms[i][j], vo, p.tables.td_open_ms[i][j]),
                ("td VC", d.td_close_ms[i][j], vc, p.tables.td_close_ms[i][j]),
            ] {
                worst_vs_table = worst_vs_table.max((got / table - 1.0).abs());
                let r = (got / w - 1.0).abs();
                if r > worst_table.0 {
                    worst_table = (r, format!("{name} at {ph} MPa, {t} °C: {got:.4} vs {w:.4}"));
                }
            }
        }
    }
    println!(
        "worst td table entry in the tested range: {:.1} % ({}) against the resampled truth, {:.1} % against the generating table",
        100.0 * worst_table.0,
        worst_table.1,
        100.0 * worst_vs_table
    );
    assert!(worst_table.0 < 0.05, "{}", worst_table.1);
}
