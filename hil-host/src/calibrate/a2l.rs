//! The A2L (ASAM MCD-2 MC) description of the calibration image, written with the `a2lfile`
//! crate from model-core's characteristic table: one `CHARACTERISTIC` per value, curve and map
//! (address in the ECU's flash, record layout, conversion, limits, `COM_AXIS` axes), one
//! `AXIS_PTS` per shared axis, a `MEMORY_SEGMENT` for the calibration sector.

use a2lfile::{
    A2lFile, A2lObject, AddrEpk, AddrType, AlignmentByte, AlignmentFloat32Ieee, AlignmentFloat64Ieee, AlignmentInt64,
    AlignmentLong, AlignmentWord, AxisDescr, AxisDescrAttribute, AxisPts, AxisPtsDim, AxisPtsRef, ByteOrder,
    ByteOrderEnum, Characteristic, CharacteristicType, CompuMethod, ConversionType, DataType, Epk, FncValues,
    IndexMode, IndexOrder, ItemList, MatrixDim, MemoryAttribute, MemorySegment, MemoryType, ModCommon, ModPar, Module,
    PhysUnit, PrgType, ReadOnly, RecordLayout,
};
use model_core::ecu::calibration::{Characteristic as Cal, Shape, CHARACTERISTICS, FORMAT_VERSION, IMAGE_BYTES, MAGIC};

/// Record layout of a value, curve, map or value block: f32 values, second index fastest.
pub const RL_VALUES: &str = "RL_F32_COLUMN_DIR";
/// Record layout of an axis: f32 breakpoints, increasing.
pub const RL_AXIS: &str = "RL_AXIS_F32";

/// The conversion (identity with the unit) of a unit: `CM_` and the unit spelled as an A2L
/// identifier, `%` as `pct`, `/` as `_per_`, a product's `*` as `_`, brackets and powers'
/// `^` dropped, the dimensionless `-` as `none` (`deg/(s^2*rpm)` → `CM_deg_per_s2_rpm`).
/// Symbols are spelled out rather than replaced by one filler, so distinct units keep
/// distinct names (`%` and `-` had both become `CM__`, two COMPU_METHODs of one name).
pub fn compu_method_name(unit: &str) -> String {
    let mut clean = String::new();
    for c in unit.trim().chars() {
        match c {
            c if c.is_ascii_alphanumeric() => clean.push(c),
            '%' => clean.push_str("pct"),
            '/' => clean.push_str("_per_"),
            '*' | '.' | ' ' | '-' => clean.push('_'),
            _ => {}
        }
    }
    let words: Vec<&str> = clean.split('_').filter(|w| !w.is_empty()).collect();
    if words.is_empty() {
        "CM_none".into()
    } else {
        format!("CM_{}", words.join("_"))
    }
}

/// The A2L text of the image at `flash_base`.
pub fn a2l_text(flash_base: u32) -> String {
    build(flash_base).write_to_string()
}

/// The A2L file object of the image at `flash_base`.
pub fn build(flash_base: u32) -> A2lFile {
    let mut file = a2lfile::new();
    file.project.name = "ecu_actuators".into();
    file.project.long_identifier = "Engine actuator ECU (EHVVA, EVVT, vacuum actuators)".into();
    file.project.module = ItemList::default();
    file.project.module.push(Module::new(
        "ecu_calibration".into(),
        format!("calibration image format v{FORMAT_VERSION}, written by hil-host calibrate"),
    ));
    let module = &mut file.project.module[0];

    let mut common = ModCommon::new("little-endian f32 values".into());
    common.byte_order = Some(ByteOrder::new(ByteOrderEnum::MsbLast));
    // The Cortex-M4's natural alignments (AAPCS): every value of the image is an f32 at a
    // multiple of 4 (model-core's layout), which a tool checks against these.
    common.alignment_byte = Some(AlignmentByte::new(1));
    common.alignment_word = Some(AlignmentWord::new(2));
    common.alignment_long = Some(AlignmentLong::new(4));
    common.alignment_int64 = Some(AlignmentInt64::new(8));
    common.alignment_float32_ieee = Some(AlignmentFloat32Ieee::new(4));
    common.alignment_float64_ieee = Some(AlignmentFloat64Ieee::new(8));
    module.mod_common = Some(common);
    let mut par = ModPar::new("STM32F405RG, calibration sector".into());
    // The image's identification: a tool reads the magic at the image's first byte and
    // compares it with EPK before it trusts the addresses (an erased sector reads 0xFF).
    par.epk = Some(Epk::new(String::from_utf8_lossy(&MAGIC).into_owned()));
    par.addr_epk.push(AddrEpk::new(flash_base));
    let mut segment = MemorySegment::new(
        "calibration".into(),
        "flash sector of the calibration image (header, values, CRC-32)".into(),
        PrgType::Data,
        MemoryType::Flash,
        MemoryAttribute::Intern,
        flash_base,
        IMAGE_BYTES as u32,
        [-1; 5],
    );
    // Addresses in hex, as calibration tools show them.
    segment.get_layout_mut().item_location.5 .1 = true;
    segment.get_layout_mut().item_location.6 .1 = true;
    par.memory_segment.push(segment);
    module.mod_par = Some(par);

    let mut rl = RecordLayout::new(RL_VALUES.into());
    rl.fnc_values = Some(FncValues::new(
        1,
        DataType::Float32Ieee,
        IndexMode::ColumnDir,
        AddrType::Direct,
    ));
    module.record_layout.push(rl);
    let mut rl = RecordLayout::new(RL_AXIS.into());
    rl.axis_pts_x = Some(AxisPtsDim::new(
        1,
        DataType::Float32Ieee,
        IndexOrder::IndexIncr,
        AddrType::Direct,
    ));
    module.record_layout.push(rl);

    let mut units: Vec<&str> = CHARACTERISTICS.iter().map(|c| c.unit).collect();
    units.sort_unstable();
    units.dedup();
    for u in units {
        module.compu_method.push(CompuMethod::new(
            compu_method_name(u),
            format!("identity, {u}"),
            ConversionType::Identical,
            "%.6".into(),
            u.into(),
        ));
    }

    let address = |c: &Cal| flash_base + c.offset() as u32;
    for c in CHARACTERISTICS.iter() {
        let conv = compu_method_name(c.unit);
        let (min, max) = (f64::from(c.min), f64::from(c.max));
        if let Shape::Axis(n) = c.shape {
            let mut a = AxisPts::new(
                c.name.into(),
                c.description.into(),
                address(c),
                "NO_INPUT_QUANTITY".into(),
                RL_AXIS.into(),
                0.0,
                conv,
                n as u16,
                min,
                max,
            );
            a.phys_unit = Some(PhysUnit::new(c.unit.into()));
            a.get_layout_mut().item_location.2 .1 = true;
            module.axis_pts.push(a);
            continue;
        }
        let kind = match c.shape {
            Shape::Value => CharacteristicType::Value,
            Shape::Array(_) => CharacteristicType::ValBlk,
            Shape::Curve { .. } => CharacteristicType::Curve,
            Shape::Map { .. } | Shape::Axis(_) => CharacteristicType::Map,
        };
        let mut ch = Characteristic::new(
            c.name.into(),
            c.description.into(),
            kind,
            address(c),
            RL_VALUES.into(),
            0.0,
            conv,
            min,
            max,
        );
        ch.phys_unit = Some(PhysUnit::new(c.unit.into()));
        ch.get_layout_mut().item_location.3 .1 = true;
        if c.read_only {
            ch.read_only = Some(ReadOnly::new());
        }
        let com_axis = |axis: &str| {
            let a = CHARACTERISTICS.iter().find(|x| x.name == axis);
            let (n, lo, hi, unit) = a.map_or((0, 0.0, 0.0, "-"), |a| {
                (a.shape.len(), f64::from(a.min), f64::from(a.max), a.unit)
            });
            let mut d = AxisDescr::new(
                AxisDescrAttribute::ComAxis,
                "NO_INPUT_QUANTITY".into(),
                compu_method_name(unit),
                n as u16,
                lo,
                hi,
            );
            d.axis_pts_ref = Some(AxisPtsRef::new(axis.into()));
            d
        };
        match c.shape {
            Shape::Array(n) => {
                let mut m = MatrixDim::new();
                m.dim_list = vec![n as u16];
                ch.matrix_dim = Some(m);
            }
            Shape::Curve { x_axis, .. } => ch.axis_descr.push(com_axis(x_axis)),
            Shape::Map { x_axis, y_axis, .. } => {
                ch.axis_descr.push(com_axis(x_axis));
                ch.axis_descr.push(com_axis(y_axis));
            }
            Shape::Value | Shape::Axis(_) => {}
        }
        module.characteristic.push(ch);
    }
    file
}

#[cfg(test)]
mod tests {
    use super::*;
    use a2lfile::A2lObjectName;
    use std::collections::BTreeSet;

    fn is_c_identifier(s: &str) -> bool {
        let mut chars = s.chars();
        chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
    }

    #[test]
    fn every_unit_has_a_conversion_of_its_own() {
        let units: BTreeSet<&str> = CHARACTERISTICS.iter().map(|c| c.unit).collect();
        let names: BTreeSet<String> = units.iter().map(|u| compu_method_name(u)).collect();
        assert_eq!(
            names.len(),
            units.len(),
            "two units share a COMPU_METHOD name: {names:?}"
        );
        for n in &names {
            assert!(is_c_identifier(n), "{n} is not an A2L identifier");
        }
        assert_eq!(compu_method_name("%"), "CM_pct");
        assert_eq!(compu_method_name("-"), "CM_none");
        assert_eq!(compu_method_name("deg/(s^2*rpm)"), "CM_deg_per_s2_rpm");
    }

    #[test]
    fn names_are_unique_in_each_namespace() {
        let file = build(0x080E_0000);
        let m = &file.project.module[0];
        let mut seen = BTreeSet::new();
        // CHARACTERISTIC and AXIS_PTS share one namespace (both are calibration objects).
        for n in m
            .characteristic
            .iter()
            .map(|c| c.get_name())
            .chain(m.axis_pts.iter().map(|a| a.get_name()))
        {
            assert!(seen.insert(n.to_string()), "object {n} defined twice");
        }
        let mut seen = BTreeSet::new();
        for n in m.compu_method.iter().map(|c| c.get_name()) {
            assert!(seen.insert(n.to_string()), "COMPU_METHOD {n} defined twice");
        }
        let mut seen = BTreeSet::new();
        for n in m.record_layout.iter().map(|r| r.get_name()) {
            assert!(seen.insert(n.to_string()), "RECORD_LAYOUT {n} defined twice");
        }
    }
}
