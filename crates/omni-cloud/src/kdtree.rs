//! A static 3D k-d tree for k-nearest-neighbour and fixed-radius queries (mm).
//!
//! Built once by median splits along the widest axis; points are copied in tree order so that
//! leaves are contiguous in memory (queries walk few cache lines). Queries are read-only and
//! can run from many threads.

/// Points per leaf: small enough to prune well, large enough to keep the tree shallow.
const LEAF_SIZE: usize = 12;
const NO_CHILD: u32 = u32::MAX;

#[derive(Debug, Clone, Copy)]
struct Node {
    /// Range of `points` below this node.
    start: u32,
    end: u32,
    /// Split coordinate and axis (inner nodes only).
    split: f64,
    axis: u8,
    left: u32,
    right: u32,
}

/// The tree. Point indices returned by queries refer to the slice it was built from.
#[derive(Debug, Clone)]
pub struct KdTree {
    points: Vec<[f64; 3]>,
    index: Vec<u32>,
    nodes: Vec<Node>,
}

impl KdTree {
    /// Builds the tree over `points` (at most 2³² − 1 points; non-finite coordinates are the
    /// caller's responsibility to reject beforehand).
    pub fn build(points: &[[f64; 3]]) -> Self {
        assert!(points.len() < u32::MAX as usize, "k-d tree holds at most 2^32 - 1 points");
        let mut index: Vec<u32> = (0..points.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * points.len() / LEAF_SIZE + 1);
        if !points.is_empty() {
            build_node(points, &mut index, 0, &mut nodes);
        }
        let ordered = index.iter().map(|&i| points[i as usize]).collect();
        KdTree { points: ordered, index, nodes }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The points in tree order, with their original indices: iterating queries in this order
    /// is much more cache-friendly than in input order.
    pub fn tree_order(&self) -> impl Iterator<Item = (u32, &[f64; 3])> {
        self.index.iter().copied().zip(self.points.iter())
    }

    /// The `k` nearest points to `q` (including a point equal to `q` itself, as Open3D's
    /// `SearchKNN` does), as (squared distance, original index), nearest first. Fewer than `k`
    /// if the tree is smaller. `out` is cleared first.
    pub fn knn(&self, q: &[f64; 3], k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k == 0 || self.nodes.is_empty() {
            return;
        }
        self.knn_node(0, q, k, [0.0; 3], 0.0, out);
    }

    /// `off`/`rd`: per-axis offsets from `q` to the node's cell and their squared sum (the
    /// incremental distance of Arya & Mount), a much tighter bound than the last split alone.
    fn knn_node(&self, n: usize, q: &[f64; 3], k: usize, mut off: [f64; 3], rd: f64, out: &mut Vec<(f64, u32)>) {
        let node = self.nodes[n];
        if node.left == NO_CHILD {
            for i in node.start as usize..node.end as usize {
                let p = &self.points[i];
                let d2 = sq(p[0] - q[0]) + sq(p[1] - q[1]) + sq(p[2] - q[2]);
                if out.len() < k {
                    insert_sorted(out, (d2, self.index[i]));
                } else if d2 < out[k - 1].0 {
                    out.pop();
                    insert_sorted(out, (d2, self.index[i]));
                }
            }
            return;
        }
        let axis = node.axis as usize;
        let diff = q[axis] - node.split;
        let (near, far) = if diff < 0.0 { (node.left, node.right) } else { (node.right, node.left) };
        self.knn_node(near as usize, q, k, off, rd, out);
        let far_rd = rd - sq(off[axis]) + diff * diff;
        if out.len() < k || far_rd < out[k - 1].0 {
            off[axis] = diff;
            self.knn_node(far as usize, q, k, off, far_rd, out);
        }
    }

    /// How many points lie strictly within `radius` of `q` (|p − q| < radius), including a
    /// point equal to `q` itself (as Open3D's `SearchRadius`). Stops counting at `stop_at`.
    pub fn count_within(&self, q: &[f64; 3], radius: f64, stop_at: usize) -> usize {
        if self.nodes.is_empty() {
            return 0;
        }
        let mut count = 0;
        self.count_node(0, q, radius * radius, stop_at, [0.0; 3], 0.0, &mut count);
        count
    }

    fn count_node(
        &self,
        n: usize,
        q: &[f64; 3],
        r2: f64,
        stop_at: usize,
        mut off: [f64; 3],
        rd: f64,
        count: &mut usize,
    ) {
        if *count >= stop_at {
            return;
        }
        let node = self.nodes[n];
        if node.left == NO_CHILD {
            for p in &self.points[node.start as usize..node.end as usize] {
                let d2 = sq(p[0] - q[0]) + sq(p[1] - q[1]) + sq(p[2] - q[2]);
                *count += (d2 < r2) as usize;
            }
            return;
        }
        let axis = node.axis as usize;
        let diff = q[axis] - node.split;
        let (near, far) = if diff < 0.0 { (node.left, node.right) } else { (node.right, node.left) };
        self.count_node(near as usize, q, r2, stop_at, off, rd, count);
        let far_rd = rd - sq(off[axis]) + diff * diff;
        if far_rd < r2 {
            off[axis] = diff;
            self.count_node(far as usize, q, r2, stop_at, off, far_rd, count);
        }
    }
}

#[inline]
fn sq(x: f64) -> f64 {
    x * x
}

/// Inserts into a vector sorted by distance (k is small, so a linear shift beats a heap).
#[inline]
fn insert_sorted(out: &mut Vec<(f64, u32)>, item: (f64, u32)) {
    let pos = out.partition_point(|e| e.0 <= item.0);
    out.insert(pos, item);
}

/// Builds the subtree over `idx` (a sub-slice of the index array starting at `offset`);
/// returns the node's position.
fn build_node(points: &[[f64; 3]], idx: &mut [u32], offset: usize, nodes: &mut Vec<Node>) -> u32 {
    let me = nodes.len();
    let (start, end) = (offset as u32, (offset + idx.len()) as u32);
    nodes.push(Node { start, end, split: 0.0, axis: 0, left: NO_CHILD, right: NO_CHILD });
    if idx.len() <= LEAF_SIZE {
        return me as u32;
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &i in idx.iter() {
        let p = &points[i as usize];
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    if !(hi[axis] > lo[axis]) {
        return me as u32; // all points identical: one (large) leaf
    }
    let mid = idx.len() / 2;
    idx.select_nth_unstable_by(mid, |&a, &b| points[a as usize][axis].total_cmp(&points[b as usize][axis]));
    let split = points[idx[mid] as usize][axis];
    let (left_idx, right_idx) = idx.split_at_mut(mid);
    let left = build_node(points, left_idx, offset, nodes);
    let right = build_node(points, right_idx, offset + mid, nodes);
    let node = &mut nodes[me];
    node.split = split;
    node.axis = axis as u8;
    node.left = left;
    node.right = right;
    me as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn random_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = SplitMix64::new(seed);
        (0..n).map(|_| [rng.uniform() * 100.0, rng.uniform() * 50.0, (rng.uniform() * 10.0).round()]).collect()
    }

    #[test]
    fn knn_and_radius_match_brute_force() {
        let pts = random_points(3000, 7);
        let tree = KdTree::build(&pts);
        let mut out = Vec::new();
        for q in pts.iter().step_by(37).chain([[50.0, 25.0, 5.0], [-10.0, 0.0, 0.0]].iter()) {
            let mut brute: Vec<f64> = pts.iter().map(|p| sq(p[0] - q[0]) + sq(p[1] - q[1]) + sq(p[2] - q[2])).collect();
            brute.sort_by(f64::total_cmp);
            tree.knn(q, 9, &mut out);
            let got: Vec<f64> = out.iter().map(|e| e.0).collect();
            assert_eq!(got, brute[..9].to_vec());
            for (d2, i) in &out {
                let p = pts[*i as usize];
                assert_eq!(*d2, sq(p[0] - q[0]) + sq(p[1] - q[1]) + sq(p[2] - q[2]));
            }
            for r in [0.5, 3.0, 7.5] {
                let expect = brute.iter().filter(|&&d2| d2 < r * r).count();
                assert_eq!(tree.count_within(q, r, usize::MAX), expect);
            }
        }
    }

    #[test]
    fn duplicate_points_and_tiny_trees() {
        let pts = vec![[1.0, 2.0, 3.0]; 100];
        let tree = KdTree::build(&pts);
        let mut out = Vec::new();
        tree.knn(&[1.0, 2.0, 3.0], 5, &mut out);
        assert_eq!(out.len(), 5);
        assert!(out.iter().all(|e| e.0 == 0.0));
        let tree = KdTree::build(&pts[..2]);
        tree.knn(&[0.0; 3], 5, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(KdTree::build(&[]).count_within(&[0.0; 3], 1.0, usize::MAX), 0);
    }
}
