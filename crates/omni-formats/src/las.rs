//! LAS 1.4 (ASPRS), through the `las` crate: point format 6, coordinates as 32-bit integers with
//! a scale of 0.01 mm (in the output unit) and an offset at the cloud's centre, so millimetres
//! survive. `intensity` goes into LAS's intensity (16-bit, rounded); every other scalar field is
//! an "extra bytes" dimension in its own type, described in the Extra Bytes VLR (LAS 1.4 §2.5.2,
//! record 4 of `LASF_Spec`), which laspy, PDAL and CloudCompare read by name.

use crate::export::CloudOptions;
use crate::ply::{PointCloud, ScalarType};
use std::io::Cursor;

/// Coordinate resolution (mm): the scale, converted to the output unit.
const RESOLUTION_MM: f64 = 0.01;

/// The Extra Bytes data type code (LAS 1.4 table 25) of a scalar type.
fn extra_bytes_type(ty: ScalarType) -> u8 {
    match ty {
        ScalarType::U8 => 1,
        ScalarType::I8 => 2,
        ScalarType::U16 => 3,
        ScalarType::I16 => 4,
        ScalarType::U32 => 5,
        ScalarType::I32 => 6,
        ScalarType::F32 => 9,
        ScalarType::F64 => 10,
    }
}

/// One 192-byte Extra Bytes descriptor: type and name, no optional statistics.
fn extra_bytes_descriptor(name: &str, ty: ScalarType) -> Result<Vec<u8>, String> {
    if name.len() > 32 {
        return Err(format!("scalar field name {name:?} is longer than LAS's 32 bytes"));
    }
    let mut d = vec![0u8; 192];
    d[2] = extra_bytes_type(ty);
    d[4..4 + name.len()].copy_from_slice(name.as_bytes());
    let description = b"omniscan scalar field";
    d[160..160 + description.len()].copy_from_slice(description);
    Ok(d)
}

/// The scale and offset of one axis: 0.01 mm resolution, offset at the centre rounded to 10 mm,
/// checked so that every value fits the 32-bit integers.
fn axis_transform(values: impl Iterator<Item = f64>, per_mm: f64, axis: &str) -> Result<las::Transform, String> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let scale = RESOLUTION_MM * per_mm;
    let step = 1000.0 * scale;
    let offset = if lo.is_finite() { ((lo + hi) / 2.0 / step).round() * step } else { 0.0 };
    if lo.is_finite() && ((hi - offset).max(offset - lo) / scale) >= i32::MAX as f64 {
        return Err(format!(
            "{axis} spans {:.0} mm, more than LAS's 32-bit coordinates hold at {RESOLUTION_MM} mm",
            (hi - lo) / per_mm
        ));
    }
    Ok(las::Transform { scale, offset })
}

/// The cloud as a LAS 1.4 file in memory (the header needs the counts and bounds first).
pub fn las_bytes(cloud: &PointCloud, opts: &CloudOptions) -> Result<Vec<u8>, String> {
    cloud.validate().map_err(|m| m.to_string())?;
    let per_mm = opts.units.per_mm();
    let intensity = cloud.scalars.iter().position(|s| s.name == "intensity");
    let extras: Vec<usize> = (0..cloud.scalars.len()).filter(|&i| Some(i) != intensity).collect();
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(6).map_err(|e| e.to_string())?;
    builder.point_format.extra_bytes = extras.iter().map(|&i| cloud.scalars[i].ty.size() as u16).sum();
    builder.generating_software = format!("omniscan {}", env!("CARGO_PKG_VERSION"));
    let axis = |k: usize, name| axis_transform(cloud.positions.iter().map(|p| p[k] * per_mm), per_mm, name);
    builder.transforms = las::Vector { x: axis(0, "x")?, y: axis(1, "y")?, z: axis(2, "z")? };
    if !extras.is_empty() {
        let mut data = Vec::new();
        for &i in &extras {
            data.extend(extra_bytes_descriptor(&cloud.scalars[i].name, cloud.scalars[i].ty)?);
        }
        builder.vlrs.push(las::Vlr {
            user_id: "LASF_Spec".into(),
            record_id: 4,
            description: "Extra Bytes Record".into(),
            data,
        });
    }
    let header = builder.into_header().map_err(|e| e.to_string())?;
    let mut writer = las::Writer::new(Cursor::new(Vec::new()), header).map_err(|e| e.to_string())?;
    for (i, p) in cloud.positions.iter().enumerate() {
        let mut extra_bytes = Vec::with_capacity(32);
        for &k in &extras {
            let s = &cloud.scalars[k];
            s.ty.encode_le(s.values[i] as f64, &mut extra_bytes);
        }
        let point = las::Point {
            x: p[0] * per_mm,
            y: p[1] * per_mm,
            z: p[2] * per_mm,
            intensity: intensity.map_or(0, |k| ScalarType::U16.quantise(cloud.scalars[k].values[i] as f64) as u16),
            return_number: 1,
            number_of_returns: 1,
            gps_time: Some(0.0),
            extra_bytes,
            ..Default::default()
        };
        writer.write_point(point).map_err(|e| format!("point {i}: {e}"))?;
    }
    let mut bytes = writer.into_inner().map_err(|e| e.to_string())?.into_inner();
    zero_legacy_point_counts(&mut bytes);
    Ok(bytes)
}

/// Offsets (bytes) of the LAS 1.4 header's legacy point count (u32) and legacy counts by return
/// (5 × u32), which follow it.
const LEGACY_COUNTS: std::ops::Range<usize> = 107..131;

/// LAS 1.4 (R15, §2.4) requires the legacy point counts to be 0 for point formats 6 and above,
/// which only the 64-bit counts describe; the `las` crate writes them as for format 0–5.
fn zero_legacy_point_counts(bytes: &mut [u8]) {
    if let Some(legacy) = bytes.get_mut(LEGACY_COUNTS) {
        legacy.fill(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::Units;
    use crate::ply::ScalarField;

    fn cloud() -> PointCloud {
        PointCloud {
            positions: vec![[1.234, -2000.005, 3000.25], [-15000.0, 4.0, -1.0], [7.77, 8.88, 9.99]],
            scalars: vec![
                ScalarField::new("intensity", vec![10.4, 20.0, 65535.0]),
                ScalarField { name: "red".into(), values: vec![255.0, 3.0, 0.0], ty: ScalarType::U8 },
                ScalarField::new("scalar_range", vec![1.5, 2.5, 3.5]),
            ],
        }
    }

    fn bytes_of(units: Units) -> Vec<u8> {
        las_bytes(&cloud(), &CloudOptions { units, ..Default::default() }).unwrap()
    }

    #[test]
    fn millimetres_survive_in_metres_and_millimetres() {
        for units in [Units::Millimetres, Units::Metres] {
            let bytes = las_bytes(&cloud(), &CloudOptions { units, ..Default::default() }).unwrap();
            let mut reader = las::Reader::new(Cursor::new(bytes)).unwrap();
            let header = reader.header().clone();
            assert_eq!((header.version().major, header.version().minor), (1, 4));
            assert_eq!(header.number_of_points(), 3);
            assert_eq!(header.number_of_points_by_return(1), Some(3));
            let (mut count, mut by_return) = ([0u8; 4], [0u8; 20]);
            count.copy_from_slice(&bytes_of(units)[107..111]);
            by_return.copy_from_slice(&bytes_of(units)[111..131]);
            assert_eq!((count, by_return), ([0; 4], [0; 20]), "LAS 1.4: legacy counts are 0 for format 6");
            let points: Vec<las::Point> = reader.read_all().unwrap().points().collect::<Result<_, _>>().unwrap();
            for (p, want) in points.iter().zip(&cloud().positions) {
                let got = [p.x, p.y, p.z].map(|c| c / units.per_mm());
                for k in 0..3 {
                    assert!((got[k] - want[k]).abs() <= 0.005 + 1e-9, "{units:?}: {got:?} vs {want:?}");
                }
            }
            assert_eq!(points.iter().map(|p| p.intensity).collect::<Vec<_>>(), [10, 20, 65535]);
            // red (u8) then scalar_range (f32), little-endian.
            assert_eq!(points[0].extra_bytes[0], 255);
            assert_eq!(f32::from_le_bytes(points[2].extra_bytes[1..5].try_into().unwrap()), 3.5);
        }
    }

    #[test]
    fn a_cloud_too_wide_for_the_integers_is_refused() {
        let mut c = cloud();
        c.positions[0][0] = 5e7;
        let e = las_bytes(&c, &CloudOptions::default()).unwrap_err();
        assert!(e.starts_with("x spans"), "{e}");
    }
}
