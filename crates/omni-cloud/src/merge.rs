//! Merging point streams and PLY clouds into one cloud: pose (motion compensation), crop,
//! voxel grid, then statistical and radius outlier removal, in that order.
//!
//! Memory: inputs are visited point by point and never held whole. With `voxel` set, points
//! go into the streaming voxel grid ([`crate::voxel::VoxelGrid`]: one chunk of 2²¹ points plus
//! the occupied voxels' sums, so memory grows with occupied voxels); otherwise the
//! kept points are stored once (positions f64 + f32 scalars) and outlier removal filters that
//! one copy in place.
//!
//! With `viewpoints` set, each point also carries the point it was seen from (its stream's
//! viewpoint, the camera's mirror focus, moved by the frame's pose; the origin for a PLY input)
//! as three hidden f32
//! fields that go through the voxel grid (averaged: the mean of positions on the seen side of a
//! surface stays on that side) and the filters with the point, and come out beside the cloud.

use crate::cloud::POINT_SCALARS;
use crate::filter::{CropBox, VoxelGrid, radius_outlier_mask, retain, statistical_outlier_mask};
use nalgebra::{Isometry3, Point3};
use omni_formats::ply::{PointCloud, ScalarField, ScalarType};
use omni_formats::stream::Frame;

/// What to do to the merged points.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MergeOptions {
    /// Voxel edge (mm); the grid is anchored at the world origin, so a point's voxel does not
    /// depend on the other inputs.
    pub voxel: Option<f64>,
    /// Open3D `remove_statistical_outlier(nb_neighbors, std_ratio)`.
    pub statistical: Option<(usize, f64)>,
    /// Open3D `remove_radius_outlier(nb_points, radius)`.
    pub radius: Option<(usize, f64)>,
    /// Keep points inside this box (world frame, after the pose).
    pub crop_box: Option<CropBox>,
    /// Keep points whose measured range (distance from the viewpoint, mm) is in [min, max].
    pub crop_range: Option<(f64, f64)>,
    /// Keep each point's viewpoint (for normals facing the sensor of the point's own frame).
    pub viewpoints: bool,
}

/// The hidden fields that carry each point's viewpoint through the merge (never written out).
const VIEWPOINT_FIELDS: [&str; 3] = ["\u{0}viewpoint_x", "\u{0}viewpoint_y", "\u{0}viewpoint_z"];

/// Counts for the report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct MergeStats {
    pub points_in: u64,
    pub cropped: u64,
    pub after_voxel: u64,
    pub statistical_removed: u64,
    pub radius_removed: u64,
    pub points_out: u64,
}

enum Sink {
    Points(PointCloud),
    Voxels(VoxelGrid),
}

/// The merge in progress.
pub struct Merger {
    opts: MergeOptions,
    names: Vec<String>,
    /// The output fields' types (the first input's; written back so uchar colours stay uchar).
    types: Vec<ScalarType>,
    sink: Option<Sink>,
    stats: MergeStats,
    /// Maps the current input's scalar order onto the output's.
    map: Vec<usize>,
    range_index: Option<usize>,
    buf: Vec<f32>,
    /// The viewpoint of the points being added (mm, world frame).
    viewpoint: [f64; 3],
    /// The current stream's viewpoint (mm, sensor frame).
    stream_viewpoint: [f64; 3],
}

impl Merger {
    pub fn new(opts: MergeOptions) -> Result<Self, String> {
        if let Some(v) = opts.voxel
            && !(v > 0.0 && v.is_finite())
        {
            return Err(format!("voxel size must be positive, got {v}"));
        }
        if let Some((lo, hi)) = opts.crop_range
            && !(lo >= 0.0 && lo <= hi)
        {
            return Err(format!("crop range needs 0 ≤ min ≤ max, got {lo},{hi}"));
        }
        Ok(Merger {
            opts,
            names: Vec::new(),
            types: Vec::new(),
            sink: None,
            stats: MergeStats::default(),
            map: Vec::new(),
            range_index: None,
            buf: Vec::new(),
            viewpoint: [0.0; 3],
            stream_viewpoint: [0.0; 3],
        })
    }

    /// Declares the scalar fields of the next input (in its order). The first input fixes the
    /// output's fields; later inputs must carry all of them (extra fields are dropped).
    pub fn begin_input(&mut self, scalar_names: &[String]) -> Result<(), String> {
        self.begin_typed_input(scalar_names, &vec![ScalarType::F32; scalar_names.len()])
    }

    /// [`Merger::begin_input`] with the fields' types (one per name): the first input's types
    /// are the output's.
    pub fn begin_typed_input(&mut self, scalar_names: &[String], types: &[ScalarType]) -> Result<(), String> {
        if types.len() != scalar_names.len() {
            return Err(format!("internal: {} types for {} scalar fields", types.len(), scalar_names.len()));
        }
        if self.sink.is_none() {
            if let Some(n) = scalar_names.iter().find(|n| VIEWPOINT_FIELDS.contains(&n.as_str())) {
                return Err(format!("scalar field name {n:?} is reserved"));
            }
            self.names = scalar_names.to_vec();
            self.types = types.to_vec();
            let mut fields = self.names.clone();
            if self.opts.viewpoints {
                fields.extend(VIEWPOINT_FIELDS.iter().map(|n| n.to_string()));
            }
            self.sink = Some(match self.opts.voxel {
                Some(size) => Sink::Voxels(VoxelGrid::new(size, [0.0; 3], fields)?),
                None => Sink::Points(PointCloud {
                    positions: Vec::new(),
                    scalars: fields.into_iter().map(|n| ScalarField::new(n, Vec::new())).collect(),
                }),
            });
        }
        self.map = self
            .names
            .iter()
            .map(|n| {
                scalar_names.iter().position(|m| m == n).ok_or_else(|| {
                    format!("has no scalar field `{n}` (the first input has it; all inputs must share fields)")
                })
            })
            .collect::<Result<_, _>>()?;
        self.range_index = scalar_names.iter().position(|n| n == "scalar_range");
        if self.opts.crop_range.is_some() && self.range_index.is_none() {
            return Err("has no `scalar_range` field, needed by the range crop".into());
        }
        self.buf = vec![0.0; self.names.len() + if self.opts.viewpoints { 3 } else { 0 }];
        self.viewpoint = [0.0; 3];
        self.stream_viewpoint = [0.0; 3];
        Ok(())
    }

    /// Adds one point of the current input (scalars in the order given to [`begin_input`]).
    ///
    /// [`begin_input`]: Merger::begin_input
    pub fn add(&mut self, p: &[f64; 3], scalars: &[f32]) -> Result<(), String> {
        self.stats.points_in += 1;
        if let (Some((lo, hi)), Some(ri)) = (self.opts.crop_range, self.range_index) {
            let r = scalars[ri] as f64;
            if !(r >= lo && r <= hi) {
                self.stats.cropped += 1;
                return Ok(());
            }
        }
        if let Some(b) = &self.opts.crop_box
            && !b.contains(p)
        {
            self.stats.cropped += 1;
            return Ok(());
        }
        for (o, &i) in self.buf.iter_mut().zip(&self.map) {
            *o = scalars[i];
        }
        if self.opts.viewpoints {
            let n = self.names.len();
            for (o, v) in self.buf[n..].iter_mut().zip(self.viewpoint) {
                *o = v as f32;
            }
        }
        match self.sink.as_mut().ok_or("internal: add before begin_input")? {
            Sink::Voxels(g) => g.add(p, &self.buf)?,
            Sink::Points(c) => {
                c.positions.push(*p);
                for (f, v) in c.scalars.iter_mut().zip(&self.buf) {
                    f.values.push(*v);
                }
            }
        }
        Ok(())
    }

    /// Starts a point-stream input (scalar fields [`POINT_SCALARS`]).
    pub fn begin_stream_input(&mut self) -> Result<(), String> {
        let names: Vec<String> = POINT_SCALARS.iter().map(|s| s.to_string()).collect();
        self.begin_input(&names)
    }

    /// The point the current stream's frames were seen from (mm, sensor frame: its header's
    /// `viewpoint_mm`, the origin where it has none).
    pub fn set_stream_viewpoint(&mut self, viewpoint_mm: [f64; 3]) {
        self.stream_viewpoint = viewpoint_mm;
    }

    /// Adds a triangulated frame's points, mapped by `pose` (sensor → world) if given; their
    /// viewpoint is the stream's ([`Merger::set_stream_viewpoint`]) moved by the pose. Call
    /// [`Merger::begin_stream_input`] first for each stream.
    pub fn add_frame(&mut self, frame: &Frame, pose: Option<&Isometry3<f64>>) -> Result<(), String> {
        let seen_from = Point3::from(self.stream_viewpoint);
        self.viewpoint = pose.map_or(seen_from, |iso| iso * seen_from).coords.into();
        let points = frame.points.as_ref().ok_or("no `points` field (run omni-triangulate first)")?;
        let stripe = frame.stripe.as_deref().unwrap_or(&[]);
        for (i, p) in points.iter().enumerate() {
            if !(p.xyz.iter().all(|c| c.is_finite()) && p.range.is_finite()) {
                return Err(format!("field points[{i}]: not a finite number"));
            }
            let sp = match stripe.get(p.stripe_index as usize) {
                Some(sp) => Some(sp),
                None if stripe.is_empty() => None,
                None => return Err(format!("field points[{i}]: stripe_index {} out of range", p.stripe_index)),
            };
            let xyz = match pose {
                Some(iso) => (iso * Point3::from(p.xyz)).coords.into(),
                None => p.xyz,
            };
            let scalars = [
                sp.map_or(0.0, |s| s.intensity as f32),
                frame.seq as f32,
                p.laser as f32,
                frame.alpha_deg as f32,
                p.range as f32,
                sp.map_or(0.0, |s| s.u as f32),
                sp.map_or(0.0, |s| s.v as f32),
            ];
            self.add(&xyz, &scalars)?;
        }
        Ok(())
    }

    /// Finishes: voxel centroids, then statistical and radius outlier removal.
    pub fn finish(self) -> Result<(PointCloud, MergeStats), String> {
        self.finish_with_viewpoints().map(|(cloud, stats, _)| (cloud, stats))
    }

    /// [`Merger::finish`], with each output point's viewpoint (mm, world frame) if
    /// [`MergeOptions::viewpoints`] is set (a voxel's: the mean of its points').
    #[allow(clippy::type_complexity)]
    pub fn finish_with_viewpoints(mut self) -> Result<(PointCloud, MergeStats, Option<Vec<[f64; 3]>>), String> {
        let mut cloud = match self.sink.take() {
            None => return Err("no input points".into()),
            Some(Sink::Points(c)) => c,
            Some(Sink::Voxels(g)) => g.finish()?,
        };
        for (f, ty) in cloud.scalars.iter_mut().zip(&self.types) {
            f.ty = *ty;
        }
        self.stats.after_voxel = cloud.len() as u64;
        if let Some((k, ratio)) = self.opts.statistical {
            let mask = statistical_outlier_mask(&cloud.positions, k, ratio)?;
            let before = cloud.len();
            retain(&mut cloud, &mask);
            self.stats.statistical_removed = (before - cloud.len()) as u64;
        }
        if let Some((n, r)) = self.opts.radius {
            let mask = radius_outlier_mask(&cloud.positions, n, r)?;
            let before = cloud.len();
            retain(&mut cloud, &mask);
            self.stats.radius_removed = (before - cloud.len()) as u64;
        }
        self.stats.points_out = cloud.len() as u64;
        let viewpoints = self.opts.viewpoints.then(|| {
            let axes: Vec<ScalarField> = cloud.scalars.drain(self.names.len()..).collect();
            (0..cloud.len()).map(|i| [0, 1, 2].map(|a| axes[a].values[i] as f64)).collect()
        });
        Ok((cloud, self.stats, viewpoints))
    }
}
