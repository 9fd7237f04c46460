//! Voxel-grid downsampling, statistical and radius outlier removal, cropping.
//!
//! Outlier removal follows Open3D's definitions exactly (checked against its source,
//! `PointCloud::RemoveStatisticalOutliers` / `RemoveRadiusOutliers`), so kept sets can be
//! compared point for point:
//! * statistical (`remove_statistical_outlier(nb_neighbors, std_ratio)`): for each point, the
//!   mean Euclidean distance to its `k` nearest points **including itself** (the query point
//!   is its own first neighbour at distance 0, so k = 1 means "itself only"); over all points
//!   with a positive mean, the cloud mean m and the sample standard deviation s (Bessel, n − 1);
//!   a point is kept iff 0 < its mean < m + std_ratio·s (strictly). A point whose k neighbours
//!   all coincide with it (mean 0) is removed, as in Open3D.
//! * radius (`remove_radius_outlier(nb_points, radius)`): the number of points strictly within
//!   `radius` (|p − q| < r), **including the point itself**; kept iff that count > nb_points,
//!   i.e. iff at least `nb_points` *other* points lie within the radius.
//!
//! Voxel downsampling lives in [`crate::voxel`] (re-exported here): the centroid of each
//! occupied voxel's points, scalars averaged, output in voxel-index order.

use crate::kdtree::KdTree;
use omni_formats::ply::{PointCloud, ScalarField};
use rayon::prelude::*;

pub use crate::voxel::{VoxelGrid, voxel_downsample, voxel_origin_open3d};

/// Open3D-compatible statistical outlier mask (module docs): `true` = keep.
pub fn statistical_outlier_mask(points: &[[f64; 3]], nb_neighbors: usize, std_ratio: f64) -> Result<Vec<bool>, String> {
    if nb_neighbors < 1 || !(std_ratio > 0.0) {
        return Err("statistical outlier removal needs nb_neighbors ≥ 1 and std_ratio > 0".into());
    }
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let tree = KdTree::build(points);
    let mean_dist = mean_neighbour_distances(&tree, nb_neighbors);
    let valid: Vec<f64> = mean_dist.iter().copied().filter(|&d| d > 0.0).collect();
    if valid.is_empty() {
        return Ok(vec![false; points.len()]);
    }
    let n = valid.len() as f64;
    let cloud_mean = valid.iter().sum::<f64>() / n;
    let sq_sum: f64 = valid.iter().map(|d| (d - cloud_mean) * (d - cloud_mean)).sum();
    // Bessel's correction as Open3D (a single valid point gives NaN there too: keep nothing).
    let std_dev = (sq_sum / (n - 1.0)).sqrt();
    let threshold = cloud_mean + std_ratio * std_dev;
    Ok(mean_dist.iter().map(|&d| d > 0.0 && d < threshold).collect())
}

/// For each point (input order), the mean distance to its `k` nearest points including itself.
fn mean_neighbour_distances(tree: &KdTree, k: usize) -> Vec<f64> {
    let order: Vec<(u32, [f64; 3])> = tree.tree_order().map(|(i, p)| (i, *p)).collect();
    let per_tree_order: Vec<f64> = order
        .par_chunks(4096)
        .flat_map_iter(|chunk| {
            let mut buf = Vec::with_capacity(k + 1);
            chunk
                .iter()
                .map(|(_, p)| {
                    tree.knn(p, k, &mut buf);
                    buf.iter().map(|e| e.0.sqrt()).sum::<f64>() / buf.len() as f64
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let mut out = vec![0.0; order.len()];
    for ((i, _), d) in order.iter().zip(per_tree_order) {
        out[*i as usize] = d;
    }
    out
}

/// Open3D-compatible radius outlier mask (module docs): `true` = keep.
pub fn radius_outlier_mask(points: &[[f64; 3]], nb_points: usize, radius: f64) -> Result<Vec<bool>, String> {
    if nb_points < 1 || !(radius > 0.0 && radius.is_finite()) {
        return Err("radius outlier removal needs nb_points ≥ 1 and a positive radius".into());
    }
    let tree = KdTree::build(points);
    let order: Vec<(u32, [f64; 3])> = tree.tree_order().map(|(i, p)| (i, *p)).collect();
    let keep_tree: Vec<bool> =
        order.par_iter().map(|(_, p)| tree.count_within(p, radius, nb_points + 1) > nb_points).collect();
    let mut out = vec![false; points.len()];
    for ((i, _), k) in order.iter().zip(keep_tree) {
        out[*i as usize] = k;
    }
    Ok(out)
}

/// The points (and their scalars) for which `mask` is true, in order.
pub fn select(cloud: &PointCloud, mask: &[bool]) -> PointCloud {
    let idx: Vec<usize> = (0..cloud.len()).filter(|&i| mask[i]).collect();
    gather(cloud, &idx)
}

/// The points (and their scalars) at the indices `idx`, in that order.
pub fn gather(cloud: &PointCloud, idx: &[usize]) -> PointCloud {
    PointCloud {
        positions: idx.iter().map(|&i| cloud.positions[i]).collect(),
        scalars: cloud
            .scalars
            .iter()
            .map(|s| ScalarField { name: s.name.clone(), values: idx.iter().map(|&i| s.values[i]).collect(), ty: s.ty })
            .collect(),
    }
}

/// In-place variant of [`select`] that never holds two copies of the cloud.
pub fn retain(cloud: &mut PointCloud, mask: &[bool]) {
    let mut w = 0;
    for r in 0..cloud.positions.len() {
        if mask[r] {
            cloud.positions[w] = cloud.positions[r];
            for s in cloud.scalars.iter_mut() {
                s.values[w] = s.values[r];
            }
            w += 1;
        }
    }
    cloud.positions.truncate(w);
    cloud.positions.shrink_to_fit();
    for s in cloud.scalars.iter_mut() {
        s.values.truncate(w);
        s.values.shrink_to_fit();
    }
}

/// An axis-aligned box (mm, inclusive bounds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropBox {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl CropBox {
    pub fn new(min: [f64; 3], max: [f64; 3]) -> Result<Self, String> {
        if !(0..3).all(|a| min[a].is_finite() && max[a].is_finite() && min[a] <= max[a]) {
            return Err(format!("crop box min {min:?} must not exceed max {max:?}"));
        }
        Ok(CropBox { min, max })
    }

    #[inline]
    pub fn contains(&self, p: &[f64; 3]) -> bool {
        (0..3).all(|a| p[a] >= self.min[a] && p[a] <= self.max[a])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn noisy_plane(n: usize, outliers: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = SplitMix64::new(seed);
        let mut pts: Vec<[f64; 3]> =
            (0..n).map(|_| [rng.uniform() * 100.0, rng.uniform() * 100.0, rng.normal() * 0.2]).collect();
        for _ in 0..outliers {
            pts.push([rng.uniform() * 100.0, rng.uniform() * 100.0, 5.0 + rng.uniform() * 30.0]);
        }
        pts
    }

    /// Open3D's algorithm written the slow obvious way (brute-force neighbours).
    fn brute_statistical(pts: &[[f64; 3]], k: usize, ratio: f64) -> Vec<bool> {
        let means: Vec<f64> = pts
            .iter()
            .map(|q| {
                let mut d: Vec<f64> = pts
                    .iter()
                    .map(|p| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
                    .collect();
                d.sort_by(f64::total_cmp);
                d[..k.min(d.len())].iter().sum::<f64>() / k.min(d.len()) as f64
            })
            .collect();
        let valid: Vec<f64> = means.iter().copied().filter(|&m| m > 0.0).collect();
        let m = valid.iter().sum::<f64>() / valid.len() as f64;
        let s = (valid.iter().map(|d| (d - m).powi(2)).sum::<f64>() / (valid.len() as f64 - 1.0)).sqrt();
        means.iter().map(|&d| d > 0.0 && d < m + ratio * s).collect()
    }

    #[test]
    fn statistical_matches_the_brute_force_definition_and_drops_planted_outliers() {
        let pts = noisy_plane(1500, 40, 3);
        let mask = statistical_outlier_mask(&pts, 10, 1.0).unwrap();
        assert_eq!(mask, brute_statistical(&pts, 10, 1.0));
        let removed_outliers = mask[1500..].iter().filter(|k| !**k).count();
        assert!(removed_outliers >= 38, "only {removed_outliers} of 40 outliers removed");
    }

    #[test]
    fn radius_counts_include_the_point_itself() {
        // Three points in a row 1 mm apart, one far away.
        let pts = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [50.0, 0.0, 0.0]];
        // Radius 1.5: the middle point has 2 others, the ends 1 other, the far point 0.
        assert_eq!(radius_outlier_mask(&pts, 1, 1.5).unwrap(), vec![true, true, true, false]);
        assert_eq!(radius_outlier_mask(&pts, 2, 1.5).unwrap(), vec![false, true, false, false]);
        // Strict inequality: a neighbour at exactly the radius does not count.
        assert_eq!(radius_outlier_mask(&pts, 1, 1.0).unwrap(), vec![false; 4]);
    }

    #[test]
    fn retain_matches_select() {
        let pts = noisy_plane(100, 5, 9);
        let cloud = PointCloud {
            scalars: vec![ScalarField::new("i", (0..pts.len()).map(|i| i as f32).collect())],
            positions: pts,
        };
        let mask: Vec<bool> = (0..cloud.len()).map(|i| i % 3 != 0).collect();
        let mut c2 = cloud.clone();
        retain(&mut c2, &mask);
        assert_eq!(c2, select(&cloud, &mask));
    }
}
