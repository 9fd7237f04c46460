//! PLY point clouds: `x y z` as float plus named scalar fields (CloudCompare reads
//! `intensity` and any `scalar_*` property as scalar fields; MeshLab and Open3D read x y z).
//!
//! Writing is done here directly (a fixed vertex layout, binary little-endian or ASCII, fast);
//! reading goes through `ply-rs-bw`, so files from other programs load whatever their property
//! order, scalar types (float/double/int…) or extra properties and elements.

use crate::{Error, Result};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Property, PropertyAccess};
use std::io::{Read, Write};
use std::path::Path;

/// A point cloud in memory: positions (mm) and per-point scalar fields.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    pub positions: Vec<[f64; 3]>,
    pub scalars: Vec<ScalarField>,
}

/// One per-point scalar (stored as float in PLY).
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarField {
    pub name: String,
    pub values: Vec<f32>,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The scalar field with this name.
    pub fn scalar(&self, name: &str) -> Option<&[f32]> {
        self.scalars.iter().find(|s| s.name == name).map(|s| s.values.as_slice())
    }

    /// Checks that every coordinate is a finite float (what the reader accepts back), every
    /// scalar field has one value per point and names are PLY-safe.
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (i, p) in self.positions.iter().enumerate() {
            if let Some(k) = p.iter().position(|c| !(*c as f32).is_finite()) {
                return Err(format!(
                    "point {i}: {} = {} is not a finite number within float range",
                    ["x", "y", "z"][k],
                    p[k]
                ));
            }
        }
        for s in &self.scalars {
            if s.values.len() != self.positions.len() {
                return Err(format!(
                    "scalar field {} has {} values for {} points",
                    s.name,
                    s.values.len(),
                    self.positions.len()
                ));
            }
            if s.name.is_empty() || s.name.contains(char::is_whitespace) {
                return Err(format!("invalid scalar field name {:?}", s.name));
            }
        }
        Ok(())
    }
}

/// PLY payload encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    BinaryLittleEndian,
    Ascii,
}

/// Writes the cloud as PLY to any writer.
pub fn write_ply_to(w: &mut dyn Write, cloud: &PointCloud, encoding: Encoding) -> std::io::Result<()> {
    cloud.validate().map_err(std::io::Error::other)?;
    let enc = match encoding {
        Encoding::BinaryLittleEndian => "binary_little_endian",
        Encoding::Ascii => "ascii",
    };
    let mut header = format!("ply\nformat {enc} 1.0\ncomment written by omniscan {}\n", env!("CARGO_PKG_VERSION"));
    header += &format!("element vertex {}\nproperty float x\nproperty float y\nproperty float z\n", cloud.len());
    for s in &cloud.scalars {
        header += &format!("property float {}\n", s.name);
    }
    header += "end_header\n";
    w.write_all(header.as_bytes())?;
    let stride = 4 * (3 + cloud.scalars.len());
    let mut buf = Vec::with_capacity(stride * 4096);
    for (chunk_start, chunk) in cloud.positions.chunks(4096).enumerate().map(|(i, c)| (i * 4096, c)) {
        buf.clear();
        for (i, p) in chunk.iter().enumerate() {
            let idx = chunk_start + i;
            match encoding {
                Encoding::BinaryLittleEndian => {
                    for c in p {
                        buf.extend_from_slice(&(*c as f32).to_le_bytes());
                    }
                    for s in &cloud.scalars {
                        buf.extend_from_slice(&s.values[idx].to_le_bytes());
                    }
                }
                Encoding::Ascii => {
                    use std::io::Write as _;
                    write!(buf, "{} {} {}", p[0] as f32, p[1] as f32, p[2] as f32)?;
                    for s in &cloud.scalars {
                        write!(buf, " {}", s.values[idx])?;
                    }
                    buf.push(b'\n');
                }
            }
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

/// Writes the cloud to a file atomically (`-` = stdout).
pub fn write_ply(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    crate::io::write_atomic(path, |w| write_ply_to(w, cloud, encoding))
}

/// One vertex as parsed: x y z plus the other scalar properties in header order.
struct Vertex {
    xyz: [f64; 3],
    seen: u8,
    extra: Vec<f64>,
}

fn as_f64(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex { xyz: [0.0; 3], seen: 0, extra: Vec::new() }
    }
    fn set_property(&mut self, name: &str, p: Property) -> ply_rs_bw::ply::PropertyAccessResult {
        let Some(v) = as_f64(&p) else { return ply_rs_bw::ply::PropertyAccessResult::Ignored };
        match name {
            "x" => (self.xyz[0], self.seen) = (v, self.seen | 1),
            "y" => (self.xyz[1], self.seen) = (v, self.seen | 2),
            "z" => (self.xyz[2], self.seen) = (v, self.seen | 4),
            _ => self.extra.push(v),
        }
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

/// Reads a PLY point cloud (any encoding; extra elements such as faces are ignored).
pub fn read_ply_from(r: &mut dyn Read, name: &str) -> Result<PointCloud> {
    let mut reader = std::io::BufReader::with_capacity(1 << 16, r);
    let parser = Parser::<Vertex>::new();
    let mut raw = ply_rs_bw::parser::Reader::new(&mut reader);
    let header = parser.read_header(&mut raw).map_err(|e| Error::new(name, "header", e.to_string()))?;
    let vertex_def =
        header.elements.get("vertex").ok_or_else(|| Error::new(name, "header", "no `vertex` element"))?.clone();
    for axis in ["x", "y", "z"] {
        if !vertex_def.properties.contains_key(axis) {
            return Err(Error::new(name, "header", format!("vertex element has no `{axis}` property")));
        }
    }
    let scalar_names: Vec<String> = vertex_def
        .properties
        .iter()
        .filter(|(k, p)| {
            !["x", "y", "z"].contains(&k.as_str()) && matches!(p.data_type, ply_rs_bw::ply::PropertyType::Scalar(_))
        })
        .map(|(k, _)| k.clone())
        .collect();
    let mut payload = parser.read_payload(&mut raw, &header).map_err(|e| Error::new(name, "data", e.to_string()))?;
    let vertices = payload.shift_remove("vertex").unwrap_or_default();
    if vertices.len() != vertex_def.count {
        return Err(Error::new(
            name,
            "data",
            format!("truncated: {} of {} vertices", vertices.len(), vertex_def.count),
        ));
    }
    let mut cloud = PointCloud {
        positions: Vec::with_capacity(vertices.len()),
        scalars: scalar_names
            .iter()
            .map(|n| ScalarField { name: n.clone(), values: Vec::with_capacity(vertices.len()) })
            .collect(),
    };
    for (i, v) in vertices.into_iter().enumerate() {
        if v.seen != 7 || v.extra.len() != scalar_names.len() {
            return Err(Error::new(name, format!("vertex {i}"), "missing properties"));
        }
        if !v.xyz.iter().all(|c| c.is_finite()) {
            return Err(Error::new(name, format!("vertex {i}"), "coordinate is not a finite number"));
        }
        cloud.positions.push(v.xyz);
        for (s, x) in cloud.scalars.iter_mut().zip(v.extra) {
            s.values.push(x as f32);
        }
    }
    Ok(cloud)
}

/// Reads a PLY file (`-` = stdin).
pub fn read_ply(path: &Path) -> Result<PointCloud> {
    let name = crate::io::display_name(path, "stdin");
    let mut input = crate::io::open_input(path)?;
    read_ply_from(&mut input, &name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> PointCloud {
        PointCloud {
            positions: (0..100).map(|i| [i as f64 * 0.5, -(i as f64), 1000.0 + i as f64 * 0.25]).collect(),
            scalars: vec![
                ScalarField { name: "intensity".into(), values: (0..100).map(|i| i as f32).collect() },
                ScalarField { name: "scalar_frame".into(), values: (0..100).map(|i| (i / 10) as f32).collect() },
            ],
        }
    }

    #[test]
    fn round_trips_binary_and_ascii() {
        for enc in [Encoding::BinaryLittleEndian, Encoding::Ascii] {
            let mut buf = Vec::new();
            write_ply_to(&mut buf, &sample(), enc).unwrap();
            let back = read_ply_from(&mut buf.as_slice(), "mem").unwrap();
            assert_eq!(back, sample(), "{enc:?}");
        }
    }

    #[test]
    fn reads_foreign_property_order_and_types() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty uchar red\nproperty double z\nproperty float x\nproperty int y\nproperty list uchar int idx\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n10 3.5 1.25 -2 2 0 1\n20 4.5 2.25 7 0\n3 0 1 1\n";
        let c = read_ply_from(&mut text.as_bytes(), "foreign.ply").unwrap();
        assert_eq!(c.positions, vec![[1.25, -2.0, 3.5], [2.25, 7.0, 4.5]]);
        assert_eq!(c.scalar("red").unwrap(), &[10.0, 20.0]);
    }

    #[test]
    fn truncated_and_garbage_are_errors() {
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &sample(), Encoding::BinaryLittleEndian).unwrap();
        buf.truncate(buf.len() - 7);
        let e = read_ply_from(&mut buf.as_slice(), "cut.ply").unwrap_err().to_string();
        assert!(e.starts_with("cut.ply: "), "{e}");
        let e = read_ply_from(&mut &b"\x00\x01garbage"[..], "junk.ply").unwrap_err().to_string();
        assert!(e.starts_with("junk.ply: header"), "{e}");
        let e = read_ply_from(
            &mut &b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n"[..],
            "nox.ply",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`y`"), "{e}");
    }

    #[test]
    fn non_finite_points_are_refused_naming_the_point() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ply");
        for bad in [f64::INFINITY, f64::NAN, 1e40] {
            let mut cloud = sample();
            cloud.positions[1][2] = bad;
            let e = write_ply(&path, &cloud, Encoding::Ascii).unwrap_err().to_string();
            assert!(e.contains("c.ply") && e.contains("point 1: z"), "{e}");
            assert!(!path.exists());
        }
    }
}
