//! PLY point clouds: `x y z` plus named scalar fields (CloudCompare reads `intensity` and any
//! `scalar_*` property as scalar fields; MeshLab and Open3D read x y z, `nx ny nz` and colours).
//!
//! Writing is done here directly (binary little-endian or ASCII; coordinates float or double;
//! each scalar field in the PLY type it was read with, so uchar colours stay uchar). Reading
//! decodes the common layout directly (`vertex` the first element, scalar properties only, any
//! type and order, either byte order or ASCII); anything else (lists in the vertex element,
//! vertex not first) goes through `ply-rs-bw`. [`visit_vertices`] streams the vertices without
//! holding the file.

use crate::export::{CloudOptions, Units};
use crate::{Error, Result};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Property, PropertyAccess};
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// A point cloud in memory: positions (mm) and per-point scalar fields.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    pub positions: Vec<[f64; 3]>,
    pub scalars: Vec<ScalarField>,
}

/// One per-point scalar: values held as f32, written back as `ty` (rounded and clamped to an
/// integer type's range).
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarField {
    pub name: String,
    pub values: Vec<f32>,
    /// The PLY type the field was read as, and is written as (float for computed fields).
    pub ty: ScalarType,
}

impl ScalarField {
    /// A float field.
    pub fn new(name: impl Into<String>, values: Vec<f32>) -> Self {
        ScalarField { name: name.into(), values, ty: ScalarType::F32 }
    }
}

/// A PLY scalar property type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    #[default]
    F32,
    F64,
}

impl ScalarType {
    /// Parses a PLY type name (`uchar`, `uint8`, `float32`, …).
    pub fn parse(s: &str) -> Option<ScalarType> {
        Some(match s {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }

    /// The PLY 1.0 name.
    pub fn ply_name(self) -> &'static str {
        match self {
            ScalarType::I8 => "char",
            ScalarType::U8 => "uchar",
            ScalarType::I16 => "short",
            ScalarType::U16 => "ushort",
            ScalarType::I32 => "int",
            ScalarType::U32 => "uint",
            ScalarType::F32 => "float",
            ScalarType::F64 => "double",
        }
    }

    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, ScalarType::F32 | ScalarType::F64)
    }

    pub fn is_signed(self) -> bool {
        !matches!(self, ScalarType::U8 | ScalarType::U16 | ScalarType::U32)
    }

    /// Decodes one value from the front of `b` (at least [`ScalarType::size`] bytes).
    #[inline]
    pub fn decode(self, b: &[u8], little: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap_or([0; $n]);
                (if little { <$t>::from_le_bytes(a) } else { <$t>::from_be_bytes(a) }) as f64
            }};
        }
        match self {
            ScalarType::I8 => b[0] as i8 as f64,
            ScalarType::U8 => b[0] as f64,
            ScalarType::I16 => num!(i16, 2),
            ScalarType::U16 => num!(u16, 2),
            ScalarType::I32 => num!(i32, 4),
            ScalarType::U32 => num!(u32, 4),
            ScalarType::F32 => num!(f32, 4),
            ScalarType::F64 => num!(f64, 8),
        }
    }

    /// `v` as this type would hold it: integers rounded to nearest and clamped to the range
    /// (NaN becomes 0), floats as they are.
    pub fn quantise(self, v: f64) -> f64 {
        let (lo, hi) = match self {
            ScalarType::I8 => (i8::MIN as f64, i8::MAX as f64),
            ScalarType::U8 => (0.0, u8::MAX as f64),
            ScalarType::I16 => (i16::MIN as f64, i16::MAX as f64),
            ScalarType::U16 => (0.0, u16::MAX as f64),
            ScalarType::I32 => (i32::MIN as f64, i32::MAX as f64),
            ScalarType::U32 => (0.0, u32::MAX as f64),
            ScalarType::F32 | ScalarType::F64 => return v,
        };
        if v.is_nan() { 0.0 } else { v.round().clamp(lo, hi) }
    }

    /// Appends `v` little-endian in this type (quantised first, see [`ScalarType::quantise`]).
    #[inline]
    pub fn encode_le(self, v: f64, out: &mut Vec<u8>) {
        let q = self.quantise(v);
        match self {
            ScalarType::I8 => out.push(q as i8 as u8),
            ScalarType::U8 => out.push(q as u8),
            ScalarType::I16 => out.extend_from_slice(&(q as i16).to_le_bytes()),
            ScalarType::U16 => out.extend_from_slice(&(q as u16).to_le_bytes()),
            ScalarType::I32 => out.extend_from_slice(&(q as i32).to_le_bytes()),
            ScalarType::U32 => out.extend_from_slice(&(q as u32).to_le_bytes()),
            ScalarType::F32 => out.extend_from_slice(&(q as f32).to_le_bytes()),
            ScalarType::F64 => out.extend_from_slice(&q.to_le_bytes()),
        }
    }

    /// Appends `v` as ASCII text in this type (integers without a fraction; f32 values with the
    /// shortest text that reads back exactly).
    pub fn write_ascii(self, v: f64, out: &mut Vec<u8>) {
        let q = self.quantise(v);
        let _ = match self {
            ScalarType::F32 => write!(out, "{}", q as f32),
            ScalarType::F64 => write!(out, "{q}"),
            _ => write!(out, "{}", q as i64),
        };
    }
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
        self.validate_coordinates(ScalarType::F32)?;
        self.validate_fields()
    }

    /// Checks that every scalar field has one value per point and a PLY-safe name.
    fn validate_fields(&self) -> std::result::Result<(), String> {
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

    /// Checks that every coordinate is finite in the type it will be written as.
    fn validate_coordinates(&self, ty: ScalarType) -> std::result::Result<(), String> {
        let finite = |c: f64| if ty == ScalarType::F64 { c.is_finite() } else { (c as f32).is_finite() };
        for (i, p) in self.positions.iter().enumerate() {
            if let Some(k) = p.iter().position(|c| !finite(*c)) {
                let range = if ty == ScalarType::F64 { "" } else { " within float range" };
                let value = omni_model::limits::shown(p[k]);
                return Err(format!("point {i}: {} = {value} is not a finite number{range}", ["x", "y", "z"][k]));
            }
        }
        Ok(())
    }

    /// Checks the cloud for writing with `opts` (coordinates finite in their output type).
    pub fn validate_for(&self, opts: &CloudOptions) -> std::result::Result<(), String> {
        self.validate_coordinates(opts.coordinate_type())?;
        self.validate_fields()
    }
}

/// PLY payload encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    BinaryLittleEndian,
    Ascii,
}

/// The comment that records the coordinate unit (`comment units mm` or `comment units m`); the
/// reader scales coordinates in metres back to millimetres.
const UNITS_COMMENT: &str = "comment units ";

/// Writes the cloud as PLY to any writer (float millimetres).
pub fn write_ply_to(w: &mut dyn Write, cloud: &PointCloud, encoding: Encoding) -> std::io::Result<()> {
    write_ply_with(w, cloud, &CloudOptions { ascii: encoding == Encoding::Ascii, ..CloudOptions::default() })
}

/// Writes the cloud as PLY with the options' encoding, coordinate type and unit; scalar fields
/// keep their types.
pub fn write_ply_with(w: &mut dyn Write, cloud: &PointCloud, opts: &CloudOptions) -> std::io::Result<()> {
    cloud.validate_for(opts).map_err(std::io::Error::other)?;
    let enc = if opts.ascii { "ascii" } else { "binary_little_endian" };
    let coord = opts.coordinate_type();
    let mut header = format!("ply\nformat {enc} 1.0\ncomment written by omniscan {}\n", env!("CARGO_PKG_VERSION"));
    header += &format!("{UNITS_COMMENT}{}\n", opts.units.name());
    header += &format!("element vertex {}\n", cloud.len());
    for axis in ["x", "y", "z"] {
        header += &format!("property {} {axis}\n", coord.ply_name());
    }
    for s in &cloud.scalars {
        header += &format!("property {} {}\n", s.ty.ply_name(), s.name);
    }
    header += "end_header\n";
    w.write_all(header.as_bytes())?;
    let mut buf = Vec::with_capacity(1 << 17);
    for_each_record(cloud, opts.units, coord, 4096, &mut buf, opts.ascii, &mut |buf| w.write_all(buf))
}

/// Encodes the cloud's points `chunk` at a time into `buf` (binary little-endian records or
/// ASCII lines: x y z in `coord` scaled to `units`, then the scalars in their types) and hands
/// each chunk to `sink`. Shared by the PLY and PCD writers, whose payloads are the same.
pub(crate) fn for_each_record(
    cloud: &PointCloud,
    units: Units,
    coord: ScalarType,
    chunk: usize,
    buf: &mut Vec<u8>,
    ascii: bool,
    sink: &mut dyn FnMut(&[u8]) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let scale = units.per_mm();
    for (start, points) in cloud.positions.chunks(chunk).enumerate().map(|(i, c)| (i * chunk, c)) {
        buf.clear();
        for (i, p) in points.iter().enumerate() {
            let idx = start + i;
            if ascii {
                for (k, c) in p.iter().enumerate() {
                    if k > 0 {
                        buf.push(b' ');
                    }
                    coord.write_ascii(c * scale, buf);
                }
                for s in &cloud.scalars {
                    buf.push(b' ');
                    s.ty.write_ascii(s.values[idx] as f64, buf);
                }
                buf.push(b'\n');
            } else {
                for c in p {
                    coord.encode_le(c * scale, buf);
                }
                for s in &cloud.scalars {
                    s.ty.encode_le(s.values[idx] as f64, buf);
                }
            }
        }
        sink(buf)?;
    }
    Ok(())
}

/// Writes the cloud to a file atomically (`-` = stdout).
pub fn write_ply(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    crate::io::write_atomic(path, |w| write_ply_to(w, cloud, encoding))
}

/// PLY payload formats as read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyFormat {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// The vertex layout of a PLY file whose first element is `vertex` with scalar properties only
/// (the layout [`visit_vertices`] decodes directly).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexLayout {
    pub format: PlyFormat,
    pub count: usize,
    /// Every vertex property in file order, x y z among them.
    pub properties: Vec<(String, ScalarType)>,
    /// Millimetres per coordinate unit: 1000 when the file says `comment units m`, else 1.
    pub mm_per_unit: f64,
    /// The elements declared after the vertices (faces, edges): not read, but checked whole.
    pub after: Vec<ElementShape>,
}

/// A property as declared: a scalar, or a list (its count's type and its items').
#[derive(Debug, Clone, PartialEq)]
pub enum DeclaredProperty {
    Scalar(String, ScalarType),
    List(ScalarType, ScalarType),
}

/// An element as declared: name, count and properties.
#[derive(Debug, Clone, PartialEq)]
pub struct ElementShape {
    pub name: String,
    pub count: usize,
    pub properties: Vec<DeclaredProperty>,
}

impl ElementShape {
    /// The scalar properties with their types, in file order (lists left out).
    pub fn scalars(&self) -> Vec<(String, ScalarType)> {
        self.properties
            .iter()
            .filter_map(|p| match p {
                DeclaredProperty::Scalar(n, k) => Some((n.clone(), *k)),
                DeclaredProperty::List(..) => None,
            })
            .collect()
    }
}

impl VertexLayout {
    /// The scalar properties other than x y z, in file order.
    pub fn scalar_fields(&self) -> Vec<(String, ScalarType)> {
        self.properties.iter().filter(|(n, _)| !["x", "y", "z"].contains(&n.as_str())).cloned().collect()
    }
}

/// Reads a PLY header up to and including `end_header`. Returns the header's bytes (to hand on
/// to the general reader) and the vertex layout when the direct path applies (`None`: the file
/// needs the general reader). Errors name the file and `header`.
pub fn read_header(r: &mut dyn BufRead, name: &str) -> Result<(Vec<u8>, Option<VertexLayout>)> {
    let bad = |m: String| Error::new(name, "header", m);
    let mut raw = Vec::new();
    let mut next = |raw: &mut Vec<u8>| -> Result<String> {
        let start = raw.len();
        // A header line is short; a binary file without newlines must not be read whole.
        let n = (&mut *r).take(4096).read_until(b'\n', raw).map_err(|e| bad(e.to_string()))?;
        if n == 0 {
            return Err(bad("unexpected end of file".into()));
        }
        if raw[start..].last() != Some(&b'\n') && n == 4096 {
            return Err(bad("line longer than 4096 bytes".into()));
        }
        String::from_utf8(raw[start..].to_vec())
            .map(|l| l.trim_end().to_string())
            .map_err(|_| bad("not a PLY file".into()))
    };
    if next(&mut raw).ok().as_deref() != Some("ply") {
        return Err(bad("not a PLY file".into()));
    }
    let mut format = None;
    let mut mm_per_unit = 1.0;
    let mut elements: Vec<ElementShape> = Vec::new();
    loop {
        let l = next(&mut raw)?;
        let t: Vec<&str> = l.split_whitespace().collect();
        match t.as_slice() {
            ["end_header"] => break,
            ["format", f, version] => {
                if *version != "1.0" {
                    return Err(bad(format!("PLY version {version}: this build reads PLY 1.0")));
                }
                format = Some(match *f {
                    "ascii" => PlyFormat::Ascii,
                    "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                    "binary_big_endian" => PlyFormat::BinaryBigEndian,
                    other => return Err(bad(format!("unknown format {other}"))),
                })
            }
            ["element", e, n] => {
                let n = n.parse().map_err(|_| bad(format!("bad element count {n:?}")))?;
                elements.push(ElementShape { name: e.to_string(), count: n, properties: Vec::new() });
            }
            ["property", "list", count, item, _] => {
                let kind = |ty: &str| ScalarType::parse(ty).ok_or(bad(format!("unknown property type {ty}")));
                let list = DeclaredProperty::List(kind(count)?, kind(item)?);
                elements.last_mut().ok_or(bad("property before element".into()))?.properties.push(list);
            }
            ["property", ty, p] => {
                let kind = ScalarType::parse(ty).ok_or(bad(format!("unknown property type {ty}")))?;
                let scalar = DeclaredProperty::Scalar(p.to_string(), kind);
                elements.last_mut().ok_or(bad("property before element".into()))?.properties.push(scalar);
            }
            ["comment", "units", "m"] => mm_per_unit = 1000.0,
            ["comment", "units", "mm"] => mm_per_unit = 1.0,
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(bad(format!("cannot parse {l:?}"))),
        }
    }
    let format = format.ok_or(bad("no format line".into()))?;
    let Some(vertex) = elements.iter().find(|e| e.name == "vertex") else {
        return Err(bad("no `vertex` element".into()));
    };
    let vertex_scalars = vertex.scalars();
    for axis in ["x", "y", "z"] {
        if !vertex_scalars.iter().any(|(n, _)| n == axis) {
            return Err(bad(format!("vertex element has no `{axis}` property")));
        }
    }
    let first = &elements[0];
    if first.name != "vertex" || first.properties.iter().any(|p| matches!(p, DeclaredProperty::List(..))) {
        return Ok((raw, None));
    }
    let (properties, count) = (first.scalars(), first.count);
    let after = elements.split_off(1);
    Ok((raw, Some(VertexLayout { format, count, properties, mm_per_unit, after })))
}

/// The per-vertex visitor of [`visit_vertices`]: xyz (mm) and the scalars.
pub type VertexFn<'a, E> = dyn FnMut(&[f64; 3], &[f32]) -> std::result::Result<(), E> + 'a;

/// Why [`visit_vertices`] stopped: the file was bad, or the visitor returned an error.
#[derive(Debug)]
pub enum VisitError<E> {
    Read(Error),
    Stopped(E),
}

/// Visits the vertices of `layout` (from [`read_header`] on the same reader) one by one:
/// `on_point(xyz in mm, scalars in layout order without x y z)`. Non-finite coordinates and
/// truncation are errors naming the file and vertex.
pub fn visit_vertices<E>(
    r: &mut dyn BufRead,
    name: &str,
    layout: &VertexLayout,
    on_point: &mut VertexFn<E>,
) -> std::result::Result<(), VisitError<E>> {
    let props = &layout.properties;
    let axis = |a: &str| props.iter().position(|(n, _)| n == a).unwrap_or(0);
    let pos = [axis("x"), axis("y"), axis("z")];
    let scalar_idx: Vec<usize> = (0..props.len()).filter(|i| !pos.contains(i)).collect();
    let mut scalars = vec![0f32; scalar_idx.len()];
    let scale = layout.mm_per_unit;
    let fail = |loc: String, m: String| VisitError::Read(Error::new(name, loc, m));
    let truncated = |i: usize| fail("data".into(), format!("truncated: {i} of {} vertices", layout.count));
    let mut emit = |i: usize, values: &[f64]| {
        let xyz = [values[pos[0]] * scale, values[pos[1]] * scale, values[pos[2]] * scale];
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(fail(format!("vertex {i}"), "coordinate is not a finite number".into()));
        }
        for (s, &k) in scalars.iter_mut().zip(&scalar_idx) {
            *s = values[k] as f32;
        }
        on_point(&xyz, &scalars).map_err(VisitError::Stopped)
    };
    let mut values = vec![0f64; props.len()];
    match layout.format {
        PlyFormat::Ascii => {
            let mut line = String::new();
            for i in 0..layout.count {
                line.clear();
                if r.read_line(&mut line).map_err(|e| fail(String::new(), e.to_string()))? == 0 {
                    return Err(truncated(i));
                }
                let mut tokens = line.split_whitespace();
                for v in values.iter_mut() {
                    let tok = tokens.next().ok_or_else(|| fail(format!("vertex {i}"), "missing properties".into()))?;
                    *v = tok.parse().map_err(|_| fail(format!("vertex {i}"), format!("bad number {tok:?}")))?;
                }
                emit(i, &values)?;
            }
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            let little = layout.format == PlyFormat::BinaryLittleEndian;
            let offsets: Vec<(usize, ScalarType)> = props
                .iter()
                .scan(0, |off, (_, k)| {
                    let o = *off;
                    *off += k.size();
                    Some((o, *k))
                })
                .collect();
            let stride: usize = props.iter().map(|(_, k)| k.size()).sum();
            let per_chunk = (1 << 20) / stride.max(1) + 1;
            let mut buf = vec![0u8; per_chunk.min(layout.count.max(1)) * stride];
            let mut i = 0;
            while i < layout.count {
                let n = (buf.len() / stride).min(layout.count - i);
                let bytes = &mut buf[..n * stride];
                read_full(r, bytes).map_err(|got| truncated(i + got / stride))?;
                for rec in bytes.chunks_exact(stride) {
                    for (v, &(off, k)) in values.iter_mut().zip(&offsets) {
                        *v = k.decode(&rec[off..], little);
                    }
                    emit(i, &values)?;
                    i += 1;
                }
            }
        }
    }
    check_whole(r, layout.format, &layout.after).map_err(|(loc, m)| fail(loc, m))
}

/// Reads past `elements` (those after the vertices), checking that each holds as many records
/// as its header declares; a file cut short in them is truncated like one cut in its vertices.
fn check_whole(
    r: &mut dyn BufRead,
    format: PlyFormat,
    elements: &[ElementShape],
) -> std::result::Result<(), (String, String)> {
    let truncated =
        |e: &ElementShape, i: usize| ("data".to_string(), format!("truncated: {i} of {} {}", e.count, e.name));
    let mut line = String::new();
    for e in elements {
        for i in 0..e.count {
            let whole = match format {
                PlyFormat::Ascii => {
                    line.clear();
                    let read = r.read_line(&mut line).map_err(|err| (String::new(), err.to_string()))?;
                    read > 0 && !line.trim().is_empty()
                }
                PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
                    skip_binary_record(r, &e.properties, format == PlyFormat::BinaryLittleEndian)
                }
            };
            if !whole {
                return Err(truncated(e, i));
            }
        }
    }
    Ok(())
}

/// Reads past one binary record of `properties`; false where the file ends first.
fn skip_binary_record(r: &mut dyn BufRead, properties: &[DeclaredProperty], little: bool) -> bool {
    let skip = |r: &mut dyn BufRead, bytes: usize| {
        std::io::copy(&mut r.take(bytes as u64), &mut std::io::sink()).ok() == Some(bytes as u64)
    };
    let mut count = [0u8; 8];
    for p in properties {
        let whole = match p {
            DeclaredProperty::Scalar(_, k) => skip(&mut *r, k.size()),
            DeclaredProperty::List(n, item) => {
                let bytes = &mut count[..n.size()];
                if read_full(&mut *r, bytes).is_err() {
                    return false;
                }
                let items = n.decode(bytes, little);
                if !(items >= 0.0 && items.fract() == 0.0) {
                    return false;
                }
                skip(&mut *r, items as usize * item.size())
            }
        };
        if !whole {
            return false;
        }
    }
    true
}

/// Fills `buf` completely or returns how many bytes were read.
fn read_full(r: &mut dyn Read, buf: &mut [u8]) -> std::result::Result<(), usize> {
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

/// Reads a PLY point cloud (any encoding; extra elements such as faces are ignored). Scalar
/// fields keep their PLY types; coordinates in metres (`comment units m`) become millimetres.
pub fn read_ply_from(r: &mut dyn Read, name: &str) -> Result<PointCloud> {
    let mut reader = std::io::BufReader::with_capacity(1 << 16, r);
    let (header, layout) = read_header(&mut reader, name)?;
    let Some(layout) = layout else {
        return read_ply_general(&mut std::io::Cursor::new(header).chain(reader), name);
    };
    // The header's count is only a hint: a corrupt one must not reserve gigabytes.
    let reserve = layout.count.min(1 << 22);
    let mut cloud = PointCloud {
        positions: Vec::with_capacity(reserve),
        scalars: layout
            .scalar_fields()
            .into_iter()
            .map(|(name, ty)| ScalarField { name, values: Vec::with_capacity(reserve), ty })
            .collect(),
    };
    visit_vertices::<std::convert::Infallible>(&mut reader, name, &layout, &mut |p, s| {
        cloud.positions.push(*p);
        for (f, v) in cloud.scalars.iter_mut().zip(s) {
            f.values.push(*v);
        }
        Ok(())
    })
    .map_err(|e| match e {
        VisitError::Read(e) => e,
        VisitError::Stopped(never) => match never {},
    })?;
    Ok(cloud)
}

/// One vertex as parsed by the general reader: x y z plus the other scalar properties in header
/// order.
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

fn scalar_type(t: &ply_rs_bw::ply::ScalarType) -> ScalarType {
    use ply_rs_bw::ply::ScalarType as P;
    match t {
        P::Char => ScalarType::I8,
        P::UChar => ScalarType::U8,
        P::Short => ScalarType::I16,
        P::UShort => ScalarType::U16,
        P::Int => ScalarType::I32,
        P::UInt => ScalarType::U32,
        P::Float => ScalarType::F32,
        P::Double => ScalarType::F64,
    }
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

/// The general reader (`ply-rs-bw`): any layout, the whole file loaded.
fn read_ply_general(r: &mut dyn Read, name: &str) -> Result<PointCloud> {
    let mut reader = std::io::BufReader::with_capacity(1 << 16, r);
    let parser = Parser::<Vertex>::new();
    let mut raw = ply_rs_bw::parser::Reader::new(&mut reader);
    let header = parser.read_header(&mut raw).map_err(|e| Error::new(name, "header", e.to_string()))?;
    let ply_rs_bw::ply::Version { major, minor } = header.version;
    if (major, minor) != (1, 0) {
        return Err(Error::new(name, "header", format!("PLY version {major}.{minor}: this build reads PLY 1.0")));
    }
    let vertex_def =
        header.elements.get("vertex").ok_or_else(|| Error::new(name, "header", "no `vertex` element"))?.clone();
    let mm_per_unit = if header.comments.iter().any(|c| c.trim() == "units m") { 1000.0 } else { 1.0 };
    let fields: Vec<(String, ScalarType)> = vertex_def
        .properties
        .iter()
        .filter(|(k, _)| !["x", "y", "z"].contains(&k.as_str()))
        .filter_map(|(k, p)| match &p.data_type {
            ply_rs_bw::ply::PropertyType::Scalar(t) => Some((k.clone(), scalar_type(t))),
            _ => None,
        })
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
        scalars: fields
            .iter()
            .map(|(n, ty)| ScalarField { name: n.clone(), values: Vec::with_capacity(vertices.len()), ty: *ty })
            .collect(),
    };
    for (i, v) in vertices.into_iter().enumerate() {
        if v.seen != 7 || v.extra.len() != fields.len() {
            return Err(Error::new(name, format!("vertex {i}"), "missing properties"));
        }
        let xyz = v.xyz.map(|c| c * mm_per_unit);
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(Error::new(name, format!("vertex {i}"), "coordinate is not a finite number"));
        }
        cloud.positions.push(xyz);
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
                ScalarField::new("intensity", (0..100).map(|i| i as f32).collect()),
                ScalarField::new("scalar_frame", (0..100).map(|i| (i / 10) as f32).collect()),
            ],
        }
    }

    /// PLY has one version: a header naming another is refused by both readers.
    #[test]
    fn other_ply_versions_are_refused() {
        for encoding in ["ascii", "binary_little_endian"] {
            let text = format!("ply\nformat {encoding} 9.0\nelement vertex 0\nproperty float x\nend_header\n");
            let err = read_ply_from(&mut text.as_bytes(), "v9.ply").unwrap_err().to_string();
            assert!(err.contains("v9.ply") && err.contains("PLY version 9.0"), "{err}");
            let mut input = text.as_bytes();
            let Err(err) = read_header(&mut input, "v9.ply") else { panic!("PLY 9.0 read") };
            assert!(err.to_string().contains("PLY version 9.0"), "{err}");
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
    fn keeps_scalar_types_double_coordinates_and_units() {
        let mut cloud = sample();
        cloud.positions[3] = [1234.567891234, -0.000123, 9876.54321];
        cloud.scalars.push(ScalarField { name: "red".into(), values: vec![200.0; 100], ty: ScalarType::U8 });
        cloud.scalars.push(ScalarField { name: "label".into(), values: vec![-7.0; 100], ty: ScalarType::I16 });
        for ascii in [false, true] {
            for units in [Units::Millimetres, Units::Metres] {
                let opts = CloudOptions { ascii, double: true, units };
                let mut buf = Vec::new();
                write_ply_with(&mut buf, &cloud, &opts).unwrap();
                let text = String::from_utf8_lossy(&buf[..400]).into_owned();
                assert!(text.contains("property uchar red\nproperty short label\n"), "{text}");
                assert!(text.contains("property double x\n"), "{text}");
                assert!(text.contains(&format!("comment units {}\n", units.name())), "{text}");
                let back = read_ply_from(&mut buf.as_slice(), "mem").unwrap();
                assert_eq!(back.scalars, cloud.scalars);
                for (a, b) in back.positions.iter().zip(&cloud.positions) {
                    for k in 0..3 {
                        // Metres lose at most the last bit of the double's mantissa to the
                        // ×0.001 and ×1000 round trip.
                        assert!((a[k] - b[k]).abs() <= 1e-12 * b[k].abs().max(1.0), "{units:?}: {a:?} vs {b:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn integer_fields_are_rounded_and_clamped_when_written() {
        let cloud = PointCloud {
            positions: vec![[0.0; 3]; 4],
            scalars: vec![ScalarField {
                name: "red".into(),
                values: vec![12.4, 12.6, 300.0, -5.0],
                ty: ScalarType::U8,
            }],
        };
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &cloud, Encoding::BinaryLittleEndian).unwrap();
        assert_eq!(&buf[buf.len() - 13 * 4..].chunks(13).map(|r| r[12]).collect::<Vec<_>>(), &[12, 13, 255, 0]);
    }

    #[test]
    fn reads_foreign_property_order_and_types() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty uchar red\nproperty double z\nproperty float x\nproperty int y\nproperty list uchar int idx\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n10 3.5 1.25 -2 2 0 1\n20 4.5 2.25 7 0\n3 0 1 1\n";
        let c = read_ply_from(&mut text.as_bytes(), "foreign.ply").unwrap();
        assert_eq!(c.positions, vec![[1.25, -2.0, 3.5], [2.25, 7.0, 4.5]]);
        assert_eq!(c.scalar("red").unwrap(), &[10.0, 20.0]);
        assert_eq!(c.scalars[0].ty, ScalarType::U8);
    }

    #[test]
    fn reads_big_endian_and_the_direct_path_equals_the_general_reader() {
        let mut bytes = b"ply\nformat binary_big_endian 1.0\ncomment units m\nelement vertex 2\nproperty uchar red\nproperty double x\nproperty float y\nproperty double z\nend_header\n".to_vec();
        for (r, p) in [(7u8, [1.5f64, 2.5, 3.5]), (9, [-1.0, 0.0, 1e3])] {
            bytes.push(r);
            bytes.extend_from_slice(&p[0].to_be_bytes());
            bytes.extend_from_slice(&(p[1] as f32).to_be_bytes());
            bytes.extend_from_slice(&p[2].to_be_bytes());
        }
        let direct = read_ply_from(&mut bytes.as_slice(), "be.ply").unwrap();
        assert_eq!(direct.positions, vec![[1500.0, 2500.0, 3500.0], [-1000.0, 0.0, 1e6]]);
        let general = read_ply_general(&mut bytes.as_slice(), "be.ply").unwrap();
        assert_eq!(direct, general);
    }

    #[test]
    fn truncated_and_garbage_are_errors() {
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &sample(), Encoding::BinaryLittleEndian).unwrap();
        buf.truncate(buf.len() - 7);
        let e = read_ply_from(&mut buf.as_slice(), "cut.ply").unwrap_err().to_string();
        assert!(e.starts_with("cut.ply: data: truncated: 99 of 100"), "{e}");
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
    fn elements_after_the_vertices_are_checked_whole() {
        let header = |format: &str, faces: usize| {
            format!(
                "ply\nformat {format} 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                 element face {faces}\nproperty list uchar int vertex_indices\nproperty uchar flag\nend_header\n"
            )
        };
        let ascii = |faces: usize, body: &str| header("ascii", faces) + "1 2 3\n4 5 6\n" + body;
        assert_eq!(read_ply_from(&mut ascii(2, "3 0 1 1 7\n2 0 1 7\n").as_bytes(), "a.ply").unwrap().len(), 2);
        let e = read_ply_from(&mut ascii(1000, "3 0 1 1 7\n").as_bytes(), "a.ply").unwrap_err().to_string();
        assert_eq!(e, "a.ply: data: truncated: 1 of 1000 face");
        let binary = |faces: usize, cut: usize| {
            let mut bytes = header("binary_little_endian", faces).into_bytes();
            for v in [1f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
                bytes.extend(v.to_le_bytes());
            }
            for _ in 0..2 {
                bytes.push(3);
                [0i32, 1, 1].iter().for_each(|i| bytes.extend(i.to_le_bytes()));
                bytes.push(7);
            }
            bytes.truncate(bytes.len() - cut);
            bytes
        };
        assert_eq!(read_ply_from(&mut binary(2, 0).as_slice(), "b.ply").unwrap().len(), 2);
        for (faces, cut, whole) in [(2, 1, 1), (2, 5, 1), (3, 0, 2)] {
            let e = read_ply_from(&mut binary(faces, cut).as_slice(), "b.ply").unwrap_err().to_string();
            assert_eq!(e, format!("b.ply: data: truncated: {whole} of {faces} face"));
        }
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
