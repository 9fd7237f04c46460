//! Voxel-grid downsampling, fast and deterministic, for whole clouds and for streams.
//!
//! # Semantics (Open3D's `voxel_down_sample`)
//! Voxel (i, j, k) is the half-open cube origin + size·[i, i+1) × [j, j+1) × [k, k+1), with
//! i = ⌊(x − origin_x)/size⌋ computed as `((x - origin_x) * (1/size)).floor()` in f64. Each
//! occupied voxel becomes one point: the centroid of its points (sums accumulated in f64, in
//! input order, divided by the count), and every scalar field becomes the mean of its values
//! (f64 sums, written as f32), as Open3D averages colours and normals. Open3D anchors the grid
//! at the cloud's minimum bound minus half a voxel; [`voxel_origin_open3d`] gives that origin.
//!
//! # Output order (deterministic)
//! Voxels come out in lexicographic voxel-index order: by i, then j, then k (x slowest, z
//! fastest). The order, and every bit of the output, depends only on the set of input points
//! and their order, never on hashing, threads or chunk sizes: [`voxel_downsample`] and a
//! [`VoxelGrid`] fed the same points give identical clouds. (Open3D's order is its hash map's.)
//!
//! # Limits
//! Voxel indices must lie within ±(2²⁰ − 1) of the origin on each axis (so a voxel packs into a
//! 63-bit key); coordinates must be finite. Both are reported as errors.
//!
//! # How it is fast
//! No hash map and no per-point allocation. On a machine with 4 kB pages (and more so in a VM)
//! every random access to a table larger than the caches costs a cache miss plus a page walk,
//! which makes a per-point hash map slow on fine grids. Here every pass
//! over the points is sequential or touches only a cache-sized table:
//! * coarse grids (the points' voxel box has ≤ 2²¹ cells): one pass summing each point into its
//!   voxel through a cell → voxel table, then the cells are walked in key order;
//! * fine grids: the voxel key relative to the box is a mixed-radix number that sorts like
//!   (i, j, k); one pass counts key prefixes (top 16 bits), which are cut into buckets of
//!   ≈ 16384 points; one pass copies the points into bucket order (stable); each bucket, now in
//!   L2, is LSD radix sorted on (key, index) words (stable) and runs of equal keys are summed.
//!
//! Fine grids use every core (rayon): the bounding box, the prefix counts and the copy run on
//! parts of the input (per-part histograms and prefix sums make the copy stable), and the
//! buckets, independent after the copy, are sorted and summed by tasks of consecutive buckets,
//! each owning the global voxels of its key range and writing its own piece of the output; the
//! pieces are concatenated in key order. A voxel never spans two buckets and its points are
//! summed in input order, so the bits never depend on the number of threads. Coarse grids (the
//! cell table) run on one thread.
//!
//! # Memory
//! Input is taken in chunks of 2²¹ points; a chunk's voxels are merged in place into sorted
//! per-voxel sums (8-byte key, 4-byte count, f64 sums: 36 + 8·fields bytes per voxel), each
//! voxel continuing its sums in input order, so the result never depends on the chunking. Peak
//! memory besides input and output: about two chunks of points (≈ 110 MB each with seven f32
//! fields) plus the per-voxel sums — bounded by the number of occupied voxels, not the input.
//! (A [`VoxelGrid`] keeps the partition's copy from chunk to chunk; the parallel tasks' output
//! pieces hold at most one chunk's voxels until they are concatenated.)

use omni_formats::ply::{PointCloud, ScalarField};
use rayon::prelude::*;

/// Largest |voxel index| accepted on each axis (21 bits per axis, so a key packs into a u64).
pub const MAX_VOXEL_INDEX: i64 = (1 << 20) - 1;

/// Points buffered by a [`VoxelGrid`] before they are partitioned, sorted and merged into the
/// accumulators (≈ 110 MB with seven scalar fields, and as much again while partitioning).
const CHUNK_POINTS: usize = 1 << 21;

/// The grid: voxel edge (mm) and anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelSpec {
    size: f64,
    inv_size: f64,
    origin: [f64; 3],
}

impl VoxelSpec {
    /// A grid of cubes of edge `size` (mm) anchored at `origin` (mm).
    pub fn new(size: f64, origin: [f64; 3]) -> Result<Self, String> {
        if !(size.is_finite() && size > 0.0) {
            return Err(format!("voxel size must be a positive number, got {size}"));
        }
        if !origin.iter().all(|o| o.is_finite()) {
            return Err(format!("voxel grid origin must be finite, got {origin:?}"));
        }
        Ok(VoxelSpec { size, inv_size: 1.0 / size, origin })
    }

    /// Voxel edge (mm).
    pub fn size(&self) -> f64 {
        self.size
    }

    /// The (unchecked) voxel index of coordinate `v` on axis `a`, as ⌊(v − origin)/size⌋.
    /// Exact floor for |index| < 2⁶³ via truncation and a correction (no libm call).
    #[inline]
    fn axis_index(&self, a: usize, v: f64) -> i64 {
        let t = (v - self.origin[a]) * self.inv_size;
        let i = t as i64;
        i - ((t < i as f64) as i64)
    }

    /// The voxel index (i, j, k) of a point, or an error naming the point if it is not finite
    /// or more than [`MAX_VOXEL_INDEX`] voxels from the origin.
    #[inline]
    pub fn index(&self, p: &[f64; 3]) -> Result<[i64; 3], String> {
        let idx = [self.axis_index(0, p[0]), self.axis_index(1, p[1]), self.axis_index(2, p[2])];
        if !(p.iter().all(|c| c.is_finite()) && idx.iter().all(|i| i.abs() <= MAX_VOXEL_INDEX)) {
            return Err(self.out_of_range(p));
        }
        Ok(idx)
    }

    fn out_of_range(&self, p: &[f64; 3]) -> String {
        if p.iter().all(|c| c.is_finite()) {
            format!(
                "point ({}, {}, {}) is more than 2^20 voxels of {} mm from the grid origin",
                p[0], p[1], p[2], self.size
            )
        } else {
            format!("point ({}, {}, {}) is not finite", p[0], p[1], p[2])
        }
    }

    /// The 63-bit key of a voxel index: 21 bits per axis, offset to non-negative, i in the high
    /// bits, so keys sort like (i, j, k) tuples.
    #[inline]
    pub fn key_of_index(idx: [i64; 3]) -> u64 {
        idx.iter().fold(0u64, |key, &i| (key << 21) | (i + MAX_VOXEL_INDEX) as u64)
    }

    /// The 63-bit key of a point's voxel (see [`VoxelSpec::key_of_index`]).
    #[inline]
    pub fn key(&self, p: &[f64; 3]) -> Result<u64, String> {
        self.index(p).map(Self::key_of_index)
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

/// Point indices grouped by voxel: `order[ends[v-1]..ends[v]]` are the points of the v-th
/// occupied voxel in (i, j, k) order, ascending (= input order) within a voxel.
#[derive(Debug, Default)]
struct VoxelRuns {
    order: Vec<u32>,
    ends: Vec<u32>,
}

impl VoxelRuns {
    fn runs(&self) -> impl Iterator<Item = &[u32]> + '_ {
        let starts = std::iter::once(0).chain(self.ends.iter().copied());
        starts.zip(self.ends.iter().copied()).map(|(s, e)| &self.order[s as usize..e as usize])
    }
}

/// Number of bits needed to write `n` (0 for 0).
fn bit_width(n: u64) -> u32 {
    64 - n.leading_zeros()
}

/// A voxel index (i, j, k) relative to a box of voxels starting at `lo` with `extent` voxels
/// per axis, as the mixed-radix number ((i − lo_i)·n_j + (j − lo_j))·n_k + (k − lo_k), which
/// sorts like the (i, j, k) tuple and needs only as many bits as the box has voxels.
#[derive(Debug, Clone, Copy)]
struct BoxKey {
    spec: VoxelSpec,
    lo: [i64; 3],
    extent: [u64; 3],
    bits: u32,
}

impl BoxKey {
    /// The box of `positions`' voxels, checking every point (finite, within the index range;
    /// errors name the point as `first_index` + its position in the slice).
    fn of(spec: &VoxelSpec, positions: &[[f64; 3]], first_index: usize) -> Result<Self, String> {
        // The index is monotonic in the coordinate, so the extreme coordinates give the index
        // range exactly. A NaN escapes min/max, hence the explicit finiteness flag.
        // In parallel over blocks (min/max are exact, so the box does not depend on the split).
        let block = |pts: &[[f64; 3]]| {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            let mut finite = true;
            for p in pts {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                    finite &= p[a].is_finite();
                }
            }
            (lo, hi, finite)
        };
        let (lo, hi, finite) = positions.par_chunks(1 << 16).map(block).reduce(
            || block(&[]),
            |(l1, h1, f1), (l2, h2, f2)| {
                ([0, 1, 2].map(|a| l1[a].min(l2[a])), [0, 1, 2].map(|a| h1[a].max(h2[a])), f1 && f2)
            },
        );
        let (lo_idx, hi_idx) = match (finite, spec.index(&lo), spec.index(&hi)) {
            (true, Ok(l), Ok(h)) => (l, h),
            _ => {
                let bad = positions.iter().position(|p| spec.index(p).is_err()).unwrap_or(0);
                return Err(format!("point {}: {}", first_index + bad, spec.out_of_range(&positions[bad])));
            }
        };
        let extent = [0, 1, 2].map(|a| (hi_idx[a] - lo_idx[a] + 1) as u64);
        // ≤ 2^21 per axis, so the product fits in 63 bits.
        let bits = bit_width(extent[0] * extent[1] * extent[2] - 1);
        Ok(BoxKey { spec: *spec, lo: lo_idx, extent, bits })
    }

    /// The 63-bit key ([`VoxelSpec::key_of_index`]) of a point inside the box (checked when
    /// the box was made).
    #[inline]
    fn global_key(&self, p: &[f64; 3]) -> u64 {
        let s = &self.spec;
        VoxelSpec::key_of_index([s.axis_index(0, p[0]), s.axis_index(1, p[1]), s.axis_index(2, p[2])])
    }

    /// Number of voxels in the box.
    fn cells(&self) -> u64 {
        self.extent[0] * self.extent[1] * self.extent[2]
    }

    #[inline]
    fn key(&self, p: &[f64; 3]) -> u64 {
        let i = (self.spec.axis_index(0, p[0]) - self.lo[0]) as u64;
        let j = (self.spec.axis_index(1, p[1]) - self.lo[1]) as u64;
        let k = (self.spec.axis_index(2, p[2]) - self.lo[2]) as u64;
        (i * self.extent[1] + j) * self.extent[2] + k
    }
}

/// Indices 0..n grouped into runs of equal `key(i)` (each < 2^key_bits), runs in ascending key
/// order and indices ascending within a run. The key goes in the high bits of a u64 above the
/// index, radix sorted on the key bits only (LSD is stable, so indices stay ascending); if the
/// two do not fit 64 bits, (key, index) pairs are sorted as u128.
fn sort_by_key(n: usize, key_bits: u32, key: impl Fn(usize) -> u64) -> VoxelRuns {
    if n == 0 {
        return VoxelRuns::default();
    }
    let idx_bits = bit_width(n as u64 - 1).max(1);
    if key_bits + idx_bits <= 64 {
        let plan = RadixPlan::new(idx_bits, key_bits);
        let mut hist = vec![0u32; plan.passes.len() << plan.digit_bits];
        let mut words: Vec<u64> = Vec::with_capacity(n);
        for i in 0..n {
            let w = (key(i) << idx_bits) | i as u64;
            plan.count(w, &mut hist);
            words.push(w);
        }
        plan.sort(&mut words, &mut hist);
        runs_of_sorted(&words, idx_bits)
    } else {
        let mut pairs: Vec<u128> = (0..n).map(|i| ((key(i) as u128) << 32) | i as u128).collect();
        pairs.sort_unstable();
        runs_of_sorted(&pairs, 32)
    }
}

/// Splits sorted words `key << idx_bits | index` into runs of equal keys.
fn runs_of_sorted<W>(words: &[W], idx_bits: u32) -> VoxelRuns
where
    W: Copy + Into<u128>,
{
    let mask = (1u128 << idx_bits) - 1;
    let mut ends = Vec::new();
    let mut order = Vec::with_capacity(words.len());
    let mut prev_key = None;
    for (r, w) in words.iter().enumerate() {
        let w: u128 = (*w).into();
        let key = w >> idx_bits;
        if prev_key.is_some_and(|k| k != key) {
            ends.push(r as u32);
        }
        prev_key = Some(key);
        order.push((w & mask) as u32);
    }
    if !words.is_empty() {
        ends.push(words.len() as u32);
    }
    VoxelRuns { order, ends }
}

/// An LSD radix sort of u64 words on bits [shift, shift + bits), in passes of equal digits.
struct RadixPlan {
    digit_bits: u32,
    /// Bit offset of each pass's digit.
    passes: Vec<u32>,
}

impl RadixPlan {
    /// Widest digit: 2^10 buckets keep the scatter's write streams in L1.
    const MAX_DIGIT_BITS: u32 = 10;

    fn new(shift: u32, bits: u32) -> Self {
        let n_passes = bits.div_ceil(Self::MAX_DIGIT_BITS).max(1);
        let digit_bits = bits.div_ceil(n_passes).max(1);
        RadixPlan { digit_bits, passes: (0..n_passes).map(|p| shift + p * digit_bits).collect() }
    }

    #[inline]
    fn count(&self, w: u64, hist: &mut [u32]) {
        let mask = (1u64 << self.digit_bits) - 1;
        for (p, &s) in self.passes.iter().enumerate() {
            hist[(p << self.digit_bits) + ((w >> s) & mask) as usize] += 1;
        }
    }

    /// Sorts `words` (stable) given the digit histograms of all passes.
    fn sort(&self, words: &mut Vec<u64>, hist: &mut [u32]) {
        self.sort_with(words, &mut Vec::new(), hist)
    }

    /// [`RadixPlan::sort`] with a reusable scratch buffer.
    fn sort_with(&self, words: &mut Vec<u64>, scratch: &mut Vec<u64>, hist: &mut [u32]) {
        let n = words.len();
        let buckets = 1usize << self.digit_bits;
        let mask = (buckets - 1) as u64;
        scratch.resize(n, 0);
        for (p, &s) in self.passes.iter().enumerate() {
            let h = &mut hist[p * buckets..(p + 1) * buckets];
            if h.iter().any(|&c| c as usize == n) {
                continue; // every word has the same digit: nothing moves
            }
            let mut sum = 0u32;
            for c in h.iter_mut() {
                let here = *c;
                *c = sum;
                sum += here;
            }
            for &w in words.iter() {
                let d = ((w >> s) & mask) as usize;
                scratch[h[d] as usize] = w;
                h[d] += 1;
            }
            std::mem::swap(words, scratch);
        }
    }
}

/// Per-voxel running sums, voxels in ascending key order.
#[derive(Debug, Clone, Default)]
struct Accumulators {
    keys: Vec<u64>,
    counts: Vec<u32>,
    sums: Vec<[f64; 3]>,
    /// One sum per scalar field per voxel (row-major).
    scalar_sums: Vec<f64>,
}

impl Accumulators {
    fn len(&self) -> usize {
        self.keys.len()
    }

    /// The position of `key`, if present (keys are sorted).
    fn find(&self, key: u64) -> Option<usize> {
        self.keys.binary_search(&key).ok()
    }
}

/// Where finished voxels go, in ascending key order: either accumulators (more chunks to come)
/// or straight into the output cloud as means (the last chunk), which saves writing and
/// re-reading the accumulators.
trait VoxelSink: Send + Sync + Sized {
    fn push(&mut self, key: u64, count: u32, sums: &[f64; 3], scalar_sums: &[f64]);

    /// An empty sink of the same kind, for one parallel task's voxels.
    fn empty_piece(&self) -> Self;

    /// Appends the tasks' voxels (which follow this sink's, pieces in key order).
    fn append_all(&mut self, pieces: Vec<Self>);

    /// Whether the global voxels the chunk does not touch are wanted too (the full union).
    fn wants_untouched_global(&self) -> bool {
        true
    }
}

/// Collects only the chunk's voxels (their sums continuing the global ones), for
/// [`merge_in_place`].
struct ChunkVoxels(Accumulators);

impl VoxelSink for ChunkVoxels {
    #[inline]
    fn push(&mut self, key: u64, count: u32, sums: &[f64; 3], scalar_sums: &[f64]) {
        self.0.push(key, count, sums, scalar_sums)
    }

    fn empty_piece(&self) -> Self {
        ChunkVoxels(self.0.empty_piece())
    }

    fn append_all(&mut self, pieces: Vec<Self>) {
        self.0.append_all(pieces.into_iter().map(|p| p.0).collect())
    }

    fn wants_untouched_global(&self) -> bool {
        false
    }
}

/// Merges sorted `chunk` voxels into sorted `global` in place (from the back, so no second copy
/// of the accumulators is ever needed); a chunk voxel replaces the global one with its key.
fn merge_in_place(global: &mut Accumulators, chunk: Accumulators, ns: usize) {
    let (mut g, mut new) = (0, 0);
    for &k in &chunk.keys {
        while g < global.len() && global.keys[g] < k {
            g += 1;
        }
        new += usize::from(g == global.len() || global.keys[g] != k);
    }
    let old = global.len();
    let total = old + new;
    global.keys.resize(total, 0);
    global.counts.resize(total, 0);
    global.sums.resize(total, [0.0; 3]);
    global.scalar_sums.resize(total * ns, 0.0);
    let (mut i, mut j, mut w) = (old, chunk.len(), total);
    while j > 0 {
        w -= 1;
        if i > 0 && global.keys[i - 1] > chunk.keys[j - 1] {
            i -= 1;
            global.keys[w] = global.keys[i];
            global.counts[w] = global.counts[i];
            global.sums[w] = global.sums[i];
            global.scalar_sums.copy_within(i * ns..(i + 1) * ns, w * ns);
        } else {
            if i > 0 && global.keys[i - 1] == chunk.keys[j - 1] {
                i -= 1;
            }
            j -= 1;
            global.keys[w] = chunk.keys[j];
            global.counts[w] = chunk.counts[j];
            global.sums[w] = chunk.sums[j];
            global.scalar_sums[w * ns..(w + 1) * ns].copy_from_slice(&chunk.scalar_sums[j * ns..(j + 1) * ns]);
        }
    }
}

impl VoxelSink for Accumulators {
    #[inline]
    fn push(&mut self, key: u64, count: u32, sums: &[f64; 3], scalar_sums: &[f64]) {
        self.keys.push(key);
        self.counts.push(count);
        self.sums.push(*sums);
        self.scalar_sums.extend_from_slice(scalar_sums);
    }

    fn empty_piece(&self) -> Self {
        Accumulators::default()
    }

    fn append_all(&mut self, pieces: Vec<Self>) {
        par_append(&mut self.keys, &pieces.iter().map(|p| p.keys.as_slice()).collect::<Vec<_>>());
        par_append(&mut self.counts, &pieces.iter().map(|p| p.counts.as_slice()).collect::<Vec<_>>());
        par_append(&mut self.sums, &pieces.iter().map(|p| p.sums.as_slice()).collect::<Vec<_>>());
        par_append(&mut self.scalar_sums, &pieces.iter().map(|p| p.scalar_sums.as_slice()).collect::<Vec<_>>());
    }
}

impl VoxelSink for PointCloud {
    #[inline]
    fn push(&mut self, _key: u64, count: u32, sums: &[f64; 3], scalar_sums: &[f64]) {
        let n = count as f64;
        self.positions.push([sums[0] / n, sums[1] / n, sums[2] / n]);
        for (f, s) in self.scalars.iter_mut().zip(scalar_sums) {
            f.values.push((s / n) as f32);
        }
    }

    fn empty_piece(&self) -> Self {
        let scalars =
            self.scalars.iter().map(|f| ScalarField { name: f.name.clone(), values: Vec::new(), ty: f.ty }).collect();
        PointCloud { positions: Vec::new(), scalars }
    }

    fn append_all(&mut self, pieces: Vec<Self>) {
        par_append(&mut self.positions, &pieces.iter().map(|p| p.positions.as_slice()).collect::<Vec<_>>());
        for (f, field) in self.scalars.iter_mut().enumerate() {
            par_append(&mut field.values, &pieces.iter().map(|p| p.scalars[f].values.as_slice()).collect::<Vec<_>>());
        }
    }
}

/// Appends the pieces' elements to `dst` in order, each piece copied by its own task (the
/// copies, and the first touch of fresh output pages, run on all cores).
fn par_append<T: Copy + Send + Sync>(dst: &mut Vec<T>, pieces: &[&[T]]) {
    let total: usize = pieces.iter().map(|p| p.len()).sum();
    dst.reserve(total);
    let mut spare = &mut dst.spare_capacity_mut()[..total];
    let mut jobs = Vec::with_capacity(pieces.len());
    for piece in pieces {
        let (head, tail) = std::mem::take(&mut spare).split_at_mut(piece.len());
        jobs.push((head, *piece));
        spare = tail;
    }
    jobs.into_par_iter().for_each(|(d, s)| {
        for (d, s) in d.iter_mut().zip(s) {
            d.write(*s);
        }
    });
    let len = dst.len() + total;
    // SAFETY: the `total` slots after the old length were all initialised above (the jobs cover
    // them exactly: the pieces' lengths sum to `total`), and `reserve` made room for them.
    unsafe { dst.set_len(len) };
}

/// Points per bucket when a chunk is partitioned: a bucket's positions (384 kB) and sort buffers
/// stay in a core's 1 MB L2 cache (with seven scalar fields, 450 kB more: L2/L3). 2¹⁴ measured
/// 40 % faster than 2¹³ on positions only (fewer write streams in the copy).
const BUCKET_POINTS: usize = 1 << 14;

/// Voxel boxes of at most this many cells use a direct cell → voxel table (4 bytes per cell).
const DENSE_CELLS: u64 = 1 << 21;

/// Thresholds of [`accumulate_chunk`] (constants, lowered in tests to exercise every path).
#[derive(Debug, Clone, Copy)]
struct Tuning {
    /// Target points per bucket ([`BUCKET_POINTS`]).
    bucket_points: usize,
    /// Largest box summed through a cell table ([`DENSE_CELLS`]).
    dense_cells: u64,
}

/// One voxel being summed: starts from the matching global voxel, if any, so that its sums
/// continue in input order across chunks.
struct Running {
    count: u32,
    sums: [f64; 3],
    scalar_sums: Vec<f64>,
}

impl Running {
    fn start(&mut self, global: &Accumulators, prior: Option<usize>, ns: usize) {
        match prior {
            Some(g) => {
                self.count = global.counts[g];
                self.sums = global.sums[g];
                self.scalar_sums.copy_from_slice(&global.scalar_sums[g * ns..(g + 1) * ns]);
            }
            None => {
                self.count = 0;
                self.sums = [0.0; 3];
                self.scalar_sums.iter_mut().for_each(|s| *s = 0.0);
            }
        }
    }
}

/// Emits the global voxels with keys below `key` (all if None), advancing `cursor`, then
/// skips and returns the one equal to `key` (which the chunk's voxel continues).
#[inline]
fn emit_global_before(
    global: &Accumulators,
    cursor: &mut usize,
    key: Option<u64>,
    ns: usize,
    out: &mut impl VoxelSink,
) -> Option<usize> {
    let emit = out.wants_untouched_global();
    while *cursor < global.len() && key.is_none_or(|k| global.keys[*cursor] < k) {
        let g = *cursor;
        if emit {
            out.push(global.keys[g], global.counts[g], &global.sums[g], &global.scalar_sums[g * ns..(g + 1) * ns]);
        }
        *cursor += 1;
    }
    if let Some(k) = key
        && *cursor < global.len()
        && global.keys[*cursor] == k
    {
        *cursor += 1;
        return Some(*cursor - 1);
    }
    None
}

/// Adds a chunk of points to the sorted voxels `global` and writes the union, in key order, to
/// `out`.
///
/// Random access to anything larger than a cache is what makes voxel grids slow (on a VM with
/// 4 kB pages each miss also walks the page tables), so every pass is sequential or confined to
/// a cache-sized table:
/// * a box of ≤ [`DENSE_CELLS`] voxels (coarse grids): one pass summing each point into its
///   voxel found through a cell → voxel table, then the cells are walked in key order;
/// * otherwise: one pass counting key prefixes (top ≤ 16 bits), cut into buckets of
///   consecutive prefixes holding ≈ `bucket_points` points; one pass copying positions and
///   scalars into bucket order (stable: input order within a bucket); per bucket, keys radix
///   sorted (stable) and runs of equal keys summed.
fn accumulate_chunk(
    spec: &VoxelSpec,
    positions: &[[f64; 3]],
    fields: &[&[f32]],
    first_index: usize,
    global: &Accumulators,
    tuning: Tuning,
    buffers: &mut PartitionBuffers,
    out: &mut impl VoxelSink,
) -> Result<(), String> {
    let ns = fields.len();
    let mut cursor = 0;
    if !positions.is_empty() {
        let bk = BoxKey::of(spec, positions, first_index)?;
        if bk.cells() <= tuning.dense_cells {
            accumulate_dense(&bk, positions, fields, global, &mut cursor, out)?;
        } else {
            accumulate_partitioned(&bk, positions, fields, global, &mut cursor, tuning.bucket_points, buffers, out)?;
        }
    }
    emit_global_before(global, &mut cursor, None, ns, out);
    Ok(())
}

fn accumulate_dense(
    bk: &BoxKey,
    positions: &[[f64; 3]],
    fields: &[&[f32]],
    global: &Accumulators,
    cursor: &mut usize,
    out: &mut impl VoxelSink,
) -> Result<(), String> {
    const EMPTY: u32 = u32::MAX;
    let ns = fields.len();
    let mut slot_of_cell = vec![EMPTY; bk.cells() as usize];
    let mut local = Accumulators::default();
    for (i, p) in positions.iter().enumerate() {
        let cell = bk.key(p) as usize;
        let mut slot = slot_of_cell[cell];
        if slot == EMPTY {
            slot = local.len() as u32;
            slot_of_cell[cell] = slot;
            let key = bk.global_key(p);
            match global.find(key) {
                Some(g) => {
                    local.push(key, global.counts[g], &global.sums[g], &global.scalar_sums[g * ns..(g + 1) * ns])
                }
                None => {
                    local.push(key, 0, &[0.0; 3], &[]);
                    local.scalar_sums.resize(local.scalar_sums.len() + ns, 0.0);
                }
            }
        }
        let v = slot as usize;
        local.counts[v] += 1;
        let s = &mut local.sums[v];
        s[0] += p[0];
        s[1] += p[1];
        s[2] += p[2];
        for (acc, f) in local.scalar_sums[v * ns..(v + 1) * ns].iter_mut().zip(fields) {
            *acc += f[i] as f64;
        }
    }
    for &slot in slot_of_cell.iter().filter(|&&s| s != EMPTY) {
        let v = slot as usize;
        let key = local.keys[v];
        emit_global_before(global, cursor, Some(key), ns, out);
        out.push(key, local.counts[v], &local.sums[v], &local.scalar_sums[v * ns..(v + 1) * ns]);
    }
    Ok(())
}

/// Bounds of the input parts that are keyed, counted and scattered in parallel: about one part
/// per thread (at least [`MIN_PART_POINTS`] points each). The result never depends on the number
/// of parts (the scatter is stable: part p's points follow parts 0..p in every bucket).
fn part_bounds(n: usize) -> Vec<usize> {
    const MIN_PART_POINTS: usize = 1 << 15;
    let parts = rayon::current_num_threads().min(n.div_ceil(MIN_PART_POINTS)).max(1);
    (0..=parts).map(|p| p * n / parts).collect()
}

/// Splits `buf` into one slice per (part, bucket), `counts[p][b]` elements each, laid out bucket
/// by bucket and, inside a bucket, part by part; returned indexed `[p][b]`.
fn split_by_part_and_bucket<'a, T>(mut buf: &'a mut [T], counts: &[Vec<u32>]) -> Vec<Vec<&'a mut [T]>> {
    let buckets = counts.first().map_or(0, |c| c.len());
    let mut out: Vec<Vec<&mut [T]>> = counts.iter().map(|_| Vec::with_capacity(buckets)).collect();
    for b in 0..buckets {
        for (p, c) in counts.iter().enumerate() {
            let (head, tail) = std::mem::take(&mut buf).split_at_mut(c[b] as usize);
            out[p].push(head);
            buf = tail;
        }
    }
    out
}

/// Pops the first `k` elements of a destination slice (a bucket's remaining slots for one part).
#[inline]
fn next_slots<'a, T>(slots: &mut &'a mut [T], k: usize) -> &'a mut [T] {
    let (first, rest) = std::mem::take(slots).split_at_mut(k);
    *slots = rest;
    first
}

/// The partition's big arrays, kept by a [`VoxelGrid`] from chunk to chunk (no fresh pages to
/// fault in and zero for every chunk).
#[derive(Debug, Clone, Default)]
struct PartitionBuffers {
    positions: Vec<[f64; 3]>,
    scalars: Vec<f32>,
}

/// A chunk copied into bucket order: positions and scalars (interleaved, `ns` per point),
/// stable (input order within a bucket); bucket b holds `starts[b]..starts[b + 1]`.
struct Partition {
    positions: Vec<[f64; 3]>,
    scalars: Vec<f32>,
    ns: usize,
    starts: Vec<usize>,
    /// The smallest box key of each bucket's key range.
    first_keys: Vec<u64>,
}

/// Partitions a chunk into buckets of consecutive key prefixes (top ≤ 16 bits of the box key)
/// holding ≈ `bucket_points` points each, so bucket order is key order: per-part prefix
/// histograms, then a stable scatter, both in parallel over parts of the input. Keys are
/// recomputed rather than stored (measured: storing them costs more memory traffic than the
/// three float → int conversions it saves).
fn partition(
    bk: &BoxKey,
    positions: &[[f64; 3]],
    fields: &[&[f32]],
    bucket_points: usize,
    buffers: &mut PartitionBuffers,
) -> Partition {
    let n = positions.len();
    let ns = fields.len();
    let prefix_bits = bk.bits.min(16);
    let prefix_shift = bk.bits - prefix_bits;
    let bounds = part_bounds(n);
    let part_hists: Vec<Vec<u32>> = bounds
        .par_windows(2)
        .map(|w| {
            let mut hist = vec![0u32; 1 << prefix_bits];
            for p in &positions[w[0]..w[1]] {
                hist[(bk.key(p) >> prefix_shift) as usize] += 1;
            }
            hist
        })
        .collect();
    // Buckets of consecutive prefixes.
    let mut bucket_of = vec![0u32; 1 << prefix_bits];
    let mut starts = vec![0usize];
    let mut first_keys = vec![0u64];
    let (mut filled, mut total) = (0usize, 0usize);
    for q in 0..bucket_of.len() {
        if filled >= bucket_points {
            starts.push(total);
            first_keys.push((q as u64) << prefix_shift);
            filled = 0;
        }
        bucket_of[q] = (starts.len() - 1) as u32;
        let c: usize = part_hists.iter().map(|h| h[q] as usize).sum();
        filled += c;
        total += c;
    }
    starts.push(n);
    let counts: Vec<Vec<u32>> = part_hists
        .iter()
        .map(|h| {
            let mut c = vec![0u32; first_keys.len()];
            for (q, &x) in h.iter().enumerate() {
                c[bucket_of[q] as usize] += x;
            }
            c
        })
        .collect();
    let mut part = Partition {
        positions: std::mem::take(&mut buffers.positions),
        scalars: std::mem::take(&mut buffers.scalars),
        ns,
        starts,
        first_keys,
    };
    // Grown only (stale contents are overwritten before they are read).
    if part.positions.len() < n {
        part.positions.resize(n, [0.0; 3]);
    }
    if part.scalars.len() < n * ns {
        part.scalars.resize(n * ns, 0.0);
    }
    let pos_dst = split_by_part_and_bucket(&mut part.positions[..n], &counts);
    let scalar_counts: Vec<Vec<u32>> = counts.iter().map(|c| c.iter().map(|&x| x * ns as u32).collect()).collect();
    let sc_dst = split_by_part_and_bucket(&mut part.scalars[..n * ns], &scalar_counts);
    pos_dst.into_par_iter().zip(sc_dst).zip(bounds.par_windows(2)).for_each(|((mut pd, mut sd), w)| {
        for i in w[0]..w[1] {
            let p = &positions[i];
            let b = bucket_of[(bk.key(p) >> prefix_shift) as usize] as usize;
            next_slots(&mut pd[b], 1)[0] = *p;
            for (d, field) in next_slots(&mut sd[b], ns).iter_mut().zip(fields) {
                *d = field[i];
            }
        }
    });
    part
}

/// Global-key bound of the voxels that a task starting at box key `first_key` owns (the global
/// key of that cell; `u64::MAX`, above every key, if the cell lies outside the box).
fn task_bound(bk: &BoxKey, first_key: u64) -> u64 {
    if first_key >= bk.cells() {
        return u64::MAX;
    }
    let k = first_key % bk.extent[2];
    let ij = first_key / bk.extent[2];
    let (i, j) = (ij / bk.extent[1], ij % bk.extent[1]);
    VoxelSpec::key_of_index([i as i64 + bk.lo[0], j as i64 + bk.lo[1], k as i64 + bk.lo[2]])
}

/// Emits the global voxels with keys in [cursor's key, `bound`), advancing `cursor`.
fn emit_global_below(global: &Accumulators, cursor: &mut usize, bound: u64, ns: usize, out: &mut impl VoxelSink) {
    let end = *cursor + global.keys[*cursor..].partition_point(|&k| k < bound);
    if out.wants_untouched_global() {
        for g in *cursor..end {
            out.push(global.keys[g], global.counts[g], &global.sums[g], &global.scalar_sums[g * ns..(g + 1) * ns]);
        }
    }
    *cursor = end;
}

/// Partitions the chunk ([`partition`]), then sorts and sums its buckets in parallel: tasks of
/// consecutive buckets, each owning the global voxels of its key range, write their voxels to
/// their own sink, concatenated in key order. A voxel's points never span two buckets and are
/// summed in input order, so the bits do not depend on threads or tasks.
fn accumulate_partitioned<S: VoxelSink>(
    bk: &BoxKey,
    positions: &[[f64; 3]],
    fields: &[&[f32]],
    global: &Accumulators,
    cursor: &mut usize,
    bucket_points: usize,
    buffers: &mut PartitionBuffers,
    out: &mut S,
) -> Result<(), String> {
    let n = positions.len();
    let part = partition(bk, positions, fields, bucket_points, buffers);
    // Tasks of ≥ 1/8 of a thread's share of points each (load balance on a busy machine).
    let task_points = bucket_points.max(n / (8 * rayon::current_num_threads()));
    let mut task_starts = vec![0usize];
    for b in 1..part.first_keys.len() {
        let from = part.starts[task_starts[task_starts.len() - 1]];
        if part.starts[b] - from >= task_points {
            task_starts.push(b);
        }
    }
    task_starts.push(part.first_keys.len());
    let tasks: Vec<(usize, usize)> = task_starts.windows(2).map(|w| (w[0], w[1])).collect();
    let last = tasks.len() - 1;
    let pieces: Vec<S> = tasks
        .par_iter()
        .enumerate()
        .map(|(t, &(b0, b1))| {
            let mut piece = out.empty_piece();
            let lo = if t == 0 { 0 } else { task_bound(bk, part.first_keys[b0]) };
            let hi = if t == last { u64::MAX } else { task_bound(bk, part.first_keys[b1]) };
            let mut cur = global.keys.partition_point(|&k| k < lo);
            sum_buckets(bk, &part, b0..b1, global, &mut cur, &mut piece)?;
            emit_global_below(global, &mut cur, hi, fields.len(), &mut piece);
            Ok(piece)
        })
        .collect::<Result<_, String>>()?;
    out.append_all(pieces);
    (buffers.positions, buffers.scalars) = (part.positions, part.scalars);
    *cursor = global.len();
    Ok(())
}

/// Sorts each bucket of `buckets` on (key, index) and sums runs of equal keys into `out`.
fn sum_buckets(
    bk: &BoxKey,
    part: &Partition,
    buckets: std::ops::Range<usize>,
    global: &Accumulators,
    cursor: &mut usize,
    out: &mut impl VoxelSink,
) -> Result<(), String> {
    let ns = part.ns;
    let mut words: Vec<u64> = Vec::new();
    let mut scratch: Vec<u64> = Vec::new();
    let mut hist: Vec<u32> = Vec::new();
    let mut run = Running { count: 0, sums: [0.0; 3], scalar_sums: vec![0.0; ns] };
    for b in buckets {
        let (s, e) = (part.starts[b], part.starts[b + 1]);
        if s == e {
            continue;
        }
        let pos = &part.positions[s..e];
        let sc = &part.scalars[s * ns..e * ns];
        // The runs read the bucket's scalars in key order, i.e. at random: one sequential read
        // first (a value per 64-byte line) lets the hardware prefetcher bring them into L2.
        std::hint::black_box(sc.iter().step_by(16).fold(0.0f32, |a, &x| a + x));
        words.clear();
        words.extend(pos.iter().map(|p| bk.key(p)));
        let (kmin, kmax) = words.iter().fold((u64::MAX, 0), |(a, b), &k| (a.min(k), b.max(k)));
        let idx_bits = bit_width(pos.len() as u64 - 1).max(1);
        let key_bits = bit_width(kmax - kmin);
        if key_bits + idx_bits > 64 {
            // A huge sparse box: the general path (rare: > 2^40 voxels in one bucket's range).
            let runs = sort_by_key(pos.len(), key_bits, |j| words[j] - kmin);
            for r in runs.runs() {
                fold_run(bk, pos, sc, r.iter().map(|&j| j as usize), global, cursor, &mut run, out)?;
            }
            continue;
        }
        let plan = RadixPlan::new(idx_bits, key_bits);
        hist.clear();
        hist.resize(plan.passes.len() << plan.digit_bits, 0);
        for (j, w) in words.iter_mut().enumerate() {
            *w = ((*w - kmin) << idx_bits) | j as u64;
            plan.count(*w, &mut hist);
        }
        plan.sort_with(&mut words, &mut scratch, &mut hist);
        let mask = (1u64 << idx_bits) - 1;
        let mut r0 = 0;
        while r0 < words.len() {
            let key = words[r0] >> idx_bits;
            let mut r1 = r0 + 1;
            while r1 < words.len() && words[r1] >> idx_bits == key {
                r1 += 1;
            }
            let members = words[r0..r1].iter().map(|w| (w & mask) as usize);
            fold_run(bk, pos, sc, members, global, cursor, &mut run, out)?;
            r0 = r1;
        }
    }
    Ok(())
}

/// Sums one voxel's points `members` (indices into the bucket, in input order), continuing
/// the matching global voxel, and emits it after the global voxels that precede it.
#[inline]
fn fold_run(
    bk: &BoxKey,
    pos: &[[f64; 3]],
    sc: &[f32],
    members: impl Iterator<Item = usize> + Clone,
    global: &Accumulators,
    cursor: &mut usize,
    run: &mut Running,
    out: &mut impl VoxelSink,
) -> Result<(), String> {
    let ns = run.scalar_sums.len();
    let first = members.clone().next().unwrap_or(0);
    let key = bk.global_key(&pos[first]);
    let prior = emit_global_before(global, cursor, Some(key), ns, out);
    run.start(global, prior, ns);
    for j in members {
        let p = &pos[j];
        run.sums[0] += p[0];
        run.sums[1] += p[1];
        run.sums[2] += p[2];
        run.count += 1;
        for (a, x) in run.scalar_sums.iter_mut().zip(&sc[j * ns..(j + 1) * ns]) {
            *a += *x as f64;
        }
    }
    out.push(key, run.count, &run.sums, &run.scalar_sums);
    Ok(())
}

/// Voxel-grid downsampling of a whole cloud (module docs: Open3D's semantics, output in voxel
/// index order, f64 sums in input order), on all cores for fine grids (module docs: the bits do
/// not depend on the threads). The cloud is processed in chunks of
/// 2²¹ points (module docs, Memory); identical to feeding a [`VoxelGrid`].
pub fn voxel_downsample(cloud: &PointCloud, size: f64, origin: [f64; 3]) -> Result<PointCloud, String> {
    let grid = VoxelGrid::new(size, origin, cloud.scalars.iter().map(|s| s.name.clone()).collect())?;
    let mut out = grid.add_cloud_and_finish(cloud)?;
    for (o, s) in out.scalars.iter_mut().zip(&cloud.scalars) {
        o.ty = s.ty;
    }
    Ok(out)
}

/// A streaming voxel-grid accumulator (module docs for semantics and order): points go in one
/// at a time or a cloud at a time; memory is one chunk of points (2²¹) plus the occupied
/// voxels' sums (key, count, f64 sums), never the whole input. Each full chunk is summed
/// (`accumulate_chunk`) and merged in place into the sorted sums, each voxel's sums continuing
/// in input order, so the result does not depend on the chunking:
/// [`VoxelGrid::finish`] gives exactly the cloud [`voxel_downsample`] gives for the same points
/// in the same order.
#[derive(Debug, Clone)]
pub struct VoxelGrid {
    spec: VoxelSpec,
    scalar_names: Vec<String>,
    chunk_positions: Vec<[f64; 3]>,
    /// One buffer per scalar field.
    chunk_scalars: Vec<Vec<f32>>,
    /// Points per chunk ([`CHUNK_POINTS`]; smaller in tests).
    chunk_points: usize,
    tuning: Tuning,
    /// Points accumulated before the chunk buffer (to name points in errors).
    points_before_chunk: usize,
    acc: Accumulators,
    /// Boxed: kept small, the grid is an enum variant next to a cloud in `merge`.
    buffers: Box<PartitionBuffers>,
}

impl VoxelGrid {
    /// A grid of cubes of edge `size` (mm) anchored at `origin`, averaging the named scalars.
    pub fn new(size: f64, origin: [f64; 3], scalar_names: Vec<String>) -> Result<Self, String> {
        let spec = VoxelSpec::new(size, origin)?;
        let ns = scalar_names.len();
        Ok(VoxelGrid {
            spec,
            scalar_names,
            chunk_positions: Vec::new(),
            chunk_scalars: vec![Vec::new(); ns],
            chunk_points: CHUNK_POINTS,
            tuning: Tuning { bucket_points: BUCKET_POINTS, dense_cells: DENSE_CELLS },
            points_before_chunk: 0,
            acc: Accumulators::default(),
            buffers: Box::default(),
        })
    }

    /// Number of occupied voxels among the points accumulated so far, not counting points
    /// still buffered (exact after [`VoxelGrid::flush`]).
    pub fn len(&self) -> usize {
        self.acc.len()
    }

    pub fn is_empty(&self) -> bool {
        self.acc.len() == 0 && self.chunk_positions.is_empty()
    }

    /// Adds one point with its scalar values (same order as the grid's scalar names). Errors
    /// (non-finite point, too far from the origin) are reported here, before buffering.
    #[inline]
    pub fn add(&mut self, p: &[f64; 3], scalars: &[f32]) -> Result<(), String> {
        self.spec.index(p)?;
        if scalars.len() != self.chunk_scalars.len() {
            return Err(format!("{} scalar values for {} fields", scalars.len(), self.chunk_scalars.len()));
        }
        self.chunk_positions.push(*p);
        for (buf, v) in self.chunk_scalars.iter_mut().zip(scalars) {
            buf.push(*v);
        }
        if self.chunk_positions.len() >= self.chunk_points {
            self.flush()?;
        }
        Ok(())
    }

    /// The scalar fields of `cloud` in the grid's order (matched by name).
    fn fields_of<'a>(&self, cloud: &'a PointCloud) -> Result<Vec<&'a [f32]>, String> {
        self.scalar_names.iter().map(|n| cloud.scalar(n).ok_or_else(|| format!("missing scalar field {n}"))).collect()
    }

    /// Adds every point of a cloud whose scalar fields include the grid's (matched by name),
    /// straight from the cloud's arrays (no copy into the chunk buffer).
    pub fn add_cloud(&mut self, cloud: &PointCloud) -> Result<(), String> {
        let fields = self.fields_of(cloud)?;
        self.flush()?;
        for start in (0..cloud.positions.len()).step_by(self.chunk_points) {
            let end = (start + self.chunk_points).min(cloud.positions.len());
            self.accumulate(&cloud.positions[start..end], &fields.iter().map(|f| &f[start..end]).collect::<Vec<_>>())?;
        }
        Ok(())
    }

    /// [`VoxelGrid::add_cloud`] then [`VoxelGrid::finish`], with the last chunk's voxels going
    /// straight to the output.
    pub fn add_cloud_and_finish(mut self, cloud: &PointCloud) -> Result<PointCloud, String> {
        let fields = self.fields_of(cloud)?;
        self.flush()?;
        let n = cloud.positions.len();
        let last = n.saturating_sub(1) / self.chunk_points * self.chunk_points;
        for start in (0..last).step_by(self.chunk_points) {
            let end = start + self.chunk_points;
            self.accumulate(&cloud.positions[start..end], &fields.iter().map(|f| &f[start..end]).collect::<Vec<_>>())?;
        }
        let tail: Vec<&[f32]> = fields.iter().map(|f| &f[last..]).collect();
        self.finish_with(&cloud.positions[last..], &tail)
    }

    /// Sums a chunk into the accumulators.
    fn accumulate(&mut self, positions: &[[f64; 3]], fields: &[&[f32]]) -> Result<(), String> {
        // Capacity for the worst case (every point a new voxel): address space only, pages
        // are touched as voxels are written.
        let cap = positions.len();
        let ns = fields.len();
        let mut chunk = ChunkVoxels(Accumulators {
            keys: Vec::with_capacity(cap),
            counts: Vec::with_capacity(cap),
            sums: Vec::with_capacity(cap),
            scalar_sums: Vec::with_capacity(cap * ns),
        });
        let first = self.points_before_chunk;
        accumulate_chunk(&self.spec, positions, fields, first, &self.acc, self.tuning, &mut self.buffers, &mut chunk)?;
        self.points_before_chunk += positions.len();
        merge_in_place(&mut self.acc, chunk.0, ns);
        Ok(())
    }

    /// Accumulates the buffered points (done automatically when the buffer is full).
    pub fn flush(&mut self) -> Result<(), String> {
        if self.chunk_positions.is_empty() {
            return Ok(());
        }
        let positions = std::mem::take(&mut self.chunk_positions);
        let scalars = std::mem::take(&mut self.chunk_scalars);
        let fields: Vec<&[f32]> = scalars.iter().map(|f| f.as_slice()).collect();
        self.accumulate(&positions, &fields)?;
        self.chunk_positions = positions;
        self.chunk_positions.clear();
        self.chunk_scalars = scalars;
        for buf in &mut self.chunk_scalars {
            buf.clear();
        }
        Ok(())
    }

    /// The downsampled cloud: one centroid per voxel (scalars averaged), in voxel-index order.
    pub fn finish(mut self) -> Result<PointCloud, String> {
        let positions = std::mem::take(&mut self.chunk_positions);
        let scalars = std::mem::take(&mut self.chunk_scalars);
        let fields: Vec<&[f32]> = scalars.iter().map(|f| f.as_slice()).collect();
        self.finish_with(&positions, &fields)
    }

    /// Merges the last chunk with the accumulators straight into the output cloud.
    fn finish_with(mut self, positions: &[[f64; 3]], fields: &[&[f32]]) -> Result<PointCloud, String> {
        let cap = self.acc.len() + positions.len();
        let mut out = PointCloud {
            positions: Vec::with_capacity(cap),
            scalars: self
                .scalar_names
                .iter()
                .map(|name| ScalarField::new(name.clone(), Vec::with_capacity(cap)))
                .collect(),
        };
        let first = self.points_before_chunk;
        let mut buffers = std::mem::take(&mut self.buffers);
        accumulate_chunk(&self.spec, positions, fields, first, &self.acc, self.tuning, &mut buffers, &mut out)?;
        let (len, cap) = (out.positions.len(), out.positions.capacity());
        if cap > 2 * len + 1024 {
            out.positions.shrink_to_fit();
            out.scalars.iter_mut().for_each(|f| f.values.shrink_to_fit());
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use std::collections::BTreeMap;

    /// `n` points in a 60 × 40 × 30 mm box straddling the origin, with two scalar fields.
    fn random_cloud(n: usize, seed: u64) -> PointCloud {
        let mut rng = SplitMix64::new(seed);
        let positions: Vec<[f64; 3]> = (0..n)
            .map(|_| [rng.uniform() * 60.0 - 20.0, rng.uniform() * 40.0 - 35.0, rng.uniform() * 30.0 + 1.0])
            .collect();
        let a = (0..n).map(|_| (rng.uniform() * 1000.0) as f32).collect();
        let b = (0..n).map(|i| (i % 7) as f32 - 3.0).collect();
        PointCloud { positions, scalars: vec![ScalarField::new("a", a), ScalarField::new("b", b)] }
    }

    /// The definition written the obvious way: ⌊(p − o)/size⌋ by division, points grouped in
    /// an ordered map, centroids and means summed per voxel.
    fn brute_force(cloud: &PointCloud, size: f64, origin: [f64; 3]) -> (Vec<[i64; 3]>, PointCloud) {
        let mut groups: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
        for (i, p) in cloud.positions.iter().enumerate() {
            let v = [0, 1, 2].map(|a| ((p[a] - origin[a]) / size).floor() as i64);
            groups.entry(v).or_default().push(i);
        }
        let mean = |idx: &[usize], f: &dyn Fn(usize) -> f64| idx.iter().map(|&i| f(i)).sum::<f64>() / idx.len() as f64;
        let positions = groups.values().map(|g| [0, 1, 2].map(|a| mean(g, &|i| cloud.positions[i][a]))).collect();
        let scalars = cloud
            .scalars
            .iter()
            .map(|f| {
                ScalarField::new(
                    f.name.clone(),
                    groups.values().map(|g| mean(g, &|i| f.values[i] as f64) as f32).collect(),
                )
            })
            .collect();
        (groups.keys().copied().collect(), PointCloud { positions, scalars })
    }

    #[test]
    fn matches_the_brute_force_definition_exactly_in_count_order_and_centroids() {
        let cloud = random_cloud(5000, 1);
        let cases = [(4.0, [0.0; 3]), (2.5, [0.3, -1.7, 2.2]), (11.0, [-100.0, 50.0, 0.0])];
        // Both summing paths: the cell table (small boxes, the default here) and partitioning.
        let partitioned = Tuning { bucket_points: 200, dense_cells: 0 };
        for ((size, origin), tuning) in cases.iter().flat_map(|c| [(*c, None), (*c, Some(partitioned))]) {
            let (cells, expect) = brute_force(&cloud, size, origin);
            let mut grid = VoxelGrid::new(size, origin, vec!["a".into(), "b".into()]).unwrap();
            if let Some(t) = tuning {
                grid.tuning = t;
            }
            let out = grid.add_cloud_and_finish(&cloud).unwrap();
            assert_eq!(out.len(), expect.len(), "voxel count at {size} mm");
            assert!(out.len() > 50 && out.len() < cloud.len(), "{} voxels: a meaningful test", out.len());
            let spec = VoxelSpec::new(size, origin).unwrap();
            for (v, (p, e)) in out.positions.iter().zip(&expect.positions).enumerate() {
                // Same voxel, same order, centroid equal to rounding (sums of ≤ 100 values < 100 mm).
                assert_eq!(spec.index(p).unwrap(), cells[v], "voxel {v} at {size} mm");
                assert!((0..3).all(|a| (p[a] - e[a]).abs() < 1e-12), "voxel {v}: {p:?} vs {e:?}");
            }
            for (f, g) in out.scalars.iter().zip(&expect.scalars) {
                assert_eq!(f.name, g.name);
                for (x, y) in f.values.iter().zip(&g.values) {
                    assert!((x - y).abs() <= 1e-4 * y.abs().max(1.0), "{}: {x} vs {y}", f.name);
                }
            }
        }
    }

    #[test]
    fn hand_computed_centroids_with_negative_and_boundary_coordinates() {
        let cloud = PointCloud {
            positions: vec![
                [0.2, 0.2, 0.2],
                [0.4, 0.6, 0.8],
                [1.5, 0.5, 0.5],
                [-0.5, 0.5, 0.5],
                [1.7, 0.1, 0.3],
                [1.0, 0.0, -0.0], // exactly on a voxel corner: belongs to voxel (1, 0, 0)
            ],
            scalars: vec![ScalarField::new("intensity", vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0])],
        };
        let out = voxel_downsample(&cloud, 1.0, [0.0; 3]).unwrap();
        let expect = [[-0.5, 0.5, 0.5], [0.3, 0.4, 0.5], [4.2 / 3.0, 0.2, 0.8 / 3.0]];
        assert_eq!(out.len(), 3);
        for (p, e) in out.positions.iter().zip(expect) {
            assert!((0..3).all(|a| (p[a] - e[a]).abs() < 1e-12), "{p:?} vs {e:?}");
        }
        assert_eq!(out.scalar("intensity").unwrap(), &[40.0, 15.0, 140.0 / 3.0]);
    }

    #[test]
    fn output_is_deterministic_and_independent_of_input_order_and_chunking() {
        let cloud = random_cloud(20_000, 2);
        let a = voxel_downsample(&cloud, 3.0, [0.5, -0.25, 0.0]).unwrap();
        assert_eq!(a, voxel_downsample(&cloud, 3.0, [0.5, -0.25, 0.0]).unwrap(), "same input, same bits");
        // Streaming, in chunks of several sizes (one point, a prime, more than the cloud) and
        // point by point: identical bits, since each voxel is summed in input order everywhere.
        let names = vec!["a".to_string(), "b".to_string()];
        // Each with the cell-table path and with the partitioned path (tiny buckets).
        for chunk in [1, 997, 50_000] {
            for tuning in
                [Tuning { bucket_points: 64, dense_cells: 0 }, Tuning { bucket_points: 1, dense_cells: 1 << 30 }]
            {
                let mut grid = VoxelGrid::new(3.0, [0.5, -0.25, 0.0], names.clone()).unwrap();
                (grid.chunk_points, grid.tuning) = (chunk, tuning);
                grid.add_cloud(&cloud).unwrap();
                assert_eq!(grid.finish().unwrap(), a, "chunk {chunk}, {tuning:?}");
            }
        }
        for tuning in
            [Tuning { bucket_points: 100, dense_cells: 0 }, Tuning { bucket_points: 100, dense_cells: 1 << 30 }]
        {
            let mut grid = VoxelGrid::new(3.0, [0.5, -0.25, 0.0], names.clone()).unwrap();
            (grid.chunk_points, grid.tuning) = (3000, tuning);
            assert_eq!(grid.add_cloud_and_finish(&cloud).unwrap(), a, "{tuning:?}");
        }
        let mut grid = VoxelGrid::new(3.0, [0.5, -0.25, 0.0], names).unwrap();
        grid.chunk_points = 4096;
        for (i, p) in cloud.positions.iter().enumerate() {
            grid.add(p, &[cloud.scalars[0].values[i], cloud.scalars[1].values[i]]).unwrap();
        }
        assert_eq!(grid.finish().unwrap(), a);
        // Reversed input: the same voxels in the same order, centroids equal to rounding.
        let mut rev = cloud.clone();
        rev.positions.reverse();
        rev.scalars.iter_mut().for_each(|f| f.values.reverse());
        let b = voxel_downsample(&rev, 3.0, [0.5, -0.25, 0.0]).unwrap();
        assert_eq!(a.len(), b.len());
        for (p, q) in a.positions.iter().zip(&b.positions) {
            assert!((0..3).all(|k| (p[k] - q[k]).abs() < 1e-12), "{p:?} vs {q:?}");
        }
        // Voxel-index order: keys strictly increasing.
        let spec = VoxelSpec::new(3.0, [0.5, -0.25, 0.0]).unwrap();
        let keys: Vec<u64> = a.positions.iter().map(|p| spec.key(p).unwrap()).collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn parallel_partition_gives_the_same_bits_for_any_thread_count_and_chunking() {
        // 150 000 points: several input parts (≥ 2^15 points each) and many bucket tasks.
        let cloud = random_cloud(150_000, 4);
        let names = vec!["a".to_string(), "b".to_string()];
        let (size, origin) = (0.5, [0.1, 0.2, -0.3]);
        let run = |cloud: &PointCloud, chunk: usize, tuning: Tuning, threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut grid = VoxelGrid::new(size, origin, names.clone()).unwrap();
                (grid.chunk_points, grid.tuning) = (chunk, tuning);
                grid.add_cloud_and_finish(cloud).unwrap()
            })
        };
        // Reference: the sequential cell-table path, one chunk.
        let dense = Tuning { bucket_points: 1, dense_cells: 1 << 30 };
        let partitioned = Tuning { bucket_points: 512, dense_cells: 0 };
        let reference = run(&cloud, 1 << 21, dense, 1);
        assert!(reference.len() > 100_000, "{} voxels: mostly single points at 0.5 mm", reference.len());
        for threads in [1, 2, 3] {
            assert_eq!(run(&cloud, 1 << 21, partitioned, threads), reference, "{threads} threads");
        }
        // Sorted along x (from 60 % of the cloud up, then from the bottom) and streamed in chunks:
        // each chunk's box is a slab, so the sums carried between chunks hold voxels outside the
        // box on both sides, which the tasks must emit once each, in key order.
        let mut order: Vec<usize> = (0..cloud.len()).collect();
        order.sort_by(|&i, &j| cloud.positions[i][0].total_cmp(&cloud.positions[j][0]).then(i.cmp(&j)));
        order.rotate_left(90_000);
        let sorted = crate::filter::gather(&cloud, &order);
        let reference = run(&sorted, 1 << 21, dense, 1);
        for (chunk, threads) in [(20_000, 2), (33_333, 3), (70_000, 1)] {
            assert_eq!(run(&sorted, chunk, partitioned, threads), reference, "chunk {chunk}, {threads} threads");
        }
    }

    #[test]
    fn key_order_of_a_huge_sparse_box_uses_the_wide_sort() {
        // Points 2^20 voxels apart on every axis: the relative key needs ~63 bits, so the
        // (key, index) pairs no longer fit a u64 and the u128 path sorts them.
        let far = 0.999 * MAX_VOXEL_INDEX as f64;
        let cloud = PointCloud {
            positions: vec![[far, far, far], [-far, far, -far], [far, -far, far], [-far, -far, -far], [far, far, far]],
            scalars: vec![ScalarField::new("s", vec![1.0, 2.0, 3.0, 4.0, 5.0])],
        };
        let out = voxel_downsample(&cloud, 1.0, [0.0; 3]).unwrap();
        let (cells, expect) = brute_force(&cloud, 1.0, [0.0; 3]);
        assert_eq!(out, expect);
        assert_eq!(cells.len(), 4);
        let mut grid = VoxelGrid::new(1.0, [0.0; 3], vec!["s".into()]).unwrap();
        grid.add_cloud(&cloud).unwrap();
        assert_eq!(grid.finish().unwrap(), out);
    }

    #[test]
    fn bad_sizes_and_points_are_errors_naming_the_point() {
        let mut cloud = random_cloud(10, 3);
        assert!(voxel_downsample(&cloud, 0.0, [0.0; 3]).is_err());
        assert!(voxel_downsample(&cloud, f64::NAN, [0.0; 3]).is_err());
        // 1e-9 mm voxels put these points ~10^10 voxels from the origin.
        let e = voxel_downsample(&cloud, 1e-9, [0.0; 3]).unwrap_err();
        assert!(e.contains("2^20 voxels"), "{e}");
        cloud.positions[7][1] = f64::NAN;
        let e = voxel_downsample(&cloud, 1.0, [0.0; 3]).unwrap_err();
        assert!(e.starts_with("point 7:") && e.contains("not finite"), "{e}");
        let mut grid = VoxelGrid::new(1.0, [0.0; 3], vec!["a".into(), "b".into()]).unwrap();
        let e = grid.add_cloud(&cloud).unwrap_err();
        assert!(e.starts_with("point 7:"), "{e}");
        assert!(grid.add(&[0.0, f64::INFINITY, 0.0], &[0.0, 0.0]).is_err());
        assert!(grid.add(&[0.0; 3], &[0.0]).is_err(), "wrong number of scalars");
        let empty = voxel_downsample(&PointCloud { positions: vec![], scalars: vec![] }, 1.0, [0.0; 3]).unwrap();
        assert!(empty.is_empty());
    }

    #[test]
    fn open3d_origin_is_the_min_bound_minus_half_a_voxel() {
        let pts = [[1.0, -2.0, 3.0], [-4.0, 5.0, 6.0]];
        assert_eq!(voxel_origin_open3d(&pts, 2.0), [-5.0, -3.0, 2.0]);
        assert_eq!(voxel_origin_open3d(&[], 2.0), [0.0; 3]);
    }
}
