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
//! Voxel downsampling replaces the points of each occupied voxel by their centroid (and each
//! scalar by its mean, as Open3D averages colours and normals). Voxel (i, j, k) covers
//! origin + size·[i, i+1) × … ; Open3D anchors its grid at min_bound − size/2, which
//! [`voxel_origin_open3d`] reproduces. The output is ordered by voxel index (i, then j, then k):
//! deterministic, unlike Open3D's hash-map order.

use crate::kdtree::KdTree;
use omni_formats::ply::{PointCloud, ScalarField};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A fast non-cryptographic hasher for voxel keys: multiply-rotate mixing per word, then the
/// MurmurHash3 finaliser. The finaliser matters: the hash table indexes buckets by the low bits,
/// and without it the low bits of a product depend only on the low bits of the key, so all
/// voxels of one z layer would collide.
#[derive(Default, Clone, Copy)]
pub struct FxHasher(u64);

impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(*b as u64);
        }
    }
    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Largest |voxel index| accepted (21 bits per axis, so a key packs into one u64).
const MAX_VOXEL_INDEX: i64 = (1 << 20) - 1;

/// A streaming voxel-grid accumulator: points go in one at a time, memory grows with the
/// number of occupied voxels, not with the number of points.
#[derive(Debug, Clone)]
pub struct VoxelGrid {
    size: f64,
    inv_size: f64,
    origin: [f64; 3],
    slots: HashMap<u64, u32, BuildHasherDefault<FxHasher>>,
    keys: Vec<u64>,
    sums: Vec<[f64; 3]>,
    counts: Vec<u32>,
    scalar_names: Vec<String>,
    /// Per voxel, one running sum per scalar field (row-major).
    scalar_sums: Vec<f64>,
}

impl VoxelGrid {
    /// A grid of cubes of edge `size` (mm) anchored at `origin`, averaging the named scalars.
    pub fn new(size: f64, origin: [f64; 3], scalar_names: Vec<String>) -> Result<Self, String> {
        if !(size.is_finite() && size > 0.0) {
            return Err(format!("voxel size must be a positive number, got {size}"));
        }
        Ok(VoxelGrid {
            size,
            inv_size: 1.0 / size,
            origin,
            slots: HashMap::default(),
            keys: Vec::new(),
            sums: Vec::new(),
            counts: Vec::new(),
            scalar_names,
            scalar_sums: Vec::new(),
        })
    }

    /// Number of occupied voxels so far.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The voxel index of a point, or an error if it is more than 2²⁰ voxels from the origin.
    #[inline]
    fn key(&self, p: &[f64; 3]) -> Result<u64, String> {
        let mut key = 0u64;
        for a in 0..3 {
            let i = ((p[a] - self.origin[a]) * self.inv_size).floor();
            if !(i.abs() <= MAX_VOXEL_INDEX as f64) {
                return Err(format!(
                    "point ({}, {}, {}) is more than 2^20 voxels of {} mm from the grid origin",
                    p[0], p[1], p[2], self.size
                ));
            }
            // Offset to non-negative so the packed keys sort like (i, j, k) tuples.
            key = (key << 21) | ((i as i64 + MAX_VOXEL_INDEX) as u64);
        }
        Ok(key)
    }

    /// Adds one point with its scalar values (same order as the grid's scalar names).
    #[inline]
    pub fn add(&mut self, p: &[f64; 3], scalars: &[f32]) -> Result<(), String> {
        let key = self.key(p)?;
        let ns = self.scalar_names.len();
        let next = self.keys.len() as u32;
        let slot = *self.slots.entry(key).or_insert(next) as usize;
        if slot == self.keys.len() {
            self.keys.push(key);
            self.sums.push([0.0; 3]);
            self.counts.push(0);
            self.scalar_sums.resize(self.scalar_sums.len() + ns, 0.0);
        }
        let s = &mut self.sums[slot];
        s[0] += p[0];
        s[1] += p[1];
        s[2] += p[2];
        self.counts[slot] += 1;
        for (acc, v) in self.scalar_sums[slot * ns..(slot + 1) * ns].iter_mut().zip(scalars) {
            *acc += *v as f64;
        }
        Ok(())
    }

    /// Adds every point of a cloud whose scalar fields are the grid's (by name).
    pub fn add_cloud(&mut self, cloud: &PointCloud) -> Result<(), String> {
        let fields: Vec<&[f32]> = self
            .scalar_names
            .iter()
            .map(|n| cloud.scalar(n).ok_or_else(|| format!("missing scalar field {n}")))
            .collect::<Result<_, _>>()?;
        let mut values = vec![0f32; fields.len()];
        for (i, p) in cloud.positions.iter().enumerate() {
            for (v, f) in values.iter_mut().zip(&fields) {
                *v = f[i];
            }
            self.add(p, &values)?;
        }
        Ok(())
    }

    /// The downsampled cloud: one centroid per voxel, ordered by voxel index.
    pub fn finish(self) -> PointCloud {
        let ns = self.scalar_names.len();
        let mut order: Vec<u32> = (0..self.keys.len() as u32).collect();
        order.sort_unstable_by_key(|&i| self.keys[i as usize]);
        let mut cloud = PointCloud {
            positions: Vec::with_capacity(order.len()),
            scalars: self
                .scalar_names
                .iter()
                .map(|n| ScalarField { name: n.clone(), values: Vec::with_capacity(order.len()) })
                .collect(),
        };
        for &i in &order {
            let i = i as usize;
            let n = self.counts[i] as f64;
            let s = self.sums[i];
            cloud.positions.push([s[0] / n, s[1] / n, s[2] / n]);
            for (f, acc) in cloud.scalars.iter_mut().zip(&self.scalar_sums[i * ns..(i + 1) * ns]) {
                f.values.push((acc / n) as f32);
            }
        }
        cloud
    }
}

/// Open3D's grid anchor for `VoxelDownSample`: the cloud's minimum bound minus half a voxel.
pub fn voxel_origin_open3d(points: &[[f64; 3]], size: f64) -> [f64; 3] {
    let mut lo = [f64::INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
        }
    }
    lo.map(|v| if v.is_finite() { v - 0.5 * size } else { 0.0 })
}

/// Voxel-grid downsampling of a whole cloud (module docs). Same output as feeding the points
/// through a [`VoxelGrid`] in order, bit for bit, but faster: voxel keys are computed in
/// parallel, voxels are numbered in a tight hashing pass over the keys alone, and the sums are
/// accumulated in one sequential pass over the input (each voxel's sum in input order).
pub fn voxel_downsample(cloud: &PointCloud, size: f64, origin: [f64; 3]) -> Result<PointCloud, String> {
    let names: Vec<String> = cloud.scalars.iter().map(|s| s.name.clone()).collect();
    let grid = VoxelGrid::new(size, origin, names.clone())?;
    let keys: Vec<u64> = cloud.positions.par_iter().map(|p| grid.key(p)).collect::<Result<_, _>>()?;
    let mut slots: HashMap<u64, u32, BuildHasherDefault<FxHasher>> = HashMap::default();
    let mut voxel_keys: Vec<u64> = Vec::new();
    let slot_of: Vec<u32> = keys
        .iter()
        .map(|&k| {
            let next = voxel_keys.len() as u32;
            *slots.entry(k).or_insert_with(|| {
                voxel_keys.push(k);
                next
            })
        })
        .collect();
    drop(slots);
    drop(keys);
    let n_voxels = voxel_keys.len();
    let ns = cloud.scalars.len();
    let mut sums = vec![[0.0f64; 3]; n_voxels];
    let mut counts = vec![0u32; n_voxels];
    let mut scalar_sums = vec![0.0f64; n_voxels * ns];
    for (i, (p, &slot)) in cloud.positions.iter().zip(&slot_of).enumerate() {
        let slot = slot as usize;
        let s = &mut sums[slot];
        s[0] += p[0];
        s[1] += p[1];
        s[2] += p[2];
        counts[slot] += 1;
        for (acc, f) in scalar_sums[slot * ns..(slot + 1) * ns].iter_mut().zip(&cloud.scalars) {
            *acc += f.values[i] as f64;
        }
    }
    // Output in voxel-index order (deterministic whatever the input order).
    let mut order: Vec<u32> = (0..n_voxels as u32).collect();
    order.par_sort_unstable_by_key(|&v| voxel_keys[v as usize]);
    let mut out = PointCloud {
        positions: Vec::with_capacity(n_voxels),
        scalars: names.into_iter().map(|name| ScalarField { name, values: Vec::with_capacity(n_voxels) }).collect(),
    };
    for &v in &order {
        let v = v as usize;
        let (s, n) = (sums[v], counts[v] as f64);
        out.positions.push([s[0] / n, s[1] / n, s[2] / n]);
        for (f, acc) in out.scalars.iter_mut().zip(&scalar_sums[v * ns..(v + 1) * ns]) {
            f.values.push((acc / n) as f32);
        }
    }
    Ok(out)
}

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
    let pick = |v: &dyn Fn(usize) -> bool| (0..cloud.len()).filter(|&i| v(i)).collect::<Vec<_>>();
    let idx = pick(&|i| mask[i]);
    PointCloud {
        positions: idx.iter().map(|&i| cloud.positions[i]).collect(),
        scalars: cloud
            .scalars
            .iter()
            .map(|s| ScalarField { name: s.name.clone(), values: idx.iter().map(|&i| s.values[i]).collect() })
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
    fn voxel_centroids_counts_and_order() {
        let cloud = PointCloud {
            positions: vec![[0.2, 0.2, 0.2], [0.4, 0.6, 0.8], [1.5, 0.5, 0.5], [-0.5, 0.5, 0.5], [1.7, 0.1, 0.3]],
            scalars: vec![ScalarField { name: "intensity".into(), values: vec![10.0, 20.0, 30.0, 40.0, 50.0] }],
        };
        let out = voxel_downsample(&cloud, 1.0, [0.0; 3]).unwrap();
        assert_eq!(out.len(), 3);
        let expect = [[-0.5, 0.5, 0.5], [0.3, 0.4, 0.5], [1.6, 0.3, 0.4]];
        for (p, e) in out.positions.iter().zip(expect) {
            assert!((0..3).all(|a| (p[a] - e[a]).abs() < 1e-12), "{p:?} vs {e:?}");
        }
        assert_eq!(out.scalar("intensity").unwrap(), &[40.0, 15.0, 40.0]);
        // Same input in another order: same output (deterministic, order by voxel index).
        let mut rev = cloud.clone();
        rev.positions.reverse();
        rev.scalars[0].values.reverse();
        let out2 = voxel_downsample(&rev, 1.0, [0.0; 3]).unwrap();
        assert_eq!(out2.scalar("intensity"), out.scalar("intensity"));
        assert!(voxel_downsample(&cloud, 0.0, [0.0; 3]).is_err());
        assert!(voxel_downsample(&cloud, 1e-9, [0.0; 3]).is_err());
    }

    #[test]
    fn batch_voxel_equals_streaming_grid_bit_for_bit() {
        let pts = noisy_plane(5000, 50, 4);
        let cloud = PointCloud {
            scalars: vec![ScalarField { name: "i".into(), values: (0..pts.len()).map(|i| i as f32 * 0.1).collect() }],
            positions: pts,
        };
        let batch = voxel_downsample(&cloud, 3.0, [0.5, -0.25, 0.0]).unwrap();
        let mut grid = VoxelGrid::new(3.0, [0.5, -0.25, 0.0], vec!["i".into()]).unwrap();
        grid.add_cloud(&cloud).unwrap();
        assert_eq!(batch, grid.finish());
        assert!(batch.len() > 500 && batch.len() < cloud.len());
    }

    #[test]
    fn retain_matches_select() {
        let pts = noisy_plane(100, 5, 9);
        let cloud = PointCloud {
            scalars: vec![ScalarField { name: "i".into(), values: (0..pts.len()).map(|i| i as f32).collect() }],
            positions: pts,
        };
        let mask: Vec<bool> = (0..cloud.len()).map(|i| i % 3 != 0).collect();
        let mut c2 = cloud.clone();
        retain(&mut c2, &mask);
        assert_eq!(c2, select(&cloud, &mask));
    }
}
