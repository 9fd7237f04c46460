//! The realistic sensor's optics against physics: laser speckle against the speckle limit of
//! Dorsch, Häusler and Herrmann (Appl. Opt. 33:1306, 1994), the PSF against its optics, and
//! determinism.

mod common;

use common::{centroid_along, centroid_within};
use omni_geom::{Point3, Vector2, intersect_ray_plane};
use omni_simulator::{
    BenchObject, Imaging, Optics, RenderOptions, Scene, Sensor, paper_bench, render_laser_frame, truth_polylines,
};

/// Speckle's share of the stripe-centre scatter on the bench plane at 500 mm.
struct SpeckleScatter {
    /// Per-point centroid offsets, speckled − incoherent image (px).
    sigma_px: f64,
    /// The same as range errors along the viewing ray (mm).
    sigma_range_mm: f64,
    /// Dorsch's limit in range (mm): the pixel limit times each point's range-per-pixel.
    dorsch_range_mm: f64,
    points: usize,
}

/// Distance from the viewpoint F = (0, 0, 2c) of the point where the ray of pixel `px` meets the
/// light plane.
fn range_at(sensor: &Sensor, lp: &omni_model::LightPlane, px: Vector2<f64>) -> Option<f64> {
    let ray = sensor.camera.pixel_to_ray(&px)?;
    let hit = intersect_ray_plane(&ray, &lp.plane, 1e-6).ok()?;
    Some((hit.point - Point3::new(0.0, 0.0, 80.0)).norm())
}

/// Renders the bench plane with and without speckle (no photon or read noise, no ambient light,
/// 16 bits) and measures the plain centroid across the stripe at every truth point, from samples
/// within ±`reach_px` of it.
fn speckle_scatter(optics: Optics, beam_fwhm_mm: f64, reach_px: f64) -> SpeckleScatter {
    let sensor = Sensor::paper();
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let quiet = RenderOptions {
        noise: false,
        ambient_e: 0.0,
        bit_depth: 16,
        beam_fwhm_mm,
        imaging: Imaging::Lens { optics, speckle: false },
        ..RenderOptions::default()
    };
    let mut offsets = vec![];
    let mut range_errors = vec![];
    let mut per_px = vec![];
    for (k, alpha_deg) in [15.0, 17.0, 19.0, 21.0, 23.0, 25.0].into_iter().enumerate() {
        let alpha = f64::to_radians(alpha_deg);
        let speckled =
            RenderOptions { seed: k as u64, imaging: Imaging::Lens { optics, speckle: true }, ..quiet.clone() };
        let a = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &quiet);
        let b = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &speckled);
        let (w, h) = (a.image.width, a.image.height);
        let img = |f: &omni_simulator::Frame16| f.data.iter().map(|v| *v as f64).collect::<Vec<f64>>();
        let (ia, ib) = (img(&a.image), img(&b.image));
        let lp = sensor.transmitter.light_plane(alpha, 0, 0).unwrap();
        for line in truth_polylines(&a.truth) {
            let inner = line.len().saturating_sub(24);
            for i in (12..12 + inner).step_by(4) {
                if line[i].xyz[1].abs() > 150.0 {
                    continue;
                }
                let tangent = (Vector2::from(line[i + 1].pixel) - Vector2::from(line[i - 1].pixel)).normalize();
                let normal = Vector2::new(-tangent.y, tangent.x);
                let centroid = |img: &[f64]| centroid_within(img, w, h, &line[i], normal, reach_px);
                let (Some(ca), Some(cb)) = (centroid(&ia), centroid(&ib)) else {
                    continue;
                };
                let p = Vector2::from(line[i].pixel);
                let (Some(r0), Some(r1)) =
                    (range_at(&sensor, &lp, p - normal * 0.5), range_at(&sensor, &lp, p + normal * 0.5))
                else {
                    continue;
                };
                let mm_per_px = r1 - r0;
                offsets.push(cb - ca);
                range_errors.push((cb - ca) * mm_per_px);
                per_px.push(mm_per_px);
            }
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    SpeckleScatter {
        sigma_px: rms(&offsets),
        sigma_range_mm: rms(&range_errors),
        dorsch_range_mm: optics.dorsch_sigma_px() * rms(&per_px),
        points: offsets.len(),
    }
}

/// Dorsch's limit holds for a resolved laser line: its geometric image at least a speckle
/// grain wide. The bench's 0.5 mm sheet is far thinner than a pixel's footprint at 500 mm
/// (≈ 2.8 mm), so the test widens the sheet to 5 mm (≈ 0.8 px σ in the image, a grain or more
/// at F/2.8–F/8).
#[test]
fn speckle_matches_the_dorsch_limit_at_three_f_numbers() {
    for f_number in [2.8, 4.0, 8.0] {
        let optics = Optics { f_number, defocus_px: 0.0, ..Optics::paper() };
        let s = speckle_scatter(optics, 5.0, 4.0);
        let ratio = s.sigma_range_mm / s.dorsch_range_mm;
        eprintln!(
            "F/{f_number}: {} points, speckle σ {:.4} px = {:.3} mm in range, Dorsch {:.4} px = {:.3} mm, ratio {ratio:.2}",
            s.points,
            s.sigma_px,
            s.sigma_range_mm,
            optics.dorsch_sigma_px(),
            s.dorsch_range_mm
        );
        assert!(s.points > 200, "F/{f_number}: only {} points", s.points);
        assert!((0.7..=1.3).contains(&ratio), "F/{f_number}: measured / Dorsch = {ratio:.2}");
    }
}

/// Speckle on a line measured row by row, against an independent Fourier-optics model of one
/// (`scripts/speckle_line_model.py`, numpy, sharing no code with the renderer: a rough surface's
/// random phases on a 1/8 px grid under a Gaussian sheet, a circular pupil of cutoff NA/λ with a
/// defocus phase, intensities integrated over the pixels; docs/DECISIONS.md, 2026-12-06). Unlike
/// Dorsch's spot, a line wider than the speckle grain scatters as the root of its width, and a
/// blur circle of d px adds (k·C·d)² to the variance. The model's figures at F/4, two patterns
/// (C 0.71), its centroid taken without a threshold: a sheet of σ 1.7 px (11 mm here) in focus
/// 0.185 px; σ 0.083 px (0.5 mm) under a 6 px circle 0.220 px; σ 0.8 px (5 mm) under a 6 px
/// circle 0.308 px. The renderer, its centroid above 5 % of the peak within ±12 px: 0.183 /
/// 0.242 / 0.275 px (the sheets' widths in px vary a little along the stripe); asserted within
/// 15 % of the model.
#[test]
fn speckle_on_a_line_follows_an_independent_model_of_width_and_defocus() {
    for (beam_mm, defocus_px, model_px) in [(11.0, 0.0, 0.185), (0.5, 6.0, 0.220), (5.0, 6.0, 0.308)] {
        let optics = Optics { defocus_px, ..Optics::paper() };
        let s = speckle_scatter(optics, beam_mm, 12.0);
        let ratio = s.sigma_px / model_px;
        eprintln!(
            "sheet {beam_mm} mm, {defocus_px} px circle: {} points, speckle σ {:.4} px, model {model_px:.3}, ratio {ratio:.2}",
            s.points, s.sigma_px
        );
        assert!(s.points > 200, "{beam_mm} mm: only {} points", s.points);
        assert!((0.85..=1.15).contains(&ratio), "{beam_mm} mm, {defocus_px} px: measured / model = {ratio:.2}");
    }
}

/// The speckled stripe keeps the incoherent stripe's position: averaged over patterns, each
/// point's centroid offset is what the patterns' own scatter leaves (a centre snapped to the
/// ¼ px cells of the coherent field would add a sawtooth of up to ±⅛ px). The reference is the
/// ensemble mean, i.e. the image through the intensity PSF |h|², estimated from 160 patterns: the
/// Gaussian stand-in that blurs the ambient light has the right width but not the shape of a
/// weakly defocused PSF (docs/DECISIONS.md).
#[test]
fn speckle_keeps_the_stripe_position_on_average() {
    for defocus_px in [0.0, Optics::paper().defocus_px] {
        let (mean, expected, bias, points) = speckle_mean_offset(Optics { defocus_px, ..Optics::paper() });
        eprintln!(
            "defocus {defocus_px} px, {points} points: mean of 8 patterns {mean:.4} px rms (scatter alone {expected:.4}), bias {bias:.4} px"
        );
        assert!(points > 100, "only {points} points");
        assert!(
            mean < 1.3 * expected,
            "defocus {defocus_px}: a systematic offset remains: {mean:.4} px against {expected:.4}"
        );
        assert!(bias.abs() < 0.01, "defocus {defocus_px}: mean offset {bias:.4} px");
    }
}

/// Per-point centroid offsets of 8 single speckled frames from the ensemble-mean image: the rms
/// of their per-point means, what 8 patterns' scatter alone gives, their mean, the point count.
fn speckle_mean_offset(optics: Optics) -> (f64, f64, f64, usize) {
    let sensor = Sensor::paper_scaled(512);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let quiet = RenderOptions {
        noise: false,
        ambient_e: 0.0,
        bit_depth: 16,
        imaging: Imaging::Lens { optics, speckle: true },
        ..RenderOptions::default()
    };
    let alpha = 19f64.to_radians();
    let img = |f: &omni_simulator::Frame16| f.data.iter().map(|v| *v as f64).collect::<Vec<f64>>();
    let render = |seed: u64, optics: Optics| {
        let o = RenderOptions { seed, imaging: Imaging::Lens { optics, speckle: true }, ..quiet.clone() };
        render_laser_frame(&sensor, &scene, alpha, 0, &[0], &o)
    };
    let patterns = 8;
    let speckled: Vec<Vec<f64>> = (0..patterns).map(|seed| img(&render(seed, optics).image)).collect();
    let first = render(0, optics);
    let (w, h, truth) = (first.image.width, first.image.height, first.truth);
    let ensemble = Optics { speckle_patterns: 8, ..optics };
    let mut reference = vec![0.0; (w * h) as usize];
    let renders = 20;
    for seed in 1000..1000 + renders {
        for (r, v) in reference.iter_mut().zip(img(&render(seed, ensemble).image)) {
            *r += v / renders as f64;
        }
    }
    let (mut means, mut all) = (vec![], vec![]);
    for line in truth_polylines(&truth) {
        let inner = line.len().saturating_sub(24);
        for i in (12..12 + inner).step_by(2) {
            let tangent = (Vector2::from(line[i + 1].pixel) - Vector2::from(line[i - 1].pixel)).normalize();
            let normal = Vector2::new(-tangent.y, tangent.x);
            let Some(c0) = centroid_along(&reference, w, h, &line[i], normal) else { continue };
            let offsets: Option<Vec<f64>> =
                speckled.iter().map(|s| centroid_along(s, w, h, &line[i], normal).map(|c| c - c0)).collect();
            let Some(offsets) = offsets else { continue };
            means.push(offsets.iter().sum::<f64>() / patterns as f64);
            all.extend(offsets);
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let expected = rms(&all) / (patterns as f64).sqrt();
    let bias = means.iter().sum::<f64>() / means.len() as f64;
    (rms(&means), expected, bias, means.len())
}

/// Mean rms width (px) of the stripe's profile across the stripe, over the plane's truth points.
fn mean_stripe_width(img: &[f64], w: u32, h: u32, truth: &[omni_simulator::TruthPoint]) -> f64 {
    let widths: Vec<f64> = truth_polylines(truth)
        .iter()
        .flat_map(|line| {
            let inner = line.len().saturating_sub(24);
            (12..12 + inner).step_by(4).filter_map(move |i| {
                let tangent = (Vector2::from(line[i + 1].pixel) - Vector2::from(line[i - 1].pixel)).normalize();
                common::width_along(img, w, h, &line[i], Vector2::new(-tangent.y, tangent.x))
            })
        })
        .collect();
    widths.iter().sum::<f64>() / widths.len() as f64
}

/// The blur follows the optics over 0.4–1.5 px (`--blur-px`): the stripe's squared width grows
/// by the PSF's σ² above the diffraction limit's, incoherently and through the coherent pupil.
#[test]
fn blur_from_the_optics_spans_the_stated_range() {
    let sensor = Sensor::paper_scaled(512);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let alpha = 19f64.to_radians();
    let base = Optics { defocus_px: 0.0, ..Optics::paper() };
    let width = |optics: Optics, speckle: bool| {
        let renders = if speckle { 4 } else { 1 };
        let o = |seed| RenderOptions {
            noise: false,
            ambient_e: 0.0,
            bit_depth: 16,
            seed,
            imaging: Imaging::Lens { optics: Optics { speckle_patterns: 8, ..optics }, speckle },
            ..RenderOptions::default()
        };
        let first = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &o(0));
        let mut sum = vec![0.0; first.image.data.len()];
        for seed in 0..renders {
            let f = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &o(seed));
            sum.iter_mut().zip(&f.image.data).for_each(|(s, v)| *s += *v as f64);
        }
        mean_stripe_width(&sum, first.image.width, first.image.height, &first.truth)
    };
    for speckle in [false, true] {
        let w0 = width(base, speckle);
        for blur in [0.4, 0.7, 1.0, 1.5] {
            let optics = base.with_psf_sigma(blur).unwrap();
            let grown = (width(optics, speckle).powi(2) - w0 * w0).sqrt();
            let expected = (blur * blur - base.psf_sigma_px().powi(2)).sqrt();
            eprintln!(
                "speckle {speckle}: blur σ {blur} px: width grows by {grown:.3} px in quadrature, expected {expected:.3}"
            );
            assert!((grown / expected - 1.0).abs() < 0.1, "blur {blur}: {grown:.3} px against {expected:.3}");
        }
    }
}

/// Speckle is the rough surface's, seen by a still camera: the same light plane from another
/// facet gives the same grains (frames identical without photon noise), a mirror angle a
/// thousandth of a degree on (the stripe moved 0.005 px) nearly the same, and another seed (another
/// surface) other grains. (Drawn per frame, the first two correlated 0.06 and 0.02.)
#[test]
fn speckle_belongs_to_the_surface_not_to_the_frame() {
    let sensor = Sensor::paper_scaled(512);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let quiet = RenderOptions { noise: false, ambient_e: 0.0, bit_depth: 16, ..RenderOptions::default() };
    let render = |alpha_deg: f64, facet: u32, seed: u64| {
        let o = RenderOptions { seed, ..quiet.clone() };
        let f = render_laser_frame(&sensor, &scene, alpha_deg.to_radians(), facet, &[0], &o);
        f.image.data.iter().map(|v| *v as f64).collect::<Vec<f64>>()
    };
    let a = render(19.0, 0, 1);
    let peak = a.iter().cloned().fold(0.0, f64::max);
    let lit: Vec<usize> = (0..a.len()).filter(|&i| a[i] > 0.1 * peak).collect();
    assert!(lit.len() > 100, "{} lit pixels", lit.len());
    let correlation = |b: &[f64]| {
        let (x, y): (Vec<f64>, Vec<f64>) = lit.iter().map(|&i| (a[i], b[i])).unzip();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (mx, my) = (mean(&x), mean(&y));
        let cov: f64 = x.iter().zip(&y).map(|(p, q)| (p - mx) * (q - my)).sum();
        let var = |v: &[f64], m: f64| v.iter().map(|p| (p - m).powi(2)).sum::<f64>();
        cov / (var(&x, mx) * var(&y, my)).sqrt()
    };
    let other_facet = render(19.0, 3, 1);
    let nudged = render(19.001, 0, 1);
    let other_surface = render(19.0, 0, 2);
    let (same, near, other) = (correlation(&other_facet), correlation(&nudged), correlation(&other_surface));
    eprintln!("speckle correlation: another facet {same:.4}, 0.001° on {near:.4}, another surface {other:.4}");
    assert!(same > 0.9999, "another facet: {same}");
    assert!(near > 0.95, "0.001° on: {near}");
    assert!(other < 0.6, "another surface: {other}");
}
