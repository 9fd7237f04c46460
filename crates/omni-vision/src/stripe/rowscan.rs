//! The row scan's test over a row: which pixels stand out from their neighbours.
//!
//! The scan runs over every pixel of the annulus (0.8 MP on a 1024 × 1024 frame), so its cost
//! per pixel matters even on a frame full of stripes. The generic form, a branch-free pass over
//! each 64-pixel block to see whether it holds a hit and a scalar pass over the blocks that do,
//! takes about three instructions per pixel of the ridge benchmark's frames (callgrind); the
//! SSE2 form for 8-bit frames about one. The AVX2 form (on CPUs that have it, detected at run
//! time) tests 32 pixels per instruction instead of 16: the plane frame, where the scan is most
//! of the work, took 5 % less time (0.219 → 0.208 ms/MP).

use super::Pixel;

/// Calls `hit(i)` for each pixel `c[i]` brighter by more than `t` than both `l[i]` and `r[i]`
/// or than both `u[i]` and `d[i]` (its row and column neighbours), in increasing `i`: the
/// generic form of [`Pixel::for_each_contrast_hit`]. All slices are as long as `c`.
#[inline(always)]
pub(super) fn for_each_hit_generic<P: Pixel>(
    c: &[P],
    l: &[P],
    r: &[P],
    u: &[P],
    d: &[P],
    t: P,
    mut hit: impl FnMut(usize),
) {
    const BLOCK: usize = 64;
    let blocks = c.chunks(BLOCK).zip(l.chunks(BLOCK)).zip(r.chunks(BLOCK));
    let blocks = blocks.zip(u.chunks(BLOCK)).zip(d.chunks(BLOCK));
    for (bi, ((((c, l), r), u), d)) in blocks.enumerate() {
        let lanes = || c.iter().zip(l).zip(r).zip(u).zip(d);
        // One pass without branches over the block; most blocks hold no stripe.
        let any = lanes().fold(false, |any, ((((&v, &l), &r), &u), &d)| any | P::contrast_above(v, l, r, u, d, t));
        if !any {
            continue;
        }
        for (i, ((((&v, &l), &r), &u), &d)) in lanes().enumerate() {
            if P::contrast_above(v, l, r, u, d, t) {
                hit(bi * BLOCK + i);
            }
        }
    }
}

/// The pixels of one 64-pixel step of the five rows (`[centre, left, right, up, down]`).
#[cfg(target_arch = "x86_64")]
type Step<'a> = [&'a [u8; STEP]; 5];

/// Pixels per step of the SIMD forms (the hits of a step fit a `u64`).
#[cfg(target_arch = "x86_64")]
const STEP: usize = 64;

/// The frame of the SIMD forms: `step_hits` gives each 64-pixel step's hits as a bit mask (bit i
/// for pixel i of the step), `hit` is called for each; a row shorter than a step takes the
/// generic test.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn for_each_step_hit(rows: [&[u8]; 5], t: u8, mut step_hits: impl FnMut(Step) -> u64, mut hit: impl FnMut(usize)) {
    let [c, l, r, u, d] = rows;
    let len = c.len();
    if len < STEP {
        for_each_hit_generic(c, l, r, u, d, t, hit);
        return;
    }
    let steps = c.chunks_exact(STEP).zip(l.chunks_exact(STEP)).zip(r.chunks_exact(STEP));
    let steps = steps.zip(u.chunks_exact(STEP)).zip(d.chunks_exact(STEP));
    let mut done = 0;
    let mut report = |mut hits: u64, first: usize| {
        while hits != 0 {
            hit(first + hits.trailing_zeros() as usize);
            hits &= hits - 1;
        }
    };
    for ((((c, l), r), u), d) in steps {
        let step = [c, l, r, u, d].map(|s| <&[u8; STEP]>::try_from(s).expect("a whole step"));
        report(step_hits(step), done);
        done += STEP;
    }
    if done == len {
        return;
    }
    // The last partial step as the whole step that ends with the row, its pixels before `done`
    // (already reported) shifted out, instead of a scalar pass over up to 63 pixels.
    let start = len - STEP;
    let step = [c, l, r, u, d].map(|s| <&[u8; STEP]>::try_from(&s[start..]).expect("a whole step"));
    report(step_hits(step) >> (done - start), done);
}

/// [`for_each_hit_generic`] for 8-bit pixels in SSE2 (part of every x86-64 CPU), 64 pixels per
/// step: `v > max(a, b) ⊕ t` (saturating addition, as `u8::contrast_above`) is
/// `v ⊖ (max(a, b) ⊕ t) ≠ 0` (saturating subtraction: SSE2 has no unsigned byte comparison).
/// The four 16-pixel results of a step are tested together (most steps hold no hit).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
#[inline]
pub(super) fn for_each_hit_sse2(c: &[u8], l: &[u8], r: &[u8], u: &[u8], d: &[u8], t: u8, hit: impl FnMut(usize)) {
    use std::arch::x86_64::*;
    let (tv, zero) = (_mm_set1_epi8(t as i8), _mm_setzero_si128());
    let step_hits = |[c, l, r, u, d]: Step| {
        let load = |s: &[u8; STEP], k: usize| {
            let bytes: &[u8; 16] = s[16 * k..16 * k + 16].try_into().expect("16 pixels");
            // SAFETY: `bytes` is 16 readable bytes; the load has no alignment requirement.
            unsafe { _mm_loadu_si128(bytes.as_ptr().cast()) }
        };
        let above = |k: usize| {
            let v = load(c, k);
            let row = _mm_adds_epu8(_mm_max_epu8(load(l, k), load(r, k)), tv);
            let col = _mm_adds_epu8(_mm_max_epu8(load(u, k), load(d, k)), tv);
            _mm_or_si128(_mm_subs_epu8(v, row), _mm_subs_epu8(v, col))
        };
        let quarters = [above(0), above(1), above(2), above(3)];
        let any = _mm_or_si128(_mm_or_si128(quarters[0], quarters[1]), _mm_or_si128(quarters[2], quarters[3]));
        if _mm_movemask_epi8(_mm_cmpeq_epi8(any, zero)) == 0xFFFF {
            return 0;
        }
        quarters.iter().enumerate().fold(0u64, |mask, (k, &q)| {
            let hits = !(_mm_movemask_epi8(_mm_cmpeq_epi8(q, zero)) as u32) & 0xFFFF;
            mask | (hits as u64) << (16 * k)
        })
    };
    for_each_step_hit([c, l, r, u, d], t, step_hits, hit);
}

/// [`for_each_hit_sse2`] with 32-pixel AVX2 vectors (the same operations, twice as wide).
///
/// # Safety
/// The CPU must support AVX2 (`is_x86_feature_detected!("avx2")`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn for_each_hit_avx2(
    c: &[u8],
    l: &[u8],
    r: &[u8],
    u: &[u8],
    d: &[u8],
    t: u8,
    hit: impl FnMut(usize),
) {
    use std::arch::x86_64::*;
    let (tv, zero) = (_mm256_set1_epi8(t as i8), _mm256_setzero_si256());
    let step_hits = |[c, l, r, u, d]: Step| {
        let load = |s: &[u8; STEP], k: usize| {
            let bytes: &[u8; 32] = s[32 * k..32 * k + 32].try_into().expect("32 pixels");
            // SAFETY: `bytes` is 32 readable bytes; the load has no alignment requirement.
            unsafe { _mm256_loadu_si256(bytes.as_ptr().cast()) }
        };
        let above = |k: usize| {
            let v = load(c, k);
            let row = _mm256_adds_epu8(_mm256_max_epu8(load(l, k), load(r, k)), tv);
            let col = _mm256_adds_epu8(_mm256_max_epu8(load(u, k), load(d, k)), tv);
            _mm256_or_si256(_mm256_subs_epu8(v, row), _mm256_subs_epu8(v, col))
        };
        let halves = [above(0), above(1)];
        if _mm256_movemask_epi8(_mm256_cmpeq_epi8(_mm256_or_si256(halves[0], halves[1]), zero)) == -1 {
            return 0;
        }
        let hits = |h| !(_mm256_movemask_epi8(_mm256_cmpeq_epi8(h, zero)) as u32) as u64;
        hits(halves[0]) | hits(halves[1]) << 32
    };
    for_each_step_hit([c, l, r, u, d], t, step_hits, hit);
}
