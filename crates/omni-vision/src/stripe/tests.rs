//! Synthetic frames with analytic stripes (known centres) and noise; errors are measured along
//! the sampling ray, as the distance from the detected point to the true centreline.

use super::*;
use omni_geom::Vector2;
use omni_geom::rng::SplitMix64;

/// Renders `intensity(x, y)` averaged over 4×4 points inside each pixel (a camera integrates
/// over the pixel), plus Gaussian noise of `noise` DN, rounded and clipped to the bit depth.
pub(super) fn render(
    w: u32,
    h: u32,
    bit_depth: u8,
    noise: f64,
    seed: u64,
    intensity: impl Fn(f64, f64) -> f64,
) -> GrayImage {
    let mut img = GrayImage::new(w, h, bit_depth);
    let max = img.max_value() as f64;
    let mut rng = SplitMix64::new(seed);
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for j in 0..4 {
                for i in 0..4 {
                    s += intensity(x as f64 - 0.375 + 0.25 * i as f64, y as f64 - 0.375 + 0.25 * j as f64);
                }
            }
            let v = s / 16.0 + noise * rng.normal();
            img.data[(y * w + x) as usize] = v.round().clamp(0.0, max) as u16;
        }
    }
    img
}

fn gaussian_line(d: f64, sigma: f64, peak: f64) -> f64 {
    peak * (-d * d / (2.0 * sigma * sigma)).exp()
}

const W: u32 = 240;
const H: u32 = 232;
/// Mirror centre deliberately off the image centre and off the pixel grid.
const CX: f64 = 121.3;
const CY: f64 = 114.6;

fn circle() -> MirrorCircle {
    MirrorCircle { centre: Vector2::new(CX, CY), inner_radius: 20.0, outer_radius: 110.0 }
}

fn detector(method: Method) -> RidgeDetector {
    RidgeDetector::new(W, H, circle(), RidgeParams { method, sampling: Sampling::Rays, ..Default::default() })
}

/// Polar angle (rad, [0, 2π)) and radius (px) of a point about the mirror centre.
fn polar(p: &StripePoint) -> (f64, f64) {
    let (dx, dy) = (p.u - CX, p.v - CY);
    (dy.atan2(dx).rem_euclid(TAU), dx.hypot(dy))
}

/// RMS and mean of the errors.
fn rms_bias(errors: &[f64]) -> (f64, f64) {
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    (rms, mean)
}

/// A ring of radius ρc(φ) = 60 + 8·sin(3φ): a closed curve that crosses the rays obliquely
/// (up to 22°). The perpendicular distance to it is ≈ (ρ − ρc)·cos γ with tan γ = ρc'/ρc.
fn wavy_radius(phi: f64) -> f64 {
    60.0 + 8.0 * (3.0 * phi).sin()
}

fn wavy_frame(peak: f64, noise: f64, seed: u64) -> GrayImage {
    render(W, H, 8, noise, seed, |x, y| {
        let (dx, dy) = (x - CX, y - CY);
        let phi = dy.atan2(dx);
        let rc = wavy_radius(phi);
        let slope = 24.0 * (3.0 * phi).cos() / rc;
        let d = (dx.hypot(dy) - rc) / (1.0 + slope * slope).sqrt();
        gaussian_line(d, 1.4, peak)
    })
}

fn wavy_errors(points: &[StripePoint]) -> Vec<f64> {
    points
        .iter()
        .map(|p| {
            let (phi, r) = polar(p);
            r - wavy_radius(phi)
        })
        .collect()
}

#[test]
fn ring_every_estimator_meets_its_accuracy_with_noise() {
    let img = render(W, H, 8, 2.0, 1, |x, y| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.5, 180.0));
    for method in Method::ALL {
        let pts = detector(method).detect(&img);
        // One point per ray crossing the ring.
        assert!(pts.len() as f64 > 0.97 * detector(method).ray_count() as f64, "{method:?}: {} points", pts.len());
        let errs: Vec<f64> = pts.iter().map(|p| polar(p).1 - 70.0).collect();
        let (rms, bias) = rms_bias(&errs);
        eprintln!("ring σ=1.5 peak=180 noise=2: {:<12} rms {rms:.4} px, bias {bias:+.4} px", method.name());
        let (rms_max, bias_max) = if method == Method::Centroid { (0.12, 0.05) } else { (0.05, 0.02) };
        assert!(rms <= rms_max && bias.abs() <= bias_max, "{method:?}: rms {rms} bias {bias}");
    }
}

#[test]
fn oblique_wavy_stripe_is_measured_along_the_ray() {
    let img = wavy_frame(160.0, 2.0, 2);
    for method in Method::ALL {
        let pts = detector(method).detect(&img);
        let (rms, bias) = rms_bias(&wavy_errors(&pts));
        eprintln!("wavy ring: {:<12} rms {rms:.4} px, bias {bias:+.4} px, {} points", method.name(), pts.len());
        let rms_max = if method == Method::Centroid { 0.15 } else { 0.06 };
        assert!(rms <= rms_max && bias.abs() <= 0.03, "{method:?}: rms {rms} bias {bias}");
        assert!(pts.len() > 600, "{method:?}: {} points", pts.len());
    }
}

#[test]
fn accuracy_is_uniform_around_the_image() {
    // A ring (constant curvature), so that only the stripe's orientation to the pixel grid
    // changes with azimuth.
    let img = render(W, H, 8, 2.0, 3, |x, y| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.0, 160.0));
    let pts = detector(Method::Gauss).detect(&img);
    let errs: Vec<f64> = pts.iter().map(|p| polar(p).1 - 70.0).collect();
    let (overall, _) = rms_bias(&errs);
    let mut worst: f64 = 0.0;
    for sector in 0..12 {
        let sel: Vec<f64> = pts
            .iter()
            .zip(&errs)
            .filter(|(p, _)| (polar(p).0 / (TAU / 12.0)) as usize == sector)
            .map(|(_, &e)| e)
            .collect();
        assert!(sel.len() > 30, "sector {sector}: {} points", sel.len());
        worst = worst.max(rms_bias(&sel).0);
    }
    eprintln!("30° sectors: overall rms {overall:.4} px, worst sector {worst:.4} px");
    assert!(worst <= 1.5 * overall, "worst {worst} overall {overall}");
}

#[test]
fn straight_stripe_across_the_annulus_is_found_where_rays_cross_it() {
    // The line n·(x − C) = 60 px with n at 30° (a chord, crossing the rays at up to 60°).
    let (nx, ny) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let c = CX * nx + CY * ny + 60.0;
    let img = render(W, H, 8, 2.0, 4, |x, y| gaussian_line(x * nx + y * ny - c, 1.3, 200.0));
    let pts = detector(Method::Gauss).detect(&img);
    let errs: Vec<f64> = pts
        .iter()
        .map(|p| {
            // Distance along the ray from the point to the line: signed distance / cos(angle).
            let (dx, dy) = ((p.u - CX), (p.v - CY));
            let r = dx.hypot(dy);
            let cos = (dx * nx + dy * ny) / r;
            (p.u * nx + p.v * ny - c) / cos
        })
        .collect();
    let (rms, bias) = rms_bias(&errs);
    eprintln!("straight chord: rms {rms:.4} px, bias {bias:+.4} px, {} points", pts.len());
    // The chord spans 2·acos(60/110) = 114° of azimuth: about 218 rays.
    assert!(pts.len() > 200, "{} points", pts.len());
    assert!(rms <= 0.06 && bias.abs() <= 0.02, "rms {rms} bias {bias}");
}

#[test]
fn two_stripes_on_one_ray_are_both_reported() {
    let img = render(W, H, 8, 2.0, 5, |x, y| {
        let r = (x - CX).hypot(y - CY);
        gaussian_line(r - 45.0, 1.4, 150.0) + gaussian_line(r - 90.0, 1.4, 150.0)
    });
    let det = detector(Method::Windowed);
    let pts = det.detect(&img);
    let inner = pts.iter().filter(|p| (polar(p).1 - 45.0).abs() < 0.2).count();
    let outer = pts.iter().filter(|p| (polar(p).1 - 90.0).abs() < 0.2).count();
    // One point per sampled ray: every second ray at r = 45 px (< r_out / 2), every ray at 90.
    assert_eq!((det.ray_step(45.0), det.ray_step(90.0)), (2, 1));
    assert!(inner as f64 > 0.97 * det.ray_count() as f64 / 2.0, "inner {inner}");
    assert!(outer as f64 > 0.97 * det.ray_count() as f64, "outer {outer}");
    assert_eq!(inner + outer, pts.len(), "no point away from the two rings");
}

#[test]
fn saturated_stripe_is_located_at_the_plateau_centre() {
    let img = render(W, H, 8, 2.0, 6, |x, y| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.6, 1200.0));
    for method in Method::ALL {
        let pts = detector(method).detect(&img);
        assert!(pts.iter().all(|p| p.quality & quality::SATURATED != 0));
        let (rms, bias) = rms_bias(&pts.iter().map(|p| polar(p).1 - 70.0).collect::<Vec<_>>());
        eprintln!("saturated ring: {:<12} rms {rms:.4} px, bias {bias:+.4} px", method.name());
        assert!(rms <= 0.1 && bias.abs() <= 0.03, "{method:?}: rms {rms} bias {bias}");
    }
}

#[test]
fn weak_stripe_is_found_and_flagged() {
    let img = render(W, H, 8, 2.0, 7, |x, y| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.5, 60.0));
    let params =
        RidgeParams { method: Method::Gauss, threshold: Some(20.0), sampling: Sampling::Rays, ..Default::default() };
    let det = RidgeDetector::new(W, H, circle(), params);
    let pts = det.detect(&img);
    let (rms, bias) = rms_bias(&pts.iter().map(|p| polar(p).1 - 70.0).collect::<Vec<_>>());
    eprintln!("weak ring (peak 60): rms {rms:.4} px, bias {bias:+.4} px, {} points", pts.len());
    assert!(pts.len() as f64 > 0.97 * det.ray_count() as f64);
    assert!(rms <= 0.1 && bias.abs() <= 0.03, "rms {rms} bias {bias}");
    assert!(pts.iter().all(|p| p.quality & quality::WEAK != 0));
}

#[test]
fn glints_noise_and_pixels_outside_the_annulus_are_rejected() {
    let img = render(W, H, 8, 3.0, 8, |x, y| {
        let r = (x - CX).hypot(y - CY);
        // A wide specular glint (disc of radius 15 px), a ring inside the blind centre and
        // one beyond the rim.
        let glint = if (x - 150.0).hypot(y - 150.0) < 15.0 { 250.0 } else { 0.0 };
        glint + gaussian_line(r - 12.0, 1.5, 200.0) + gaussian_line(r - 114.0, 1.5, 200.0)
    });
    let mut img = img;
    // Isolated hot pixels.
    for k in 0..40 {
        let (x, y) = (30 + (k * 37) % 180, 30 + (k * 53) % 170);
        img.data[y * W as usize + x] = 255;
    }
    let pts = detector(Method::Windowed).detect(&img);
    assert!(pts.is_empty(), "{} false points, first {:?}", pts.len(), pts.first());
}

#[test]
fn sixteen_bit_frames_give_the_same_centres() {
    let f = |x: f64, y: f64| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.5, 180.0);
    let img8 = render(W, H, 8, 0.0, 9, f);
    let img16 = render(W, H, 16, 0.0, 9, |x, y| 257.0 * f(x, y));
    let det = detector(Method::Gauss);
    let (a, b) = (det.detect(&img8), det.detect(&img16));
    assert!((a.len() as i64 - b.len() as i64).abs() <= 2, "{} vs {}", a.len(), b.len());
    let (ra, _) = rms_bias(&a.iter().map(|p| polar(p).1 - 70.0).collect::<Vec<_>>());
    let (rb, _) = rms_bias(&b.iter().map(|p| polar(p).1 - 70.0).collect::<Vec<_>>());
    assert!(ra < 0.02 && rb < 0.02, "8-bit {ra}, 16-bit {rb}");
    // 16-bit intensities are in 16-bit units.
    assert!(b.iter().all(|p| p.intensity > 255.0));
}

#[test]
fn u8_and_u16_buffers_agree_exactly() {
    let img = render(W, H, 8, 2.0, 10, |x, y| gaussian_line((x - CX).hypot(y - CY) - 70.0, 1.5, 180.0));
    let bytes = img.to_u8();
    let det = detector(Method::Windowed);
    let f8 = Frame { width: W, height: H, data: &bytes, max_value: 255.0 };
    let a = det.detect_frame(&f8, &mut Scratch::default());
    assert_eq!(a, det.detect(&img));
}

#[test]
fn fast_atan2_is_accurate() {
    for i in 0..3600 {
        let a = i as f64 * TAU / 3600.0 + 1e-3;
        let (s, c) = a.sin_cos();
        let got = fast_atan2(3.0 * s, 3.0 * c);
        let d = (got - a.rem_euclid(TAU) + TAU / 2.0).rem_euclid(TAU) - TAU / 2.0;
        assert!(d.abs() < 2e-5, "angle {a}: {got}");
    }
}

#[test]
fn methods_parse_from_their_names() {
    for m in Method::ALL {
        assert_eq!(m.name().parse::<Method>().unwrap(), m);
    }
    assert!("median".parse::<Method>().unwrap_err().contains("blais-rioux"));
}

#[test]
fn fast_candidate_test_matches_the_general_one() {
    let mut rng = SplitMix64::new(77);
    let (w, h) = (40u32, 30u32);
    let data: Vec<u8> = (0..w * h).map(|_| (rng.uniform() * 60.0) as u8).collect();
    let f = Frame { width: w, height: h, data: &data, max_value: 255.0 };
    for threshold in [10.0, 10.5, 25.0] {
        let t = u8::from_threshold(threshold);
        let k = 7usize;
        for y in k..h as usize - k {
            for x in k..w as usize - k {
                let at = |xx: usize, yy: usize| data[yy * w as usize + xx];
                let fast = u8::contrast_above(at(x, y), at(x - k, y), at(x + k, y), at(x, y - k), at(x, y + k), t);
                assert_eq!(fast, stands_out(&f, x, y, k, threshold as f32), "({x}, {y}) T {threshold}");
            }
        }
    }
}

#[test]
fn row_tests_flag_exactly_the_pixels_the_single_test_flags() {
    // Every row length up to 140 (the SIMD paths' 64-pixel steps and their overlapped last
    // step; the generic path's 64-pixel blocks), thresholds at and near the saturating cases,
    // pixels near 255.
    let mut rng = SplitMix64::new(78);
    let mut bytes = |n: usize| -> Vec<u8> { (0..n).map(|_| (rng.uniform() * 256.0) as u8).collect() };
    for n in 0..=140 {
        let [c, l, r, u, d] = [bytes(n), bytes(n), bytes(n), bytes(n), bytes(n)];
        for t in [0u8, 1, 10, 100, 255] {
            let single: Vec<usize> = (0..n).filter(|&i| u8::contrast_above(c[i], l[i], r[i], u[i], d[i], t)).collect();
            let mut hits = Vec::new();
            u8::for_each_contrast_hit(&c, &l, &r, &u, &d, t, |i| hits.push(i));
            assert_eq!(hits, single, "8-bit, {n} px, T {t}");
            // Each x86-64 form, whichever the CPU running the test gets from the trait.
            #[cfg(target_arch = "x86_64")]
            {
                hits.clear();
                // SAFETY: SSE2 is part of the x86-64 baseline.
                unsafe { super::rowscan::for_each_hit_sse2(&c, &l, &r, &u, &d, t, |i| hits.push(i)) };
                assert_eq!(hits, single, "8-bit SSE2, {n} px, T {t}");
                if std::arch::is_x86_feature_detected!("avx2") {
                    hits.clear();
                    // SAFETY: the CPU has AVX2 (checked).
                    unsafe { super::rowscan::for_each_hit_avx2(&c, &l, &r, &u, &d, t, |i| hits.push(i)) };
                    assert_eq!(hits, single, "8-bit AVX2, {n} px, T {t}");
                }
            }
            let wide = |v: &[u8]| v.iter().map(|&x| x as u16 * 257).collect::<Vec<u16>>();
            let [c, l, r, u, d] = [wide(&c), wide(&l), wide(&r), wide(&u), wide(&d)];
            let t = t as u16 * 257;
            let single: Vec<usize> = (0..n).filter(|&i| u16::contrast_above(c[i], l[i], r[i], u[i], d[i], t)).collect();
            let mut hits = Vec::new();
            u16::for_each_contrast_hit(&c, &l, &r, &u, &d, t, |i| hits.push(i));
            assert_eq!(hits, single, "16-bit, {n} px");
        }
    }
}

#[test]
fn fast_helpers_agree_with_the_plain_arithmetic() {
    for &x in &[-3.5, -2.0, -0.25, 0.0, 0.2, 1.0, 7.999_999_999, 12.5, 511.75, 1e6 + 0.3] {
        assert_eq!(floor_i64(x), x.floor() as i64, "floor {x}");
        assert_eq!(-floor_i64(-x), x.ceil() as i64, "ceil {x}");
        if x >= 0.0 {
            let (i, f) = fixed_point(x);
            assert_eq!(i, x.floor() as usize, "integer part {x}");
            assert_eq!(f, ((x - x.floor()) * 256.0).floor() as u32, "fraction {x} in 1/256: {f}");
        }
    }
    // The cross of four samples equals four bilinear samples; None where one leaves the image.
    let (w, h) = (9u32, 7u32);
    let data: Vec<u8> = (0..w * h).map(|i| ((i * 37) % 251) as u8).collect();
    let f = Frame { width: w, height: h, data: &data, max_value: 255.0 };
    for &(x, y) in &[(3.3, 2.7), (1.0, 1.0), (6.99, 4.5), (4.0, 4.999)] {
        let cross = f.cross(x, y).unwrap();
        let plain = [f.bilinear(x - 1.0, y), f.bilinear(x + 1.0, y), f.bilinear(x, y - 1.0), f.bilinear(x, y + 1.0)];
        for (a, b) in cross.iter().zip(plain) {
            assert!((a - b.unwrap()).abs() < 1e-4, "({x}, {y}): {cross:?}");
        }
    }
    for &(x, y) in &[(0.9, 3.0), (7.0, 3.0), (3.0, 0.5), (3.0, 5.0)] {
        assert!(f.cross(x, y).is_none(), "({x}, {y})");
    }
    // A line of bilinear samples equals the samples one by one.
    let mut line = Vec::new();
    f.bilinear_line(4.2, 3.1, -2.0, (0.6, 0.8), 5, &mut line);
    for (k, v) in line.iter().enumerate() {
        let r = -2.0 + k as f64;
        assert!((v - f.bilinear(4.2 + 0.6 * r, 3.1 + 0.8 * r).unwrap()).abs() < 1e-4);
    }
    // sin(MIN_EDGE_ANGLE_DEG) is the constant edge_faces_ray uses.
    assert!((MIN_EDGE_ANGLE_DEG.to_radians().sin() - 0.5).abs() < 1e-12);
}

/// What happens as a stripe turns towards the radial direction: a chord at 25 px from the
/// mirror centre meets the rays at every angle β between its direction and the ray's (β = 90°
/// at its closest point, sin β = 25 / r, down to 13° at the rim). The detector samples along
/// the rays only (not along the stripe's gradient): a point's error along its ray is its
/// perpendicular error / sin β, and the segment along the ray widens as 1 / sin β. Where the
/// gradient at the stripe's edges makes more than 90° − [`MIN_EDGE_ANGLE_DEG`] = 60° with the
/// ray (β < 30°) the ray is skipped: a nearly radial stripe is not measured rather than measured
/// badly. Measured (noise 2 DN, σ 1.2 px, peak 180): β 60–90° every ray, rms along the ray
/// 0.007–0.017 px; 40–60° every ray, 0.012–0.028 px; 30–40° about 60 % of the rays,
/// 0.017–0.021 px; below 30° none.
#[test]
fn nearly_radial_stripes_are_measured_down_to_thirty_degrees_and_skipped_below() {
    use std::f64::consts::{FRAC_PI_2, PI};
    let d = 25.0;
    let (nx, ny) = (200f64.to_radians().cos(), 200f64.to_radians().sin());
    let c = CX * nx + CY * ny + d;
    let img = render(W, H, 8, 2.0, 9, |x, y| gaussian_line(x * nx + y * ny - c, 1.2, 180.0));
    // β bins (degrees) and the arc of chord in each, to count the rays crossing it.
    let bins = [(13.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 60.0), (60.0, 90.0)];
    for method in [Method::Centroid, Method::Gauss, Method::Hessian] {
        let det = detector(method);
        let pts = det.detect(&img);
        let mut rows = Vec::new();
        for &(lo, hi) in &bins {
            let (mut along, mut perp, mut n) = (0.0, 0.0, 0usize);
            for p in &pts {
                let (dx, dy) = (p.u - CX, p.v - CY);
                let r = dx.hypot(dy);
                let beta = (d / r).clamp(-1.0, 1.0).asin().to_degrees();
                if beta < lo || beta >= hi {
                    continue;
                }
                let dist = p.u * nx + p.v * ny - c;
                perp += dist * dist;
                along += (dist / (d / r)).powi(2);
                n += 1;
            }
            // Rays sampling the chord with β in the bin: ray φ meets it at r = d / cos(φ − φn)
            // with β = 90° − |φ − φn|, if it samples that radius (every ray_step(r)-th ray).
            let rays = (0..det.ray_count())
                .filter(|&i| {
                    let phi = TAU * i as f64 / det.ray_count() as f64;
                    let delta = (phi - 200f64.to_radians() + PI).rem_euclid(TAU) - PI;
                    let (beta, r) = (90.0 - delta.abs().to_degrees(), d / delta.cos());
                    delta.abs() < FRAC_PI_2
                        && (lo..hi).contains(&beta)
                        && (20.0..=110.0).contains(&r)
                        && i % det.ray_step(r) == 0
                })
                .count() as f64;
            let rms_along = (along / n.max(1) as f64).sqrt();
            let rms_perp = (perp / n.max(1) as f64).sqrt();
            eprintln!(
                "radial-ish chord {:<9} β {lo:>2}–{hi:<2}°: {n:>3} points of ≈ {rays:>5.1} rays, rms along ray {rms_along:.4} px, perpendicular {rms_perp:.4} px",
                method.name()
            );
            rows.push((lo, n, rays, rms_along));
        }
        for (lo, n, rays, rms_along) in rows {
            if lo >= 30.0 {
                // Measured wherever the stripe crosses the rays at ≤ 60° from perpendicular:
                // every ray from β = 40° on, most of them between 30° and 40° (the edge test
                // is a hard cut at 30°, reached earlier by noisy edges).
                let coverage = if lo >= 40.0 { 0.9 } else { 0.4 };
                assert!(n as f64 >= coverage * rays, "{method:?} β ≥ {lo}°: {n} of {rays:.0} rays");
                assert!(rms_along <= 0.1, "{method:?} β ≥ {lo}°: rms {rms_along}");
            } else {
                // Nearly radial: skipped, not measured badly.
                assert!(n as f64 <= 0.1 * rays, "{method:?} β < 30°: {n} of {rays:.0} rays");
            }
        }
    }
}

/// A ring stripe (σ 1.2 px, 150 DN) on a lit surface (40 DN) whose silhouette runs `gap` px
/// inside it (nothing but 0 DN beyond): the points found and their radial errors (px).
fn stripe_beside_a_silhouette(gap: f64) -> (usize, Vec<f64>) {
    const R: f64 = 60.0;
    let img = render(W, H, 8, 1.0, 9, |x, y| {
        let r = (x - CX).hypot(y - CY);
        if r < R - gap { 0.0 } else { 40.0 + gaussian_line(r - R, 1.2, 150.0) }
    });
    let pts = detector(Method::Windowed).detect(&img);
    let errors = pts.iter().map(|p| polar(p).1 - R).collect();
    (pts.len(), errors)
}

#[test]
fn stripes_cut_by_a_silhouette_are_rejected_and_whole_ones_kept() {
    // The silhouette 1.2 px (1σ) inside the stripe cuts its inner flank: its centre moves
    // outwards; the sides' backgrounds (0 and 40 DN) differ by 0.27 of the contrast. (With the
    // former MAX_BACKGROUND_STEP of 0.5: 452 points reported, 0.45 px outwards.)
    let (cut, cut_errors) = stripe_beside_a_silhouette(1.2);
    let first_cut = &cut_errors[..cut_errors.len().min(3)];
    // The silhouette 7 px inside: within the background windows (max_width / 2 + 2 = 8 px), the
    // stripe whole and clear of it (STEP_CLEARANCE_PX); 14 px inside: beyond the windows.
    for gap in [7.0, 14.0] {
        let (whole, errors) = stripe_beside_a_silhouette(gap);
        let (rms, bias) = rms_bias(&errors);
        eprintln!(
            "silhouette {gap} px inside: {whole} points, rms {rms:.4}, bias {bias:+.4}; cut: {cut} {first_cut:?}"
        );
        assert!(whole > 300, "gap {gap} px: {whole} points on the whole stripe");
        assert!(rms <= 0.05 && bias.abs() <= 0.02, "gap {gap} px: rms {rms} bias {bias}");
        assert!(cut * 100 <= whole, "cut stripe: {cut} points reported (whole: {whole})");
    }
}

/// The real laser's profile as measured (docs/DECISIONS.md), drawn by [`lopsided_ring`].
fn lopsided() -> omni_model::LaserProfile {
    omni_model::LaserProfile::tailed(0.17, 4.0)
}
/// The lens's blur (px) and the ring's radius (px) of [`lopsided_ring`].
const LOPSIDED_BLUR_PX: f64 = 0.7;
const LOPSIDED_RADIUS_PX: f64 = 70.0;

/// A ring of the lopsided laser's stripe (its tail outwards, 4 px wide behind the lens) on a
/// surface whose 30° sectors alternate between peaks of `dim` and `bright` levels above
/// `background` (8 bits: clipped at 255), with 1 level of noise.
fn lopsided_ring(dim: f64, bright: f64, background: f64) -> GrayImage {
    let (profile, blur) = (lopsided(), LOPSIDED_BLUR_PX);
    let core = 4.0 / profile.fwhm();
    let s = (1.0 + blur * blur / (core * core)).sqrt();
    let peak = (0..2000).map(|k| profile.unit(-5.0 + k as f64 * 0.01, s)).fold(0.0, f64::max);
    render(W, H, 8, 1.0, 12, |x, y| {
        let (dx, dy) = (x - CX, y - CY);
        let sector = (dy.atan2(dx).rem_euclid(TAU) / 30f64.to_radians()) as usize;
        let amplitude = if sector.is_multiple_of(2) { dim } else { bright };
        let d = dx.hypot(dy) - LOPSIDED_RADIUS_PX;
        background + amplitude * profile.unit((d + profile.mode() * core) / core, s) / peak
    })
}

/// A ring whose laser is lopsided (the real profile's tail outwards, 4 px wide behind a 0.7 px
/// lens) and whose surface alternates every 30° between dim (peak 150 DN) and bright sectors
/// clipped 1.6, 3.3, 8 and 12 times over: the clipped plateaus' edges are read far down the
/// profile, where the tail pulls their midpoint outwards (+0.11, +0.26, +0.78, +1.6 px). With
/// the profile known, the dim sectors' widths give the sheet's width and the plateaus' edges
/// their depth, and the clipped points come back to the sheet's peak (+0.004, −0.004, −0.003,
/// −0.006 px; RMS 0.009, 0.009, 0.026, 0.020 px; points within 2 px of a sector's edge, where
/// the surface changes under the profile, left out). At 12 times over the clipped points 2–3 px
/// from a sector's edge have too few dim profiles within reach on this tight ring, and take
/// their clipped neighbours' offsets.
#[test]
fn a_known_laser_profile_leads_clipped_lopsided_plateaus_to_the_sheets_peak() {
    for (bright, background) in [(400.0, 20.0), (850.0, 20.0), (2000.0, 20.0), (3000.0, 20.0)] {
        let img = lopsided_ring(150.0, bright, background);
        let bias = |laser_profile| {
            let params = RidgeParams { optics_blur_px: Some(LOPSIDED_BLUR_PX), laser_profile, ..Default::default() };
            let pts = RidgeDetector::new(W, H, circle(), params).detect(&img);
            // Away from the sectors' edges, where the surface changes under the profile.
            let sector = 30f64.to_radians();
            let inside = |p: &&StripePoint| {
                let phase = polar(p).0.rem_euclid(sector);
                phase.min(sector - phase) * LOPSIDED_RADIUS_PX > 2.0
            };
            let (clipped, dim): (Vec<_>, Vec<_>) =
                pts.iter().filter(inside).partition(|p| p.quality & quality::SATURATED != 0);
            let errors = |pts: &[&StripePoint]| pts.iter().map(|p| polar(p).1 - LOPSIDED_RADIUS_PX).collect::<Vec<_>>();
            let ((rc, bc), (rd, bd)) = (rms_bias(&errors(&clipped)), rms_bias(&errors(&dim)));
            eprintln!(
                "bright {bright}, profile {}: clipped {} points rms {rc:.4} bias {bc:+.4} px, dim {} points rms {rd:.4} bias {bd:+.4} px",
                laser_profile.is_some(),
                clipped.len(),
                dim.len()
            );
            assert!(clipped.len() > 150 && dim.len() > 150, "{} clipped, {} dim", clipped.len(), dim.len());
            (bc, bd, rc)
        };
        let (clipped, _, _) = bias(None);
        assert!(clipped > 0.1, "bright {bright}: the tail pulls clipped plateaus outwards: {clipped} px");
        let (clipped, dim, rms) = bias(Some(lopsided()));
        assert!(clipped.abs() <= 0.012 && dim.abs() <= 0.012, "bright {bright}: clipped {clipped} px, dim {dim} px");
        assert!(rms <= 0.035, "bright {bright}: clipped points' RMS {rms} px");
    }
}

/// The lopsided ring of the test above, its bright sectors clipped 8 times over (2000 DN above
/// a background of 20): the clipped profiles' flanks, read relative to their plateau, are far
/// more lopsided than the dim sectors' (−0.49 against −0.08), steadily so along them. Judged
/// against one lopsidedness for the whole stripe they passed for cuts, and with `--max-width
/// 30` (where they are measured at full resolution) none was kept.
#[test]
fn a_stripe_clipped_in_parts_keeps_its_clipped_points() {
    let img = lopsided_ring(150.0, 2000.0, 20.0);
    for max_width in [12.0, 30.0] {
        let params = RidgeParams { optics_blur_px: Some(LOPSIDED_BLUR_PX), max_width, ..Default::default() };
        let pts = RidgeDetector::new(W, H, circle(), params).detect(&img);
        let clipped = pts.iter().filter(|p| p.quality & quality::SATURATED != 0).count();
        eprintln!("max width {max_width} px: {} points, {clipped} clipped", pts.len());
        // Measured: 243 and 202 clipped points of about 250 (the bright half of a 440 px ring).
        assert!(clipped >= 180, "max width {max_width} px: {clipped} clipped points kept");
    }
}

/// Read at a mosaic's sites, reflections are judged among the points the search region keeps,
/// as in a frame read whole: a brighter stripe outside the region does not take a dimmer one
/// inside it.
#[test]
fn reflections_at_mosaic_sites_are_judged_after_the_search_region() {
    // Sites: 96 × 96, a bright stripe along site row 20 and a dim one along row 60 (frame
    // rows 40.5 and 120.5 of the 192 × 192 frame, the region keeping frame rows 100-150).
    let mut sites = GrayImage::new(96, 96, 8);
    for y in 0..96 {
        let level = gaussian_line(y as f64 - 20.0, 1.5, 200.0) + gaussian_line(y as f64 - 60.0, 1.5, 70.0);
        for x in 0..96 {
            sites.data[y * 96 + x] = level.round() as u16;
        }
    }
    let region = SearchRegion::Rect { x0: 0, y0: 100, x1: 192, y1: 150 };
    let found = |one_stripe_per| {
        let params = RidgeParams { one_stripe_per, ..Default::default() };
        let frame = RidgeDetector::for_image_centre(192, 192, params).with_region(region.clone()).unwrap();
        let at_sites = frame.for_mosaic_sites((0, 0));
        frame.points_from_mosaic_sites(at_sites.detect(&sites), (0, 0))
    };
    let every = found(None);
    assert!(every.len() > 40 && every.iter().all(|p| (p.v - 120.0).abs() < 1.0), "{} points", every.len());
    assert_eq!(found(Some(ScanLines::Columns)), every);
}
