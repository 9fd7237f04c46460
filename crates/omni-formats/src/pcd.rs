//! PCD, the Point Cloud Library's format (v0.7): `x y z` float (or double) plus the scalar
//! fields in their types, ASCII or binary (packed little-endian records, PCL's `DATA binary`).
//! Normals `nx ny nz` are named `normal_x normal_y normal_z` as PCL and Open3D expect. The
//! coordinate unit is recorded in a `# units` comment line (PCL skips comments).

use crate::export::CloudOptions;
use crate::ply::{PointCloud, ScalarType, for_each_record};
use std::io::Write;

/// PCL's field name for one of ours.
fn pcd_name(name: &str) -> &str {
    match name {
        "nx" => "normal_x",
        "ny" => "normal_y",
        "nz" => "normal_z",
        other => other,
    }
}

/// PCD's `SIZE` and `TYPE` letters for a scalar type.
fn pcd_type(ty: ScalarType) -> (usize, char) {
    let letter = if ty.is_float() {
        'F'
    } else if ty.is_signed() {
        'I'
    } else {
        'U'
    };
    (ty.size(), letter)
}

/// Writes the cloud as PCD to any writer.
pub fn write_pcd_to(w: &mut dyn Write, cloud: &PointCloud, opts: &CloudOptions) -> std::io::Result<()> {
    cloud.validate_for(opts).map_err(std::io::Error::other)?;
    let coord = opts.coordinate_type();
    let fields: Vec<(&str, ScalarType)> = ["x", "y", "z"]
        .into_iter()
        .map(|a| (a, coord))
        .chain(cloud.scalars.iter().map(|s| (pcd_name(&s.name), s.ty)))
        .collect();
    let join = |f: &dyn Fn(&(&str, ScalarType)) -> String| fields.iter().map(f).collect::<Vec<_>>().join(" ");
    let n = cloud.len();
    let header = format!(
        "# .PCD v0.7 - Point Cloud Data file format\n# written by omniscan {}\n# units {}\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {}\n",
        env!("CARGO_PKG_VERSION"),
        opts.units.name(),
        join(&|(name, _)| name.to_string()),
        join(&|(_, ty)| pcd_type(*ty).0.to_string()),
        join(&|(_, ty)| pcd_type(*ty).1.to_string()),
        join(&|_| "1".to_string()),
        if opts.ascii { "ascii" } else { "binary" },
    );
    w.write_all(header.as_bytes())?;
    let mut buf = Vec::with_capacity(1 << 17);
    for_each_record(cloud, opts.units, coord, 4096, &mut buf, opts.ascii, &mut |buf| w.write_all(buf))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::Units;
    use crate::ply::ScalarField;

    fn cloud() -> PointCloud {
        PointCloud {
            positions: vec![[1.5, -2.0, 3000.25], [0.0, 4.0, -1.0]],
            scalars: vec![
                ScalarField::new("intensity", vec![10.5, 20.0]),
                ScalarField { name: "red".into(), values: vec![255.0, 3.0], ty: ScalarType::U8 },
                ScalarField::new("nx", vec![0.0, 1.0]),
            ],
        }
    }

    #[test]
    fn ascii_header_and_lines_name_fields_types_and_units() {
        let mut buf = Vec::new();
        write_pcd_to(&mut buf, &cloud(), &CloudOptions { ascii: true, double: false, units: Units::Metres }).unwrap();
        let text = String::from_utf8(buf).unwrap();
        let expected_tail = "VERSION 0.7\nFIELDS x y z intensity red normal_x\nSIZE 4 4 4 4 1 4\nTYPE F F F F U F\nCOUNT 1 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n0.0015 -0.002 3.00025 10.5 255 0\n0 0.004 -0.001 20 3 1\n";
        assert!(text.ends_with(expected_tail), "{text}");
        assert!(text.contains("# units m\n"), "{text}");
    }

    #[test]
    fn binary_records_are_packed_little_endian() {
        let mut buf = Vec::new();
        write_pcd_to(&mut buf, &cloud(), &CloudOptions { double: true, ..Default::default() }).unwrap();
        let start = buf.windows(12).position(|w| w == b"DATA binary\n").unwrap() + 12;
        let data = &buf[start..];
        assert_eq!(data.len(), 2 * (3 * 8 + 4 + 1 + 4));
        assert_eq!(f64::from_le_bytes(data[16..24].try_into().unwrap()), 3000.25);
        assert_eq!(f32::from_le_bytes(data[24..28].try_into().unwrap()), 10.5);
        assert_eq!(data[28], 255);
    }
}
