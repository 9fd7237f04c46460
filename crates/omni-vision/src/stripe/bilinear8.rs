//! Bilinear samples on 8-bit frames in SSE2, four at a time: along a line, and the cross of
//! four samples around a point.
//!
//! The coarse profiles (1-px steps along every marked stretch of a ray: about 37 000 samples
//! per frame of the ridge benchmark's room) are the detector's most numerous samples. Here the
//! four samples of a step share their arithmetic: one `pmaddwd` weighs the horizontal pairs of
//! all four, in both rows, and the vertical blend is four-wide. Measured on the room frame: 4 %
//! less time per frame than one sample at a time, although the instructions per sample rose
//! from 47 to 57 (callgrind). Reading the pixels without bounds checks (the line's two ends bound it)
//! saved another 0.8 M instructions per frame but no measurable time, so the checks stay.
//!
//! Exactly the values of `lerp_q8`: with 8-bit pixels and 1/256 fractions the row sums are
//! integers below 2¹⁶ and the final sums below 2²⁴, so the float products and sums here are
//! exact.

/// Writes to `out[k]` the bilinear sample at (x, y) = (`xf`, `yf`) + k·`step` in 32.32 fixed
/// point (non-negative), whose 2×2 neighbourhoods in `data` (`w` pixels per row) must all be
/// inside (else it panics on a slice index).
#[target_feature(enable = "sse2")]
#[inline]
pub(super) fn bilinear_line_sse2(data: &[u8], w: usize, xf: i64, yf: i64, step: (i64, i64), out: &mut [f32]) {
    use std::arch::x86_64::*;
    let mut at = (xf, yf);
    let mut chunks = out.chunks_exact_mut(4);
    for chunk in &mut chunks {
        // Four samples' horizontal pairs of pixels (top rows, then bottom rows), x weights
        // (`(256 − fx) | fx << 16`: two 16-bit lanes) and y fractions.
        let (mut pairs, mut wx, mut fy) = ([0u8; 16], [0i32; 4], [0i32; 4]);
        for j in 0..4 {
            let s = Sample::at(data, w, at);
            at = (at.0 + step.0, at.1 + step.1);
            pairs[2 * j..2 * j + 2].copy_from_slice(&s.top);
            pairs[8 + 2 * j..8 + 2 * j + 2].copy_from_slice(&s.bottom);
            (wx[j], fy[j]) = (s.wx, s.fy);
        }
        // SAFETY: the loads read 16 bytes from 16-byte arrays; unaligned loads.
        let (pairs, wx, fy) = unsafe {
            (
                _mm_loadu_si128(pairs.as_ptr().cast()),
                _mm_loadu_si128(wx.as_ptr().cast()),
                _mm_cvtepi32_ps(_mm_loadu_si128(fy.as_ptr().cast())),
            )
        };
        let zero = _mm_setzero_si128();
        let top = _mm_cvtepi32_ps(_mm_madd_epi16(_mm_unpacklo_epi8(pairs, zero), wx));
        let bottom = _mm_cvtepi32_ps(_mm_madd_epi16(_mm_unpackhi_epi8(pairs, zero), wx));
        let sum = _mm_add_ps(_mm_mul_ps(top, _mm_sub_ps(_mm_set1_ps(256.0), fy)), _mm_mul_ps(bottom, fy));
        let mut values = [0.0f32; 4];
        // SAFETY: `values` is 16 writable bytes; the store has no alignment requirement.
        unsafe { _mm_storeu_ps(values.as_mut_ptr(), _mm_mul_ps(sum, _mm_set1_ps(1.0 / 65536.0))) };
        chunk.copy_from_slice(&values);
    }
    for v in chunks.into_remainder() {
        let s = Sample::at(data, w, at);
        at = (at.0 + step.0, at.1 + step.1);
        let row = |[left, right]: [u8; 2]| (i32::from(left) * (s.wx & 0xFFFF) + i32::from(right) * (s.wx >> 16)) as f32;
        *v = (row(s.top) * (256 - s.fy) as f32 + row(s.bottom) * s.fy as f32) * (1.0 / 65536.0);
    }
}

/// One bilinear sample's inputs: its top and bottom pairs of pixels, its x weights
/// `(256 − fx) | fx << 16` and its y fraction `fy` (fractions in 1/256 px).
struct Sample {
    top: [u8; 2],
    bottom: [u8; 2],
    wx: i32,
    fy: i32,
}

impl Sample {
    /// The sample at `(x, y)` (32.32 fixed point) in `data`, `w` pixels per row.
    #[inline(always)]
    fn at(data: &[u8], w: usize, (x, y): (i64, i64)) -> Sample {
        let ((xi, fx), (yi, fy)) = (super::split_fixed(x), super::split_fixed(y));
        let i = yi * w + xi;
        let (top, bottom) = (&data[i..i + 2], &data[i + w..i + w + 2]);
        Sample {
            top: [top[0], top[1]],
            bottom: [bottom[0], bottom[1]],
            wx: ((256 - fx) | fx << 16) as i32,
            fy: fy as i32,
        }
    }
}

/// `Frame::cross` on 8-bit pixels in SSE2: the bilinear samples 1 px left, right, above and
/// below a point, whose 2×2 cells in the 4×4 `block` (rows `w` apart, from the pixel up and left
/// of the point's) share the fractions `fx`, `fy` (1/256 px). The eight horizontal pairs of the
/// four cells are weighed in one `pmaddwd`, as in [`bilinear_line_sse2`]; the same values as
/// `lerp_q8` to the last bit.
#[target_feature(enable = "sse2")]
#[inline]
pub(super) fn cross_sse2(block: &[u8], w: usize, fx: u32, fy: u32) -> [f32; 4] {
    use std::arch::x86_64::*;
    let pair = |row: usize, col: usize| {
        let i = row * w + col;
        i16::from_le_bytes([block[i], block[i + 1]])
    };
    // Cells (top-left pixel): left (1, 0), right (1, 2), up (0, 1), down (2, 1); their top
    // pairs in lanes 0–3, their bottom pairs in lanes 4–7.
    let pairs =
        _mm_set_epi16(pair(3, 1), pair(1, 1), pair(2, 2), pair(2, 0), pair(2, 1), pair(0, 1), pair(1, 2), pair(1, 0));
    let zero = _mm_setzero_si128();
    let wx = _mm_set1_epi32(((256 - fx) | fx << 16) as i32);
    let top = _mm_cvtepi32_ps(_mm_madd_epi16(_mm_unpacklo_epi8(pairs, zero), wx));
    let bottom = _mm_cvtepi32_ps(_mm_madd_epi16(_mm_unpackhi_epi8(pairs, zero), wx));
    let fy = _mm_set1_ps(fy as f32);
    let sum = _mm_add_ps(_mm_mul_ps(top, _mm_sub_ps(_mm_set1_ps(256.0), fy)), _mm_mul_ps(bottom, fy));
    let mut values = [0.0f32; 4];
    // SAFETY: `values` is 16 writable bytes; the store has no alignment requirement.
    unsafe { _mm_storeu_ps(values.as_mut_ptr(), _mm_mul_ps(sum, _mm_set1_ps(1.0 / 65536.0))) };
    values
}

#[cfg(test)]
mod tests {
    use super::super::{Frame, Pixel, to_fixed};

    /// The SSE2 line equals the one-sample-at-a-time interpolation bit for bit: lines in every
    /// direction, at every length around the 4-sample steps, on pixels covering 0–255.
    #[test]
    fn sse2_line_matches_single_samples() {
        let (w, h) = (40u32, 30u32);
        let data: Vec<u8> = (0..w * h).map(|i| ((i * 97 + i / 7) % 256) as u8).collect();
        let frame = Frame { width: w, height: h, data: &data, max_value: 255.0 };
        for (k, angle) in (0..24).map(|k| (k, k as f64 * 0.2618 + 0.01)) {
            let dir = (angle.cos(), angle.sin());
            let (cx, cy) = (19.7 + 0.01 * k as f64, 14.3);
            let n = 3 + k % 8;
            let mut fast = vec![0.0f32; n];
            assert!(u8::bilinear_line_fast(
                &data,
                w as usize,
                to_fixed(cx + 2.0 * dir.0),
                to_fixed(cy + 2.0 * dir.1),
                (to_fixed(dir.0), to_fixed(dir.1)),
                &mut fast,
            ));
            let single: Vec<f32> = (0..n)
                .map(|i| {
                    let r = 2.0 + i as f64;
                    frame.bilinear(cx + r * dir.0, cy + r * dir.1).unwrap()
                })
                .collect();
            assert_eq!(fast, single, "angle {angle}");
        }
    }

    /// The SSE2 cross equals four single bilinear samples bit for bit.
    #[test]
    fn sse2_cross_matches_single_samples() {
        let (w, h) = (9u32, 7u32);
        let data: Vec<u8> = (0..w * h).map(|i| ((i * 97 + i / 5) % 256) as u8).collect();
        let frame = Frame { width: w, height: h, data: &data, max_value: 255.0 };
        for k in 0..200 {
            let (x, y) = (1.0 + (k as f64 * 0.037) % 5.99, 1.0 + (k as f64 * 0.053) % 3.99);
            let cross = frame.cross(x, y).unwrap();
            let single =
                [(x - 1.0, y), (x + 1.0, y), (x, y - 1.0), (x, y + 1.0)].map(|(x, y)| frame.bilinear(x, y).unwrap());
            assert_eq!(cross, single, "({x}, {y})");
        }
    }
}
