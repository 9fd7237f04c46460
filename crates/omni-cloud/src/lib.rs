//! Point clouds for omniscan: triangulation, merging, motion compensation, voxel grid, outlier
//! removal and evaluation against primitives.
//!
//! * [`triangulate`]: stripe pixels → 3D points (ray ∩ light plane, laser assignment, grazing
//!   threshold); [`triangulate::intersect_ray`] is the per-point kernel.
//! * [`cloud`]: triangulated frames → a [`PointCloud`] with the standard scalar fields.
//! * [`voxel`]: voxel-grid downsampling (Open3D's centroid semantics, voxel-index order, whole
//!   clouds or streamed with bounded memory).
//! * [`filter`]: Open3D-compatible statistical / radius outlier removal, cropping (and the voxel
//!   functions, re-exported); [`kdtree`] is the neighbour search behind them.
//! * [`merge`]: many inputs → one cloud (pose, crop, voxel, outliers) with bounded memory;
//!   [`ply_stream`] visits PLY vertices without loading the file.
//! * [`normals`]: surface normals from a local plane fit, oriented towards the sensor.
//! * [`export`]: the command-line options and message grouping for cloud files and ROS 2 bags.
//! * [`motion`]: poses interpolated from odometry (slerp + lerp) for a moving sensor.
//! * [`eval`]: signed distances to a scene's true surfaces, per object.
//! * [`fit`]: RANSAC + least-squares plane, sphere, cylinder and cone fits and error statistics.
//!
//! Lengths are millimetres (world = receiver frame of SENSOR.md), angles radians in code.
//!
//! ```
//! use omni_cloud::filter::{radius_outlier_mask, statistical_outlier_mask};
//! let pts = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [40.0, 40.0, 40.0]];
//! assert_eq!(radius_outlier_mask(&pts, 2, 1.5).unwrap(), vec![true, true, true, true, false]);
//! assert_eq!(statistical_outlier_mask(&pts, 3, 1.0).unwrap().iter().filter(|k| **k).count(), 4);
//! ```

pub mod align;
pub mod cloud;
pub mod eval;
pub mod export;
pub mod filter;
pub mod fit;
pub mod kdtree;
pub mod merge;
pub mod motion;
pub mod normals;
pub mod ply_stream;
pub mod render;
pub use omni_geom::rng;
pub mod triangulate;
pub mod voxel;

pub use omni_formats::ply::PointCloud;
