//! `hil-host calibrate`: from a generated unit's bench logs to the ECU's calibration image, its
//! A2L and JSON, and the ECU running it.
//!
//! The A2L is read back three times: by `a2lfile` (load + its consistency check), by a small
//! structural reader in this file (tokens of the `CHARACTERISTIC`/`AXIS_PTS` blocks) that
//! takes every object's address, element count and limits and checks the image's bytes there,
//! and by pya2ldb (tools/py/read_a2l.py: an ASAP2 parser and validator of its own, in the
//! venv that tools/test.sh makes; skipped without it unless HIL_REQUIRE_PY is set).
use std::path::{Path, PathBuf};

use a2lfile::A2lObjectName;
use hil_host::calibrate::{self, FLASH_BASE};
use hil_host::generate;
use hil_host::log::Plant;
use hil_host::run::{run_unit, Summary};
use model_core::ecu::calibration::{CalibrationImage, CHARACTERISTICS, IMAGE_BYTES};
use model_core::ecu::lockstep::EcuCoreConfig;

mod py_venv;

mod calibrate_common;
use calibrate_common::{sweep, workdir, write_case};

fn f32_at(image: &[u8], addr: u64) -> f32 {
    let off = (addr - u64::from(FLASH_BASE)) as usize;
    f32::from_le_bytes(image[off..off + 4].try_into().unwrap())
}

/// Tokens of an A2L text: quoted strings whole, comments dropped.
fn tokens(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c.is_whitespace() {
            continue;
        }
        if c == '"' {
            let mut s = String::new();
            for d in chars.by_ref() {
                if d == '"' {
                    break;
                }
                s.push(d);
            }
            out.push(format!("\"{s}\""));
        } else if c == '/' && chars.peek() == Some(&'*') {
            let mut prev = ' ';
            for d in chars.by_ref() {
                if prev == '*' && d == '/' {
                    break;
                }
                prev = d;
            }
        } else {
            let mut s = String::from(c);
            while let Some(&d) = chars.peek() {
                if d.is_whitespace() {
                    break;
                }
                s.push(d);
                chars.next();
            }
            out.push(s);
        }
    }
    out
}

/// One object of the A2L as the structural reader sees it.
#[derive(Debug)]
struct Object {
    kind: String,
    name: String,
    address: u64,
    count: usize,
    lower: f64,
    upper: f64,
}

/// The CHARACTERISTIC and AXIS_PTS blocks: address, element count (VALUE 1, VAL_BLK its
/// MATRIX_DIM, CURVE/MAP the product of their AXIS_DESCR point counts, AXIS_PTS its maximum
/// number of points) and limits.
fn objects(text: &str) -> Vec<Object> {
    let t = tokens(text);
    let num = |s: &str| -> f64 { s.parse().unwrap_or_else(|_| panic!("not a number: {s}")) };
    // Addresses in hex (0x...) or decimal, as A2L allows.
    let hex = |s: &str| match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).unwrap(),
        None => s.parse().unwrap(),
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < t.len() {
        if t[i] == "/begin" && t[i + 1] == "CHARACTERISTIC" {
            // name "desc" TYPE address deposit max_diff conversion lower upper
            let kind = t[i + 4].clone();
            let mut o = Object {
                kind: kind.clone(),
                name: t[i + 2].clone(),
                address: hex(&t[i + 5]),
                count: 1,
                lower: num(&t[i + 9]),
                upper: num(&t[i + 10]),
            };
            let end = (i..t.len())
                .find(|&k| t[k] == "/end" && t[k + 1] == "CHARACTERISTIC")
                .unwrap();
            let mut axes = Vec::new();
            for k in i + 11..end {
                if t[k] == "/begin" && t[k + 1] == "AXIS_DESCR" {
                    // attribute input_quantity conversion max_axis_points lower upper
                    axes.push(t[k + 5].parse::<usize>().unwrap());
                }
                if t[k] == "MATRIX_DIM" {
                    o.count = t[k + 1].parse().unwrap();
                }
            }
            if kind == "CURVE" || kind == "MAP" {
                o.count = axes.iter().product();
            }
            out.push(o);
            i = end;
        } else if t[i] == "/begin" && t[i + 1] == "AXIS_PTS" {
            // name "desc" address input_quantity deposit max_diff conversion max_points lower upper
            out.push(Object {
                kind: "AXIS_PTS".into(),
                name: t[i + 2].clone(),
                address: hex(&t[i + 4]),
                count: t[i + 9].parse().unwrap(),
                lower: num(&t[i + 10]),
                upper: num(&t[i + 11]),
            });
        }
        i += 1;
    }
    out
}

#[test]
fn ehvva_unit_gives_an_image_json_and_a2l_that_agree() {
    let dir = workdir("outputs");
    let case = generate::generate(Plant::Ehvva, "pressure-delay", 7).unwrap();
    let (est, _) = write_case(&case, &dir.join("unit"));
    let outcome = calibrate::calibrate(std::slice::from_ref(&est), &mut |_| {}).unwrap();
    let written = calibrate::write_outputs(&outcome, &dir.join("cal"), FLASH_BASE).unwrap();
    assert_eq!(written.len(), 3);
    let image = std::fs::read(dir.join("cal/calibration.bin")).unwrap();
    assert_eq!(image.len(), IMAGE_BYTES);
    let cal = CalibrationImage::parse(&image).unwrap();
    // The identified td table falls with supply pressure as the unit's does (gain 0.67).
    let td = cal.ehvva_tables.td_open_ms;
    for j in 0..5 {
        assert!(
            td[0][j] > td[3][j],
            "td VO at 5 MPa {} not above 8 MPa {}",
            td[0][j],
            td[3][j]
        );
    }

    // JSON: flash base, every characteristic with its address, value and source.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cal/calibration.json")).unwrap()).unwrap();
    assert_eq!(json["flash_base"], serde_json::json!(FLASH_BASE));
    let chars = json["characteristics"].as_object().unwrap();
    assert_eq!(chars.len(), CHARACTERISTICS.len());
    for c in CHARACTERISTICS.iter() {
        let e = &chars[c.name];
        let addr = u64::from(FLASH_BASE) + c.offset() as u64;
        assert_eq!(e["address"], format!("0x{addr:08X}"), "{}", c.name);
        let first = match &e["value"] {
            serde_json::Value::Array(a) => match &a[0] {
                serde_json::Value::Array(row) => row[0].as_f64().unwrap(),
                v => v.as_f64().unwrap(),
            },
            v => v.as_f64().unwrap(),
        };
        assert_eq!(first as f32, f32_at(&image, addr), "{}", c.name);
    }
    let from = |n: &str| chars[n]["source"]["from"].as_str().unwrap().to_string();
    assert_eq!(from("ehvva.td_open_ms"), "log");
    assert!(chars["ehvva.td_open_ms"]["source"]["logs"][0]
        .as_str()
        .unwrap()
        .ends_with("estimation.csv"));
    // The diagnosis named the extension the td tables carry.
    let method = chars["ehvva.td_open_ms"]["source"]["method"].as_str().unwrap();
    assert!(method.contains("cause `pressure-delay`"), "{method}");
    assert_eq!(from("evvt.alpha_deg_per_s2_rpm"), "paper default");
    assert_eq!(from("vacuum.hpc.fc_kpa"), "paper default");

    // A2L, reader 1: a2lfile loads it strictly and its consistency check finds nothing.
    let text = std::fs::read_to_string(dir.join("cal/calibration.a2l")).unwrap();
    let (a2l, log) = a2lfile::load_from_string(&text, None, true).unwrap();
    assert!(log.is_empty(), "{log:?}");
    assert!(a2l.check().is_empty(), "{:?}", a2l.check());
    let m = &a2l.project.module[0];
    assert_eq!(m.characteristic.len() + m.axis_pts.len(), CHARACTERISTICS.len());
    for ch in m.characteristic.iter() {
        let c = CHARACTERISTICS.iter().find(|c| c.name == ch.get_name()).unwrap();
        assert_eq!(ch.address, FLASH_BASE + c.offset() as u32, "{}", c.name);
    }

    // A2L, reader 2: every object's values in the image, inside its limits.
    let objs = objects(&text);
    assert_eq!(objs.len(), CHARACTERISTICS.len());
    let mut covered = 0;
    for o in &objs {
        let c = CHARACTERISTICS
            .iter()
            .find(|c| c.name == o.name)
            .unwrap_or_else(|| panic!("{o:?}"));
        assert_eq!(o.count, c.shape.len(), "{}", o.name);
        let expect_kind = match c.shape {
            model_core::ecu::calibration::Shape::Value => "VALUE",
            model_core::ecu::calibration::Shape::Array(_) => "VAL_BLK",
            model_core::ecu::calibration::Shape::Curve { .. } => "CURVE",
            model_core::ecu::calibration::Shape::Map { .. } => "MAP",
            model_core::ecu::calibration::Shape::Axis(_) => "AXIS_PTS",
        };
        assert_eq!(o.kind, expect_kind, "{}", o.name);
        for k in 0..o.count {
            let v = f64::from(f32_at(&image, o.address + 4 * k as u64));
            assert!(
                v >= o.lower && v <= o.upper,
                "{}[{k}] = {v} outside {}..{}",
                o.name,
                o.lower,
                o.upper
            );
        }
        covered += 4 * o.count;
    }
    // The objects cover every value byte between the header and the CRC.
    assert_eq!(covered, IMAGE_BYTES - 16 - 4);

    // A2L, reader 3: pya2ldb, an ASAP2 parser of its own, as a calibration tool reads the file.
    if let Some(py) = py_venv::python() {
        pya2l_reads_the_image(&py, &dir.join("cal"), &image, &json);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Reads `cal/calibration.a2l` with pya2ldb (tools/py/read_a2l.py) and checks what it finds
/// against the image and its JSON: no message of its ASAP2 validator, one conversion per name,
/// the image's identification (EPK at ADDR_EPK), and every object at its address with the
/// image's f32 layout, its unit's conversion, its limits, its axes, and the JSON's values.
fn pya2l_reads_the_image(py: &Path, cal: &Path, image: &[u8], json: &serde_json::Value) {
    use model_core::ecu::calibration::Shape;
    use serde_json::Value;
    let out = cal.join("pya2l.json");
    let o = std::process::Command::new(py)
        .arg(py_venv::root().join("tools/py/read_a2l.py"))
        .arg(cal.join("calibration.a2l"))
        .arg(&out)
        .output()
        .expect("python runs");
    assert!(
        o.status.success(),
        "read_a2l.py failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["diagnostics"], serde_json::json!([]), "pya2l's validator");
    assert_eq!(r["byte_order"], "MSB_LAST");
    let segment = &r["memory_segments"][0];
    assert_eq!(segment["address"], serde_json::json!(FLASH_BASE));
    assert_eq!(segment["size"], serde_json::json!(IMAGE_BYTES));
    let epk = r["epk"].as_str().unwrap().as_bytes();
    let epk_at = r["addr_epk"][0].as_u64().unwrap() - u64::from(FLASH_BASE);
    assert_eq!(&image[epk_at as usize..epk_at as usize + epk.len()], epk, "EPK");

    let layouts = &r["record_layouts"];
    let mut unit_of = std::collections::BTreeMap::new();
    for cm in r["compu_methods"].as_array().unwrap() {
        let name = cm["name"].as_str().unwrap();
        assert_eq!(cm["type"], "IDENTICAL", "{name}");
        let before = unit_of.insert(name.to_string(), cm["unit"].as_str().unwrap().to_string());
        assert!(before.is_none(), "COMPU_METHOD {name} defined twice");
    }
    let objects: Vec<&Value> = r["characteristics"]
        .as_array()
        .unwrap()
        .iter()
        .chain(r["axis_pts"].as_array().unwrap())
        .collect();
    assert_eq!(objects.len(), CHARACTERISTICS.len());
    let values = json["characteristics"].as_object().unwrap();
    for c in CHARACTERISTICS.iter() {
        let o = objects
            .iter()
            .find(|o| o["name"] == c.name)
            .unwrap_or_else(|| panic!("pya2l: no object {}", c.name));
        let address = u64::from(FLASH_BASE) + c.offset() as u64;
        assert_eq!(o["address"].as_u64(), Some(address), "{}", c.name);
        let layout = &layouts[o["record_layout"].as_str().unwrap()];
        let datatype = if matches!(c.shape, Shape::Axis(_)) {
            &layout["axis_pts_x"]
        } else {
            assert_eq!(layout["fnc_index_mode"], "COLUMN_DIR", "{}", c.name);
            &layout["fnc_values"]
        };
        assert_eq!(datatype, "FLOAT32_IEEE", "{}", c.name);
        let conversion = o["conversion"].as_str().unwrap();
        assert_eq!(unit_of[conversion], c.unit, "{}: conversion {conversion}", c.name);
        assert_eq!(o["lower"].as_f64(), Some(f64::from(c.min)), "{}", c.name);
        assert_eq!(o["upper"].as_f64(), Some(f64::from(c.max)), "{}", c.name);
        let axes: Vec<(&str, u64)> = o["axes"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|x| {
                        (
                            x["axis_pts_ref"].as_str().unwrap(),
                            x["max_axis_points"].as_u64().unwrap(),
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        let axis_len = |name: &str| CHARACTERISTICS.iter().find(|a| a.name == name).unwrap().shape.len() as u64;
        match c.shape {
            Shape::Value => assert_eq!(o["type"], "VALUE", "{}", c.name),
            Shape::Axis(n) => assert_eq!(o["max_axis_points"].as_u64(), Some(n as u64), "{}", c.name),
            Shape::Array(n) => {
                assert_eq!(o["type"], "VAL_BLK", "{}", c.name);
                assert_eq!(o["matrix_dim"], serde_json::json!([n]), "{}", c.name);
            }
            Shape::Curve { x_axis, n } => {
                assert_eq!(o["type"], "CURVE", "{}", c.name);
                assert_eq!(axes, vec![(x_axis, n as u64)], "{}", c.name);
                assert_eq!(axis_len(x_axis), n as u64);
            }
            Shape::Map { x_axis, nx, y_axis, ny } => {
                assert_eq!(o["type"], "MAP", "{}", c.name);
                assert_eq!(axes, vec![(x_axis, nx as u64), (y_axis, ny as u64)], "{}", c.name);
            }
        }
        // The values at the address, in the A2L's order (COLUMN_DIR: the second index fastest,
        // as the JSON nests them), are the JSON's and inside the limits.
        let mut expect = Vec::new();
        let mut flatten = vec![&values[c.name]["value"]];
        while let Some(v) = flatten.pop() {
            match v {
                Value::Array(a) => flatten.extend(a.iter().rev()),
                v => expect.push(v.as_f64().unwrap()),
            }
        }
        assert_eq!(expect.len(), c.shape.len(), "{}", c.name);
        for (k, e) in expect.iter().enumerate() {
            let v = f32_at(image, address + 4 * k as u64);
            assert_eq!(v, *e as f32, "{}[{k}]", c.name);
            assert!(v >= c.min && v <= c.max, "{}[{k}] = {v}", c.name);
        }
    }
}

fn runs(truth: &Path, image: &Path) -> (Summary, Summary) {
    let unit = calibrate::unit_from_truth(truth).unwrap();
    let before = run_unit(&sweep(), None, EcuCoreConfig::default(), unit).unwrap();
    let cfg = calibrate::ecu_config_from_image(image).unwrap();
    let after = run_unit(&sweep(), None, cfg, unit).unwrap();
    assert!(!before.calibration_fault && !after.calibration_fault);
    (before, after)
}

/// A valve that is the paper's but for its td, Cd, tau_p, mass and a supply-pressure-dependent
/// delay (gain drawn 0.6-1.5): its bench matrix log and truth.json, as `generate` writes them.
fn pressure_delay_unit(seed: u64, dir: &Path) -> (PathBuf, PathBuf) {
    use hil_host::diagnose::ehvva::{apply_knobs, effect_knob, reference_values, BASELINE_KNOBS};
    use hil_host::generate::ehvva::{estimation_tests, log_text, run_bench, Sensors, DT_MS};
    use hil_host::generate::Rng;
    use model_core::ehvva::{EhvvaParams, EhvvaReduced};
    let mut rng = Rng::new(seed);
    let (td0, cd0, tau0) = reference_values();
    let x = [
        td0 * rng.uniform(0.85, 1.15),
        cd0 * rng.uniform(0.85, 1.15),
        tau0 * rng.uniform(0.8, 1.25),
        rng.uniform(0.165, 0.2),
    ];
    let mut p = apply_knobs(&EhvvaParams::baseline(), &BASELINE_KNOBS, &x);
    let knob = effect_knob("pressure-delay").unwrap();
    let gain = rng.uniform(0.6, 1.5);
    (knob.apply)(&mut p, gain);
    let mut params = serde_json::Map::new();
    for (k, v) in BASELINE_KNOBS.iter().zip(x) {
        params.insert(k.name.into(), serde_json::json!(v));
    }
    params.insert(knob.name.into(), serde_json::json!(gain));
    let sensors = Sensors {
        lift_sigma_mm: 0.004,
        lift_lsb_mm: 0.002,
        p_sigma_mpa: 0.01,
        p_lsb_mpa: 0.005,
        temp_sigma_c: 0.3,
        temp_lsb_c: 0.1,
    };
    let tests = estimation_tests(&mut rng);
    let make = |i: &model_core::ehvva::EhvvaInputs<f64>| {
        EhvvaReduced::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    };
    let cols = run_bench(&tests, DT_MS, &sensors, &mut rng, make).unwrap();
    std::fs::create_dir_all(dir).unwrap();
    let est = dir.join("estimation.csv");
    std::fs::write(&est, log_text("calibrate test bench", DT_MS, &cols)).unwrap();
    let truth = dir.join("truth.json");
    let t = serde_json::json!({"plant": "ehvva", "effect": "pressure-delay", "seed": seed, "params": params});
    std::fs::write(&truth, serde_json::to_string_pretty(&t).unwrap()).unwrap();
    (est, truth)
}

/// Calibrates `est`, runs the sweep on the unit before and after, asserts the 30 % and returns
/// (before, after) and the image's JSON.
fn ehvva_gain(label: &str, est: PathBuf, truth: &Path, out: &Path) -> (f64, f64, serde_json::Value) {
    let outcome = calibrate::calibrate(&[est], &mut |_| {}).unwrap();
    calibrate::write_outputs(&outcome, out, FLASH_BASE).unwrap();
    let (before, after) = runs(truth, &out.join("calibration.bin"));
    let (b, a) = (before.ehvva_timing_error_deg_rms, after.ehvva_timing_error_deg_rms);
    eprintln!(
        "{label}: EHVVA timing error RMS {b:.2} -> {a:.2} crank deg ({} / {} events, {} / {} without a held stop)",
        before.ehvva_events, after.ehvva_events, before.ehvva_stop_not_held_events, after.ehvva_stop_not_held_events
    );
    // A smaller advance may move the run's last opening past its end: one event either way.
    assert!(before.ehvva_events > 30 && after.ehvva_events.abs_diff(before.ehvva_events) <= 1);
    assert!(a <= 0.7 * b, "{label}: {a:.2} deg is not 30 % below {b:.2} deg");
    // Each closing is timed against its own pilot cycle's closing edge: a cycle whose valve
    // did not reach or hold its stop (a unit near force balance at 5 MPa) is counted apart,
    // not scored against the next cycle's fall from the stop (that read -104 crank degrees).
    for s in [&before, &after] {
        assert!(
            s.ehvva_close_error_deg.1 < 30.0,
            "{label}: closing error {:?}",
            s.ehvva_close_error_deg
        );
    }
    // The JSON the `run --json` option writes carries the figure by name.
    let j = after.json("calibration-sweep");
    assert_eq!(j["ehvva"]["timing_error_deg_rms"].as_f64(), Some(a));
    assert!(j["evvt"]["phase_error_deg_rms"].as_f64().is_some());
    assert!(j["vacuum"]["position_error_pct_rms"].as_f64().is_some());
    let json = serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    (b, a, json)
}

#[test]
fn the_units_own_calibration_beats_the_paper_defaults_on_supply_pressure_dependent_delay() {
    let dir = workdir("ehvva-gain");
    // The paper's valve but for td, Cd, tau_p, mass and the delay's pressure gain.
    let (est, truth) = pressure_delay_unit(7, &dir.join("paper-valve"));
    ehvva_gain("paper valve, seed 7", est, &truth, &dir.join("cal-paper-valve"));
    // Units as `generate` draws them: spring, preload, friction, areas and orifices differ
    // from the paper's too. Identified on the paper's valve, their other spring and areas
    // went into td, and the image put the valve events ~10 crank degrees late (seed 7: 3.2 ->
    // 10.0 deg RMS); identified on the unit's valve as diagnosed, td is the unit's.
    for seed in [7, 21] {
        let case = generate::generate(Plant::Ehvva, "pressure-delay", seed).unwrap();
        let (est, truth) = write_case(&case, &dir.join(format!("unit{seed}")));
        let (_, _, json) = ehvva_gain(
            &format!("generated unit, seed {seed}"),
            est,
            &truth,
            &dir.join(format!("cal{seed}")),
        );
        // td at 7 MPa, 22 °C (the ECU's grid point [2][2]; the pressure-dependent delay is read
        // at its nominal 7 MPa there), VO and VC alike, is the unit's within 10 %.
        let td_true = case.truth.iter().find(|(k, _)| k == "td_ms_at_7MPa_22C").unwrap().1;
        for table in ["ehvva.td_open_ms", "ehvva.td_close_ms"] {
            let td = json["characteristics"][table]["value"][2][2].as_f64().unwrap();
            assert!(
                (td / td_true - 1.0).abs() < 0.1,
                "seed {seed}: {table} {td:.3} ms at 7 MPa / 22 °C, truth {td_true:.3} ms"
            );
        }
        let motion = &json["characteristics"]["ehvva.motion_open_low_ms"]["source"];
        assert_eq!(motion["from"], "log", "{motion}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn vacuum_unit_calibrated_through_diagnose_and_its_named_extension() {
    let dir = workdir("vacuum");
    let case = generate::generate(Plant::Vacuum, "coulomb-friction", 11).unwrap();
    let (est, truth) = write_case(&case, &dir.join("unit"));
    let outcome = calibrate::calibrate(&[est], &mut |_| {}).unwrap();
    let out = dir.join("cal");
    calibrate::write_outputs(&outcome, &out, FLASH_BASE).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    let preset = case
        .truth
        .iter()
        .find(|(k, _)| k.starts_with("preset_"))
        .unwrap()
        .0
        .clone();
    let name = preset.trim_start_matches("preset_").to_lowercase();
    let fc = &json["characteristics"][format!("vacuum.{name}.fc_kpa")];
    assert_eq!(fc["source"]["from"], "log");
    assert!(fc["source"]["method"].as_str().unwrap().contains("coulomb-friction"));
    let fc_true = case.truth.iter().find(|(k, _)| k == "fc_kPa").unwrap().1;
    let fc_got = fc["value"].as_f64().unwrap();
    assert!(
        (fc_got / fc_true - 1.0).abs() < 0.2,
        "fc {fc_got} kPa, truth {fc_true} kPa"
    );
    let (before, after) = runs(&truth, &out.join("calibration.bin"));
    eprintln!(
        "vacuum {name}: position error RMS {:.2} -> {:.2} % (all three), {:?} -> {:?}",
        before.vacuum_position_error_pct_rms,
        after.vacuum_position_error_pct_rms,
        before.vacuum_rms_error_pct_each,
        after.vacuum_rms_error_pct_each
    );
    assert!(after.vacuum_position_error_pct_rms < before.vacuum_position_error_pct_rms);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_images_logs_and_units_are_refused_by_name() {
    let dir = workdir("refused");
    let good = dir.join("good.bin");
    let mut image = vec![0u8; IMAGE_BYTES];
    let cal = model_core::ecu::calibration::EcuCalibration::paper_defaults();
    CalibrationImage::serialize(&cal, &mut image).unwrap();
    std::fs::write(&good, &image).unwrap();
    assert!(calibrate::ecu_config_from_image(&good).is_ok());
    // One flipped bit: the CRC refuses it, and the error says calibration.
    let mut bad = image.clone();
    bad[200] ^= 0x04;
    let p = dir.join("corrupt.bin");
    std::fs::write(&p, &bad).unwrap();
    let e = calibrate::ecu_config_from_image(&p).unwrap_err();
    assert!(
        e.contains("calibration") && e.contains("corrupted") && e.contains("corrupt.bin"),
        "{e}"
    );
    // Cut short: incomplete.
    let p = dir.join("short.bin");
    std::fs::write(&p, &image[..IMAGE_BYTES / 2]).unwrap();
    let e = calibrate::ecu_config_from_image(&p).unwrap_err();
    assert!(e.contains("calibration image incomplete"), "{e}");
    // EVVT logs that do not cover the 3x3 grid (one operating point): refused with the reason.
    let (name, text) = generate::evvt::identification_grid(5).unwrap().remove(0);
    let one_point = dir.join(name);
    std::fs::write(&one_point, text).unwrap();
    let e = calibrate::calibrate(&[one_point], &mut |_| {}).unwrap_err();
    assert!(e.contains("EVVT logs") && e.contains("3×3 grid"), "{e}");
    // A unit run does not simulate (the positioner is no ECU actuator): named.
    let case = generate::generate(Plant::Positioner, "none", 3).unwrap();
    let (_, truth) = write_case(&case, &dir.join("positioner"));
    let e = calibrate::unit_from_truth(&truth).unwrap_err();
    assert!(e.contains("positioner") && e.contains("truth.json"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_command_line_calibrates_and_runs_the_unit_with_its_image() {
    let dir = workdir("cli");
    let bin = env!("CARGO_BIN_EXE_hil-host");
    let case = generate::generate(Plant::Ehvva, "pressure-delay", 21).unwrap();
    let (est, truth) = write_case(&case, &dir.join("unit"));
    let help = std::process::Command::new(bin)
        .args(["calibrate", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout).to_string();
    assert!(
        help.contains("Usage: hil-host calibrate") && help.contains("Examples:\n  hil-host "),
        "{help}"
    );
    let cal = dir.join("cal");
    let o = std::process::Command::new(bin)
        .arg("calibrate")
        .arg(&est)
        .arg("--out")
        .arg(&cal)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["calibration.bin", "calibration.a2l", "calibration.json"] {
        assert!(cal.join(f).is_file(), "{f}");
    }
    // Another unit's log into the same directory: refused (exit status 1), the image kept.
    let other = dir.join("other-unit.csv");
    std::fs::copy(&est, &other).unwrap();
    let image = std::fs::read(cal.join("calibration.bin")).unwrap();
    let o = std::process::Command::new(bin)
        .arg("calibrate")
        .arg(&other)
        .arg("--out")
        .arg(&cal)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("holds the outputs of `hil-host calibrate`")
            && err.contains("other-unit.csv")
            && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(cal.join("calibration.bin")).unwrap(), image);
    let sweep = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/calibration-sweep.toml");
    let run = |extra: &[&Path], json: &Path| {
        let mut c = std::process::Command::new(bin);
        c.arg("run")
            .arg(&sweep)
            .arg("--out")
            .arg(dir.join("out"))
            .arg("--force");
        c.arg("--unit").arg(&truth).arg("--json").arg(json);
        if let Some(image) = extra.first() {
            c.arg("--calibration").arg(image);
        }
        c.output().unwrap()
    };
    let figure = |p: &Path| -> f64 {
        let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
        j["ehvva"]["timing_error_deg_rms"].as_f64().unwrap()
    };
    let o = run(&[], &dir.join("before.json"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(&[&cal.join("calibration.bin")], &dir.join("after.json"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (b, a) = (figure(&dir.join("before.json")), figure(&dir.join("after.json")));
    assert!(a <= 0.7 * b, "{a} deg vs {b} deg");
    // A corrupted image: refused, exit status 1, the error says calibration.
    let mut bytes = std::fs::read(cal.join("calibration.bin")).unwrap();
    bytes[64] ^= 0xFF;
    let bad = dir.join("bad.bin");
    std::fs::write(&bad, &bytes).unwrap();
    let o = run(&[&bad], &dir.join("bad.json"));
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("calibration image corrupted"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A bench recording whose tool names the columns its own way is calibrated through the
/// channel map (`calibrate --channel-map`): the same image as from the DATA-FORMAT log.
#[test]
fn a_bench_recording_with_its_own_column_names_calibrates_through_a_channel_map() {
    let dir = workdir("mapped");
    let case = generate::generate(Plant::Evvt, "none", 3).unwrap();
    let (est, _) = write_case(&case, &dir.join("unit"));
    let text = std::fs::read_to_string(&est).unwrap();
    let ours = "t_s,motor_cmd_rpm,engine_rpm,u_batt_V,phase_ref_deg,phase_deg";
    assert!(text.contains(ours), "the EVVT header changed");
    let bench = dir.join("unit/bench.csv");
    std::fs::write(
        &bench,
        text.replacen(ours, "Time,CamMot_rpm,nEng,UBatt,PhiSoll,PhiIst", 1),
    )
    .unwrap();
    let map_path = dir.join("bench.toml");
    std::fs::write(
        &map_path,
        "[channels]\n\"Time\" = \"t_s\"\n\"CamMot_rpm\" = \"motor_cmd_rpm\"\n\"nEng\" = \"engine_rpm\"\n\"UBatt\" = \"u_batt_V\"\n\"PhiSoll\" = \"phase_ref_deg\"\n\"PhiIst\" = \"phase_deg\"\n",
    )
    .unwrap();
    let map = hil_host::mf4::ChannelMap::read(&map_path).unwrap();
    // Without the map the bench's names are refused by name.
    let e = calibrate::calibrate(std::slice::from_ref(&bench), &mut |_| {}).unwrap_err();
    assert!(e.contains("t_s"), "{e}");
    let mapped = calibrate::calibrate_mapped(std::slice::from_ref(&bench), Some(&map), &mut |_| {}).unwrap();
    let plain = calibrate::calibrate(std::slice::from_ref(&est), &mut |_| {}).unwrap();
    calibrate::write_outputs(&mapped, &dir.join("mapped"), FLASH_BASE).unwrap();
    calibrate::write_outputs(&plain, &dir.join("plain"), FLASH_BASE).unwrap();
    let image = |d: &str| std::fs::read(dir.join(d).join("calibration.bin")).unwrap();
    assert_eq!(image("mapped"), image("plain"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("mapped/calibration.json")).unwrap()).unwrap();
    assert_eq!(
        json["characteristics"]["evvt.alpha_deg_per_s2_rpm"]["source"]["from"],
        "log"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
