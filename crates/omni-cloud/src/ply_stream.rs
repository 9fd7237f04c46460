//! Streaming PLY vertex reader: visits points one by one without holding the file in memory
//! (the merge of a 50-million-point cloud must not need it twice).
//!
//! The common layout (`vertex` the first element, scalar properties only) is decoded as it is
//! read by `omni_formats::ply::visit_vertices`; anything else (lists in the vertex element,
//! vertex not first) falls back to the full reader `omni_formats::ply::read_ply`, which loads
//! the file.

use omni_formats::ply::{ScalarType, VisitError, read_header, read_ply, visit_vertices};
use std::path::Path;

/// Called once per file with the scalar names (header order, without x y z) and vertex count.
pub type HeaderFn<'a> = dyn FnMut(&[String], usize) -> Result<(), String> + 'a;
/// [`HeaderFn`] with the scalar fields' PLY types.
pub type TypedHeaderFn<'a> = dyn FnMut(&[String], &[ScalarType], usize) -> Result<(), String> + 'a;
/// Called per vertex with its position and scalars.
pub type PointFn<'a> = dyn FnMut(&[f64; 3], &[f32]) -> Result<(), String> + 'a;

/// Visits every vertex of a PLY file: first `on_header(scalar names, vertex count)`, then
/// `on_point(xyz, scalars)` per vertex, scalars in header order without x y z. Non-finite
/// coordinates and truncation are errors naming the file and vertex.
pub fn for_each_vertex(path: &Path, on_header: &mut HeaderFn, on_point: &mut PointFn) -> Result<(), String> {
    for_each_vertex_typed(path, &mut |names, _, n| on_header(names, n), on_point)
}

/// [`for_each_vertex`] that also hands `on_header` the scalar fields' types.
pub fn for_each_vertex_typed(path: &Path, on_header: &mut TypedHeaderFn, on_point: &mut PointFn) -> Result<(), String> {
    let name = omni_formats::io::display_name(path, "stdin");
    let mut input = omni_formats::io::open_input(path).map_err(|e| e.to_string())?;
    let (_, layout) = read_header(&mut input, &name).map_err(|e| e.to_string())?;
    let Some(layout) = layout else {
        drop(input);
        return for_each_vertex_loaded(path, on_header, on_point);
    };
    let (names, types): (Vec<String>, Vec<ScalarType>) = layout.scalar_fields().into_iter().unzip();
    on_header(&names, &types, layout.count)?;
    visit_vertices(&mut input, &name, &layout, on_point).map_err(|e| match e {
        VisitError::Read(e) => e.to_string(),
        VisitError::Stopped(m) => m,
    })
}

/// General layouts: load with the full reader, then visit.
fn for_each_vertex_loaded(path: &Path, on_header: &mut TypedHeaderFn, on_point: &mut PointFn) -> Result<(), String> {
    let cloud = read_ply(path).map_err(|e| e.to_string())?;
    let names: Vec<String> = cloud.scalars.iter().map(|s| s.name.clone()).collect();
    let types: Vec<ScalarType> = cloud.scalars.iter().map(|s| s.ty).collect();
    on_header(&names, &types, cloud.len())?;
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
                cloud.borrow_mut().scalars = n.iter().map(|n| ScalarField::new(n.clone(), vec![])).collect();
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
            scalars: vec![ScalarField::new("intensity", (0..5000).map(|i| i as f32).collect())],
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
