//! Streaming PLY vertex reader: visits points one by one without holding the file in memory
//! (the merge of a 50-million-point cloud must not need it twice).
//!
//! Handles the common layout directly: `vertex` as the first element, scalar properties only
//! (any PLY scalar type, any order, `x y z` among them), ASCII or binary of either byte order.
//! Anything else (lists in the vertex element, vertex not first) falls back to the full reader
//! `omni_formats::ply::read_ply`, which loads the file.

use omni_formats::ply::read_ply;
use std::io::{BufRead, Read};
use std::path::Path;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Kind {
    fn parse(s: &str) -> Option<Kind> {
        Some(match s {
            "char" | "int8" => Kind::I8,
            "uchar" | "uint8" => Kind::U8,
            "short" | "int16" => Kind::I16,
            "ushort" | "uint16" => Kind::U16,
            "int" | "int32" => Kind::I32,
            "uint" | "uint32" => Kind::U32,
            "float" | "float32" => Kind::F32,
            "double" | "float64" => Kind::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Kind::I8 | Kind::U8 => 1,
            Kind::I16 | Kind::U16 => 2,
            Kind::I32 | Kind::U32 | Kind::F32 => 4,
            Kind::F64 => 8,
        }
    }

    #[inline]
    fn decode(self, b: &[u8], little: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap_or([0; $n]);
                (if little { <$t>::from_le_bytes(a) } else { <$t>::from_be_bytes(a) }) as f64
            }};
        }
        match self {
            Kind::I8 => b[0] as i8 as f64,
            Kind::U8 => b[0] as f64,
            Kind::I16 => num!(i16, 2),
            Kind::U16 => num!(u16, 2),
            Kind::I32 => num!(i32, 4),
            Kind::U32 => num!(u32, 4),
            Kind::F32 => num!(f32, 4),
            Kind::F64 => num!(f64, 8),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

/// Called once per file with the scalar names (header order, without x y z) and vertex count.
pub type HeaderFn<'a> = dyn FnMut(&[String], usize) -> Result<(), String> + 'a;
/// Called per vertex with its position and scalars.
pub type PointFn<'a> = dyn FnMut(&[f64; 3], &[f32]) -> Result<(), String> + 'a;
/// An element as declared: name, count, properties (`None` for list properties).
type Element = (String, usize, Vec<Option<(String, Kind)>>);

/// The vertex layout of a PLY header when the streaming path applies.
struct Layout {
    format: Format,
    count: usize,
    props: Vec<(String, Kind)>,
}

/// Parses the header; `Ok(None)` if the file needs the general reader.
fn read_header(r: &mut dyn BufRead, name: &str) -> Result<Option<Layout>, String> {
    let mut line = String::new();
    let mut next = |line: &mut String| -> Result<String, String> {
        line.clear();
        let n = r.read_line(line).map_err(|e| format!("{name}: header: {e}"))?;
        if n == 0 {
            return Err(format!("{name}: header: unexpected end of file"));
        }
        Ok(line.trim_end().to_string())
    };
    if next(&mut line)? != "ply" {
        return Err(format!("{name}: header: not a PLY file"));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let l = next(&mut line)?;
        let t: Vec<&str> = l.split_whitespace().collect();
        match t.as_slice() {
            ["end_header"] => break,
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => Format::BinaryBe,
                    other => return Err(format!("{name}: header: unknown format {other}")),
                })
            }
            ["element", e, n] => {
                let n = n.parse().map_err(|_| format!("{name}: header: bad element count {n:?}"))?;
                elements.push((e.to_string(), n, Vec::new()));
            }
            ["property", "list", ..] => {
                elements.last_mut().ok_or(format!("{name}: header: property before element"))?.2.push(None)
            }
            ["property", ty, p] => {
                let kind = Kind::parse(ty).ok_or(format!("{name}: header: unknown property type {ty}"))?;
                elements
                    .last_mut()
                    .ok_or(format!("{name}: header: property before element"))?
                    .2
                    .push(Some((p.to_string(), kind)));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(format!("{name}: header: cannot parse {l:?}")),
        }
    }
    let format = format.ok_or(format!("{name}: header: no format line"))?;
    let Some((first, count, props)) = elements.first() else {
        return Err(format!("{name}: header: no `vertex` element"));
    };
    if first != "vertex" || props.iter().any(|p| p.is_none()) {
        return Ok(None);
    }
    let props: Vec<(String, Kind)> = props.iter().flatten().cloned().collect();
    for axis in ["x", "y", "z"] {
        if !props.iter().any(|(n, _)| n == axis) {
            return Err(format!("{name}: header: vertex element has no `{axis}` property"));
        }
    }
    Ok(Some(Layout { format, count: *count, props }))
}

/// Visits every vertex of a PLY file: first `on_header(scalar names, vertex count)`, then
/// `on_point(xyz, scalars)` per vertex, scalars in header order without x y z. Non-finite
/// coordinates and truncation are errors naming the file and vertex.
pub fn for_each_vertex(path: &Path, on_header: &mut HeaderFn, on_point: &mut PointFn) -> Result<(), String> {
    let name = omni_formats::io::display_name(path, "stdin");
    let mut input = omni_formats::io::open_input(path).map_err(|e| e.to_string())?;
    let Some(layout) = read_header(&mut input, &name)? else {
        drop(input);
        return for_each_vertex_loaded(path, on_header, on_point);
    };
    let pos: Vec<usize> =
        ["x", "y", "z"].iter().map(|a| layout.props.iter().position(|(n, _)| n == a).unwrap_or(0)).collect();
    let scalar_idx: Vec<usize> = (0..layout.props.len()).filter(|i| !pos.contains(i)).collect();
    let names: Vec<String> = scalar_idx.iter().map(|&i| layout.props[i].0.clone()).collect();
    on_header(&names, layout.count)?;
    let mut values = vec![0f64; layout.props.len()];
    let mut scalars = vec![0f32; scalar_idx.len()];
    let mut emit = |i: usize, values: &[f64]| -> Result<(), String> {
        let xyz = [values[pos[0]], values[pos[1]], values[pos[2]]];
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(format!("{name}: vertex {i}: coordinate is not a finite number"));
        }
        for (s, &k) in scalars.iter_mut().zip(&scalar_idx) {
            *s = values[k] as f32;
        }
        on_point(&xyz, &scalars)
    };
    let truncated = |i: usize| format!("{name}: data: truncated: {i} of {} vertices", layout.count);
    match layout.format {
        Format::Ascii => {
            let mut line = String::new();
            for i in 0..layout.count {
                line.clear();
                if input.read_line(&mut line).map_err(|e| format!("{name}: {e}"))? == 0 {
                    return Err(truncated(i));
                }
                let mut tokens = line.split_whitespace();
                for v in values.iter_mut() {
                    let tok = tokens.next().ok_or_else(|| format!("{name}: vertex {i}: missing properties"))?;
                    *v = tok.parse().map_err(|_| format!("{name}: vertex {i}: bad number {tok:?}"))?;
                }
                emit(i, &values)?;
            }
        }
        Format::BinaryLe | Format::BinaryBe => {
            let little = layout.format == Format::BinaryLe;
            let stride: usize = layout.props.iter().map(|(_, k)| k.size()).sum();
            let per_chunk = (1 << 16) / stride.max(1) + 1;
            let mut buf = vec![0u8; per_chunk * stride];
            let mut i = 0;
            while i < layout.count {
                let n = per_chunk.min(layout.count - i);
                let bytes = &mut buf[..n * stride];
                read_full(&mut input, bytes).map_err(|got| truncated(i + got / stride))?;
                for rec in bytes.chunks_exact(stride) {
                    let mut off = 0;
                    for (v, (_, k)) in values.iter_mut().zip(&layout.props) {
                        *v = k.decode(&rec[off..], little);
                        off += k.size();
                    }
                    emit(i, &values)?;
                    i += 1;
                }
            }
        }
    }
    Ok(())
}

/// Fills `buf` completely or returns how many bytes were read.
fn read_full(r: &mut dyn Read, buf: &mut [u8]) -> Result<(), usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => return Err(got),
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return Err(got),
        }
    }
    Ok(())
}

/// General layouts: load with the full reader, then visit.
fn for_each_vertex_loaded(path: &Path, on_header: &mut HeaderFn, on_point: &mut PointFn) -> Result<(), String> {
    let cloud = read_ply(path).map_err(|e| e.to_string())?;
    let names: Vec<String> = cloud.scalars.iter().map(|s| s.name.clone()).collect();
    on_header(&names, cloud.len())?;
    let mut scalars = vec![0f32; names.len()];
    for (i, p) in cloud.positions.iter().enumerate() {
        for (s, f) in scalars.iter_mut().zip(&cloud.scalars) {
            *s = f.values[i];
        }
        on_point(p, &scalars)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_formats::ply::{Encoding, PointCloud, ScalarField, write_ply};

    fn collect(path: &Path) -> Result<PointCloud, String> {
        let cloud = std::cell::RefCell::new(PointCloud::default());
        for_each_vertex(
            path,
            &mut |n, _| {
                cloud.borrow_mut().scalars =
                    n.iter().map(|n| ScalarField { name: n.clone(), values: vec![] }).collect();
                Ok(())
            },
            &mut |p, s| {
                let mut c = cloud.borrow_mut();
                c.positions.push(*p);
                for (f, v) in c.scalars.iter_mut().zip(s) {
                    f.values.push(*v);
                }
                Ok(())
            },
        )?;
        Ok(cloud.into_inner())
    }

    #[test]
    fn streams_what_the_writer_writes_and_foreign_layouts() {
        let dir = tempfile::tempdir().unwrap();
        let cloud = PointCloud {
            positions: (0..5000).map(|i| [i as f64 * 0.5, -(i as f64), 7.25]).collect(),
            scalars: vec![ScalarField { name: "intensity".into(), values: (0..5000).map(|i| i as f32).collect() }],
        };
        for enc in [Encoding::BinaryLittleEndian, Encoding::Ascii] {
            let path = dir.path().join("c.ply");
            write_ply(&path, &cloud, enc).unwrap();
            assert_eq!(collect(&path).unwrap(), cloud);
        }
        // Big-endian doubles with a uchar first, then a face element with a list.
        let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty uchar red\nproperty double x\nproperty double y\nproperty double z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        for (r, p) in [(7u8, [1.5f64, 2.5, 3.5]), (9, [-1.0, 0.0, 1e3])] {
            bytes.push(r);
            for c in p {
                bytes.extend_from_slice(&c.to_be_bytes());
            }
        }
        let path = dir.path().join("be.ply");
        std::fs::write(&path, &bytes).unwrap();
        let c = collect(&path).unwrap();
        assert_eq!(c.positions, vec![[1.5, 2.5, 3.5], [-1.0, 0.0, 1e3]]);
        assert_eq!(c.scalar("red").unwrap(), &[7.0, 9.0]);
        // Truncated binary.
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        assert!(collect(&path).unwrap_err().contains("truncated: 1 of 2"));
    }
}
