//! Tests of the calibration image: layout, checks, round trips (`calibration.rs`).

use super::*;

fn image(cal: &EcuCalibration) -> [u8; IMAGE_BYTES] {
    let mut buf = [0u8; IMAGE_BYTES];
    assert_eq!(CalibrationImage::serialize(cal, &mut buf), Ok(IMAGE_BYTES));
    buf
}

/// Re-seals a modified image with a good CRC (a tool that wrote a bad value properly).
fn reseal(buf: &mut [u8; IMAGE_BYTES]) {
    let crc = CRC32.checksum(&buf[..IMAGE_BYTES - 4]);
    buf[IMAGE_BYTES - 4..].copy_from_slice(&crc.to_le_bytes());
}

fn find(name: &str) -> &'static Characteristic {
    CHARACTERISTICS.iter().find(|c| c.name == name).unwrap()
}

#[test]
fn slots_match_the_characteristics_and_names_are_unique() {
    let mut cal = EcuCalibration::paper_defaults();
    for (c, s) in CHARACTERISTICS.iter().zip(cal.slots()) {
        assert_eq!(s.len(), c.shape.len(), "{}", c.name);
    }
    for (i, a) in CHARACTERISTICS.iter().enumerate() {
        assert!(CHARACTERISTICS[i + 1..].iter().all(|b| b.name != a.name), "{}", a.name);
        if let Shape::Map { x_axis, nx, y_axis, ny } = a.shape {
            assert_eq!(find(x_axis).shape, Shape::Axis(nx), "{}", a.name);
            assert_eq!(find(y_axis).shape, Shape::Axis(ny), "{}", a.name);
        }
        if let Shape::Curve { x_axis, n } = a.shape {
            assert_eq!(find(x_axis).shape, Shape::Axis(n), "{}", a.name);
        }
    }
    assert_eq!(IMAGE_BYTES, HEADER_BYTES + 4 * N_VALUES + 4);
    assert_eq!(find("ehvva.td_p_supply_mpa").offset(), HEADER_BYTES);
    assert_eq!(find("ehvva.td_temp_c").offset(), HEADER_BYTES + 16);
}

#[test]
fn paper_defaults_round_trip_and_build_the_default_ecu() {
    let cal = EcuCalibration::paper_defaults();
    let buf = image(&cal);
    assert_eq!(&buf[..4], b"ECAL");
    let back = CalibrationImage::parse(&buf).unwrap();
    // f32 precision: every value within its f32 rounding.
    let mut a = [0.0; N_VALUES];
    let mut b = [0.0; N_VALUES];
    let mut k = 0;
    cal.for_each(|_, v| {
        for x in v {
            a[k] = *x;
            k += 1;
        }
    });
    k = 0;
    back.for_each(|_, v| {
        for x in v {
            b[k] = *x;
            k += 1;
        }
    });
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(*x as f32, *y as f32);
    }
    // Bit-identical through a second round trip.
    assert_eq!(image(&back), buf);
    // The ECU built from it runs.
    assert!(crate::ecu::lockstep::EcuCore::new(back.config()).is_ok());
    // The paper's kp at 800 rpm, 14 V is about 25 rpm/deg (evvt_phase's doc).
    assert!(cal.evvt_kp_rpm_per_deg.iter().flatten().all(|k| *k > 2.0 && *k < 200.0));
}

#[test]
fn a_changed_table_reaches_the_config() {
    let mut cal = EcuCalibration::paper_defaults();
    cal.ehvva_tables.td_open_ms[2][3] = 2.5;
    cal.vacuum[1].static_map[1] = 101.0;
    cal.evvt_lpv.alpha_deg_per_s2_rpm[1][1] *= 1.5;
    cal.evvt_kp_rpm_per_deg = cal.implied_kp().unwrap();
    let back = CalibrationImage::parse(&image(&cal)).unwrap();
    let cfg = back.config();
    assert_eq!(cfg.ehvva_model.tables.td_open_ms[2][3], 2.5);
    assert!(matches!(
        cfg.vacuum.actuators[1].static_map,
        StaticPressureMap::PiecewiseLinear { p01_kpa, .. } if p01_kpa == 101.0
    ));
    let t = EhvvaTables::<f32>::with_valve_motion(&cfg.ehvva_model, &cfg.ehvva_motion).unwrap();
    let (vo, _) = t.t_delay_pair_ms(7.0, 60.0);
    assert!((vo - 2.5).abs() < 1e-6, "td VO at 7 MPa, 60 °C: {vo}");
}

#[test]
fn corrupted_truncated_or_other_version_images_are_refused() {
    let good = image(&EcuCalibration::paper_defaults());
    let mut bad = good;
    bad[100] ^= 0x01;
    assert!(matches!(
        CalibrationImage::parse(&bad),
        Err(CalibrationError::Crc { .. })
    ));
    assert!(matches!(
        CalibrationImage::parse(&good[..IMAGE_BYTES - 1]),
        Err(CalibrationError::TooShort { .. })
    ));
    let mut v2 = good;
    v2[4] = 2;
    reseal(&mut v2);
    assert_eq!(
        CalibrationImage::parse(&v2),
        Err(CalibrationError::Version { found: 2, supported: 1 })
    );
    assert_eq!(CalibrationImage::parse(&[0xFF; 64]), Err(CalibrationError::NoImage));
    let mut small = [0u8; 10];
    assert!(matches!(
        CalibrationImage::serialize(&EcuCalibration::paper_defaults(), &mut small),
        Err(CalibrationError::BufferTooSmall { .. })
    ));
    // A flash sector holds more than the image: trailing bytes are ignored.
    let mut sector = [0xFFu8; IMAGE_BYTES + 64];
    sector[..IMAGE_BYTES].copy_from_slice(&good);
    assert!(CalibrationImage::parse(&sector).is_ok());
    let e = CalibrationImage::parse(&bad).unwrap_err();
    let mut s = heapless::String::<160>::new();
    core::fmt::write(&mut s, format_args!("{e}")).unwrap();
    assert!(s.starts_with("calibration image corrupted"), "{s}");
}

#[test]
fn values_outside_limits_or_inconsistent_are_refused_by_name() {
    let cal = EcuCalibration::paper_defaults();
    let set_f32 = |buf: &mut [u8; IMAGE_BYTES], name: &str, index: usize, v: f32| {
        let off = find(name).offset() + 4 * index;
        buf[off..off + 4].copy_from_slice(&v.to_le_bytes());
        reseal(buf);
    };
    let mut b = image(&cal);
    set_f32(&mut b, "ehvva.td_open_ms", 7, 25.0);
    assert!(matches!(
        CalibrationImage::parse(&b),
        Err(CalibrationError::OutOfLimits {
            name: "ehvva.td_open_ms",
            index: 7,
            ..
        })
    ));
    let mut b = image(&cal);
    set_f32(&mut b, "ehvva.cd", 2, f32::NAN);
    assert_eq!(
        CalibrationImage::parse(&b),
        Err(CalibrationError::NotFinite {
            name: "ehvva.cd",
            index: 2
        })
    );
    let mut b = image(&cal);
    set_f32(&mut b, "ehvva.td_temp_c", 3, 10.0);
    assert_eq!(
        CalibrationImage::parse(&b),
        Err(CalibrationError::AxisNotIncreasing {
            name: "ehvva.td_temp_c",
            index: 3
        })
    );
    // α changed without the kp it implies: refused.
    let mut b = image(&cal);
    set_f32(
        &mut b,
        "evvt.alpha_deg_per_s2_rpm",
        4,
        2.0 * cal.evvt_lpv.alpha_deg_per_s2_rpm[1][1] as f32,
    );
    assert!(matches!(
        CalibrationImage::parse(&b),
        Err(CalibrationError::Inconsistent {
            name: "evvt.kp_rpm_per_deg",
            ..
        })
    ));
    // check() refuses what parse would.
    let mut c = cal;
    c.vacuum[2].fc_kpa = -1.0;
    assert!(matches!(
        c.check(),
        Err(CalibrationError::OutOfLimits {
            name: "vacuum.hpc.fc_kpa",
            ..
        })
    ));
    assert!(cal.check().is_ok());
}

#[test]
fn boot_falls_back_to_the_paper_defaults_with_the_fault_flag() {
    let mut cal = EcuCalibration::paper_defaults();
    cal.ehvva_tables.td_open_ms[1][1] = 3.0;
    let good = image(&cal);
    let (cfg, status) = boot_config(&good);
    assert_eq!(status, BootCalibration::Image);
    assert_eq!(cfg.ehvva_model.tables.td_open_ms[1][1], 3.0);
    assert!(!cfg.calibration_fault);
    let (cfg, status) = boot_config(&[0xFF; IMAGE_BYTES]);
    assert_eq!(status, BootCalibration::Absent);
    assert!(!cfg.calibration_fault);
    let mut bad = good;
    bad[IMAGE_BYTES - 1] ^= 0x80;
    let (cfg, status) = boot_config(&bad);
    assert!(matches!(status, BootCalibration::Refused(CalibrationError::Crc { .. })));
    assert!(cfg.calibration_fault);
    // Nothing of the refused image: the paper's td.
    assert_eq!(cfg.ehvva_model.tables, EhvvaTableData::paper_default());
    // The flag reaches every actuator frame.
    let mut core = crate::ecu::lockstep::EcuCore::new(cfg).unwrap();
    let frame = crate::ecu::frame::SensorFrame {
        seq: 1,
        t_us: 50,
        n_edges: 0,
        edges: [crate::ecu::frame::SensorFrame::NO_EDGE; crate::ecu::frame::MAX_EDGES],
        adc_counts: [2000; crate::ecu::supervisor::N_CHANNELS],
        valve: crate::ecu::ehvva_task::ValveRequest {
            open_deg: 100.0,
            close_deg: 400.0,
            high_lift: true,
            soft_seat: true,
            enabled: false,
        },
        cam_phase_set_deg: 10.0,
        vacuum_x_set_pct: [0.0; 3],
        motor_driver_fault: false,
    };
    assert_ne!(core.step(&frame).faults & CALIBRATION_FAULT_BIT, 0);
}

#[test]
fn set_by_name() {
    let mut cal = EcuCalibration::paper_defaults();
    assert!(cal.set("vacuum.hpc.backlash_pct", &[2.0]));
    assert_eq!(cal.vacuum[2].backlash_pct, 2.0);
    assert!(!cal.set("vacuum.hpc.backlash_pct", &[1.0, 2.0]));
    assert!(!cal.set("nope", &[1.0]));
}
