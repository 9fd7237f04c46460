//! Real-shaped stripes rendered and measured: width, shape and peak of the tailed profile,
//! a blooming saturated stripe's plateau, colour frames and JPEG.

use crate::*;

/// A matte wall 400 mm out at 45° azimuth, where laser 0's stripe runs obliquely across the
/// image at 20°.
fn oblique(width: u32) -> (Sensor, Scene, f64) {
    use omni_formats::scene::{SceneFile, SceneObject, Shape};
    let wall = Shape::Rectangle {
        centre_mm: [283.0, 283.0, -60.0],
        normal: [-std::f64::consts::FRAC_1_SQRT_2, -std::f64::consts::FRAC_1_SQRT_2, 0.0],
        up: [0.0, 0.0, 1.0],
        width_mm: 700.0,
        height_mm: 500.0,
    };
    let scene = SceneFile::new(vec![SceneObject { albedo: 0.8, ..SceneObject::new(wall) }]);
    (Sensor::paper_scaled(width), Scene::from_file(scene).unwrap(), 20f64.to_radians())
}

/// Ideal optics, no noise, no ambient light, 16 bits, a full well far above the stripe.
fn quiet() -> RenderOptions {
    RenderOptions { noise: false, ambient_e: 0.0, bit_depth: 16, full_well_e: 1e5, ..RenderOptions::ideal() }
}

/// The stripe's cross-section as its pixels sample it: every pixel within `reach` px across and
/// 10 px along the stripe of a laser-0 truth point near the middle of the stripe where it runs
/// obliquely (so that pixel centres fall at every phase), with its offset across the stripe from
/// the nearest truth point, along that point's sheet gradient (towards the plane's normal side).
/// Returns ((offset px, value, x, y) per pixel, the sheet's width in px at the middle point, and
/// that point's mm per px).
fn cross_section(
    sensor: &Sensor,
    scene: &Scene,
    alpha: f64,
    frame: &LaserFrame,
    reach: f64,
) -> (Vec<[f64; 4]>, f64, f64) {
    let points: Vec<(&TruthPoint, [f64; 2])> = frame
        .truth
        .iter()
        .filter(|t| t.laser == 0)
        .filter_map(|t| {
            let g = sheet_gradient_at(sensor, scene, alpha, 0, t)?;
            let n = (g[0] * g[0] + g[1] * g[1]).sqrt();
            Some((t, [g[0] / n, g[1] / n, n]))
        })
        .filter(|(_, n)| n[0].abs() > 0.4 && n[1].abs() > 0.4)
        .map(|(t, n)| (t, [n[0], n[1]]))
        .collect();
    assert!(points.len() > 200, "{} oblique truth points", points.len());
    let mid = points.len() / 2;
    let (t, n) = points[mid];
    let scale = {
        let g = sheet_gradient_at(sensor, scene, alpha, 0, t).unwrap();
        (g[0] * g[0] + g[1] * g[1]).sqrt()
    };
    let run = &points[mid - 100..mid + 100];
    let r = (reach + 12.0).ceil() as i64;
    let (cx, cy) = (t.pixel[0].round() as i64, t.pixel[1].round() as i64);
    let mut out = vec![];
    for y in cy - r..=cy + r {
        for x in cx - r..=cx + r {
            if x < 0 || y < 0 || x >= frame.image.width as i64 || y >= frame.image.height as i64 {
                continue;
            }
            let (px, py) = (x as f64, y as f64);
            if ((px - t.pixel[0]) * n[1] - (py - t.pixel[1]) * n[0]).abs() > 10.0 {
                continue;
            }
            // The truth point whose normal line passes nearest the pixel.
            let (along, s) = run
                .iter()
                .map(|(q, m)| {
                    let (dx, dy) = (px - q.pixel[0], py - q.pixel[1]);
                    ((dx * m[1] - dy * m[0]).abs(), dx * m[0] + dy * m[1])
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            if along < 0.2 && s.abs() <= reach {
                out.push([s, frame.image.get(x as u32, y as u32) as f64, px, py]);
            }
        }
    }
    (out, frame.sheet_fwhm_mm[0] / scale, scale)
}

/// The value the model predicts at pixel (x, y) (to a constant factor): the sheet's profile
/// (`curve`, of the plane distance in px at `scale` mm per px) times the fan's spreading and
/// incidence, at the surface point each position sees, through the
/// ideal PSF (σ 0.7 px) and the pixel's square: a 21 × 21 grid 0.25 px apart, each position
/// weighted by the PSF integrated over the pixel.
fn predicted(
    sensor: &Sensor,
    scene: &Scene,
    alpha: f64,
    scale: f64,
    curve: &impl Fn(f64) -> f64,
    x: f64,
    y: f64,
) -> f64 {
    let lp = sensor.transmitter.light_plane(alpha, 0, 0).unwrap();
    let kernel =
        |u: f64| (0..16).map(|i| (-0.5 * ((u - (i as f64 + 0.5) / 16.0 + 0.5) / 0.7).powi(2)).exp()).sum::<f64>();
    let (mut sum, mut weight) = (0.0, 0.0);
    for j in -10..=10 {
        for i in -10..=10 {
            let (u, v) = (i as f64 * 0.25, j as f64 * 0.25);
            let Some(ray) = sensor.camera.pixel_to_ray(&omni_geom::Vector2::new(x + u, y + v)) else { continue };
            let Some(hit) = scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY) else { continue };
            let w = kernel(u) * kernel(v);
            // The fan's 1/r spreading and the incidence where the sheet's plane crosses the
            // surface, as the renderer takes them: they change along the stripe.
            let d = lp.plane.signed_distance(&hit.point);
            let normal = lp.plane.normal.into_inner();
            let t = normal - hit.normal * normal.dot(&hit.normal);
            let p0 = hit.point - t * (d / t.norm_squared());
            let to_p0 = p0 - lp.virtual_source;
            let falloff = (to_p0.normalize().dot(&hit.normal)).abs() / to_p0.norm();
            sum += w * falloff * curve(d / scale);
            weight += w;
        }
    }
    sum / weight
}

/// The peak of samples (offset, value): a parabola fitted by least squares to those above 80 % of
/// the largest value.
fn peak(samples: &[[f64; 2]]) -> f64 {
    let top = samples.iter().map(|s| s[1]).fold(0.0, f64::max);
    let near: Vec<&[f64; 2]> = samples.iter().filter(|s| s[1] > 0.8 * top).collect();
    // Normal equations of v = a + b x + c x².
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs = nalgebra::Vector3::<f64>::zeros();
    for s in near {
        let row = nalgebra::Vector3::new(1.0, s[0], s[0] * s[0]);
        m += row * row.transpose();
        rhs += row * s[1];
    }
    let c = m.lu().solve(&rhs).unwrap();
    -c[1] / (2.0 * c[2])
}

/// FWHM of samples (offset, value): the half-maximum crossings of their means in 0.25 px bins.
fn fwhm(samples: &[[f64; 2]]) -> f64 {
    let reach = samples.iter().map(|s| s[0].abs()).fold(0.0, f64::max);
    let bins = (2.0 * reach / 0.25).ceil() as usize + 1;
    let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
    for s in samples {
        let k = ((s[0] + reach) / 0.25).round() as usize;
        sum[k] += s[1];
        count[k] += 1;
    }
    let kept: Vec<usize> = (0..bins).filter(|k| count[*k] > 0).collect();
    let x: Vec<f64> = kept.iter().map(|k| *k as f64 * 0.25 - reach).collect();
    let y: Vec<f64> = kept.iter().map(|k| sum[*k] / count[*k] as f64).collect();
    let k = (0..y.len()).max_by(|a, b| y[*a].total_cmp(&y[*b])).unwrap();
    let half = 0.5 * y[k];
    let (mut i, mut j) = (k, k);
    while y[i] > half {
        i -= 1;
    }
    while y[j] > half {
        j += 1;
    }
    let left = x[i] + (half - y[i]) / (y[i + 1] - y[i]) * (x[i + 1] - x[i]);
    let right = x[j - 1] + (half - y[j - 1]) / (y[j] - y[j - 1]) * (x[j] - x[j - 1]);
    right - left
}

/// σ (px) of the blur the pixels see: the ideal PSF (0.7 px) and the pixel's area.
fn pixel_blur_px() -> f64 {
    (0.49f64 + 1.0 / 12.0).sqrt()
}

/// The stripe measured as the detector sees it, in the image, against the model computed
/// independently of the renderer (the sheet's profile at the surface point each position sees,
/// the fan's spreading, the PSF and the pixel's square, by ray casting): FWHM as asked and as the
/// model, the peak where the model puts it (the sheet's peak on the light plane: the truth), the
/// tail on its side as strong as the model's. The peak fitted to pixels pooled over 20 px of
/// stripe sits off the truth by what the pooling, the perspective and the brightness change along
/// the stripe do to the fit (the model's column), not by a misplaced sheet.
#[test]
fn real_and_gaussian_stripes_render_at_the_asked_width_with_their_shape_and_their_peak_on_the_truth() {
    let (sensor, scene, alpha) = oblique(512);
    let pairs = |v: &[[f64; 4]]| v.iter().map(|s| [s[0], s[1]]).collect::<Vec<_>>();
    for (profile, target) in [
        (SheetProfile::real(), 2.5),
        (SheetProfile::real(), 8.0),
        (SheetProfile::real(), 20.0),
        (SheetProfile::Gaussian, 3.0),
    ] {
        let opts = RenderOptions { profile, stripe_fwhm_px: Some(target), ..quiet() };
        let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &opts);
        let (rendered, sheet, scale) = cross_section(&sensor, &scene, alpha, &frame, 2.5 * target + 4.0);
        let blur = pixel_blur_px();
        // The model at each pixel: the sheet's profile at the plane distance of each surface point
        // around it (perspective and all), through the PSF and the pixel's square.
        let curve = profile.curve(sheet, 0.0);
        let model: Vec<[f64; 4]> = rendered
            .iter()
            .map(|s| [s[0], predicted(&sensor, &scene, alpha, scale, &curve, s[2], s[3]), s[2], s[3]])
            .collect();
        let (measured, predicted) = (pairs(&rendered), pairs(&model));
        let (width, want_width) = (fwhm(&measured), fwhm(&predicted));
        let (top, want_top) = (peak(&measured), peak(&predicted));
        let pull = profile.blurred_peak_offset_px(sheet, blur);
        // Asymmetry: the mean level 0.6–1.2 FWHM out on the tail's side over the core's side.
        let sides = |v: &[[f64; 2]]| {
            let band = |sign: f64| {
                let inside: Vec<f64> =
                    v.iter().filter(|s| (0.6..1.2).contains(&(sign * s[0] / target))).map(|s| s[1]).collect();
                inside.iter().sum::<f64>() / inside.len() as f64
            };
            band(1.0) / band(-1.0)
        };
        let (ratio, want_ratio) = (sides(&measured), sides(&predicted));
        eprintln!(
            "{profile:?} at {target} px: sheet {sheet:.3} px ({:.2} mm); stripe FWHM {width:.3} px (model {want_width:.3}); \
             fitted peak {top:+.4} px from the truth (model {want_top:+.4}; the blur's pull alone {pull:+.4}); \
             tail/core level 0.6-1.2 FWHM out {ratio:.3} (model {want_ratio:.3})",
            frame.sheet_fwhm_mm[0]
        );
        assert!((width / target - 1.0).abs() < 0.02 && (width / want_width - 1.0).abs() < 0.005, "FWHM {width}");
        assert!((top - want_top).abs() < 0.01, "peak {top} px from the truth, model {want_top}");
        assert!((ratio / want_ratio - 1.0).abs() < 0.02, "tail/core {ratio}, model {want_ratio}");
        if profile != SheetProfile::Gaussian {
            assert!(ratio > 1.5, "the tail side is brighter: {ratio}");
        }
    }
}

/// The middle truth point of laser 0's stripe where it runs obliquely, and the column through it.
fn oblique_column(sensor: &Sensor, scene: &Scene, alpha: f64, frame: &LaserFrame) -> u32 {
    let points: Vec<&TruthPoint> = frame
        .truth
        .iter()
        .filter(|t| t.laser == 0)
        .filter(|t| {
            sheet_gradient_at(sensor, scene, alpha, 0, t).is_some_and(|g| {
                let n = (g[0] * g[0] + g[1] * g[1]).sqrt();
                g[0].abs() > 0.4 * n && g[1].abs() > 0.4 * n
            })
        })
        .collect();
    points[points.len() / 2].pixel[0].round() as u32
}

#[test]
fn a_saturated_stripe_blooms_into_the_plateau_the_model_predicts() {
    let (sensor, scene, alpha) = oblique(512);
    let bright = RenderOptions {
        profile: SheetProfile::real(),
        stripe_fwhm_px: Some(10.0),
        laser_strength: 60.0 * DEFAULT_LASER_STRENGTH,
        ..quiet()
    };
    // The light on the pixels, unclipped: a full well far above it, 16 bits.
    let open = RenderOptions { full_well_e: 1e6, ..bright.clone() };
    let light = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &open);
    let x = oblique_column(&sensor, &scene, alpha, &light);
    let (w, h) = (light.image.width, light.image.height);
    let electrons: Vec<f64> = (0..h).map(|y| light.image.get(x, y) as f64 / 65535.0 * 1e6).collect();
    let peak = electrons.iter().cloned().fold(0.0, f64::max);
    let full_well = 10_000.0;
    let saturated = |v: &[f64]| v.iter().filter(|e| **e >= full_well * (1.0 - 1e-9)).count();
    for (bloom, spill) in
        [(Some(Bloom::columns()), 1.0), (Some(Bloom { axis: BloomAxis::Columns, spill: 0.5 }), 0.5), (None, 0.0)]
    {
        let mut model = electrons.clone();
        bloom_line(&mut model, full_well, spill);
        let want = saturated(&model);
        let opts = RenderOptions { full_well_e: full_well, bit_depth: 8, bloom, ..bright.clone() };
        let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &opts);
        let column: Vec<u16> = (0..h).map(|y| frame.image.get(x, y)).collect();
        let plateau: Vec<usize> = (0..h as usize).filter(|y| column[*y] == 255).collect();
        let run = plateau.last().unwrap() - plateau[0] + 1;
        // Where the truth crosses the column (the truth samples nearest to it, interpolated).
        let near: Vec<&TruthPoint> =
            frame.truth.iter().filter(|t| t.laser == 0 && (t.pixel[0] - x as f64).abs() < 0.3).collect();
        let truth_y = near.iter().map(|t| t.pixel[1]).sum::<f64>() / near.len() as f64;
        let centre = 0.5 * (plateau[0] + plateau.last().unwrap()) as f64;
        eprintln!(
            "peak {:.1} full wells, spill {spill}: plateau {run} px down column {x} (model {want} px; {} px over the full well \
             unbloomed), its centre {:+.2} px from the truth",
            peak / full_well,
            saturated(&electrons),
            centre - truth_y
        );
        assert_eq!(run, plateau.len(), "one flat run: {plateau:?}");
        assert!(run.abs_diff(want) <= 1, "plateau {run} px, the model {want} px");
        if spill == 1.0 {
            assert!((25..=90).contains(&run), "a real close-range core: {run} px");
        }
    }
    assert!(w > x);
}

/// The colour frame's value at the middle oblique truth point and `offset` px across the stripe.
fn across(sensor: &Sensor, scene: &Scene, alpha: f64, frame: &LaserFrame, offset: f64) -> [u16; 3] {
    let x = oblique_column(sensor, scene, alpha, frame);
    let t = frame.truth.iter().find(|t| t.laser == 0 && t.pixel[0].round() as u32 == x).unwrap();
    let g = sheet_gradient_at(sensor, scene, alpha, 0, t).unwrap();
    let n = (g[0] * g[0] + g[1] * g[1]).sqrt();
    let (px, py) = (t.pixel[0] + offset * g[0] / n, t.pixel[1] + offset * g[1] / n);
    frame.colour.as_ref().unwrap().get(px.round() as u32, py.round() as u32)
}

#[test]
fn a_red_stripe_on_lit_paper_is_dark_in_luma_bright_in_red_and_a_saturated_one_white_with_a_red_glow() {
    let (sensor, scene, alpha) = oblique(256);
    let camera = CameraColour { bayer: Some(BayerPattern::Rggb), ..Default::default() };
    let luma = |p: [u16; 3]| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
    let contrast = |p: [u16; 3]| p[0] as f64 - 0.5 * (p[1] as f64 + p[2] as f64);
    let lit = RenderOptions {
        profile: SheetProfile::real(),
        stripe_fwhm_px: Some(6.0),
        ambient_e: CALIBRATION_AMBIENT_E,
        laser_strength: 5.0 * DEFAULT_LASER_STRENGTH,
        gamma: 2.2,
        noise: false,
        colour: Some(Colour::new(&camera, 650.0, ColourOutput::Rgb)),
        ..RenderOptions::ideal()
    };
    let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &lit);
    let (stripe, paper) = (across(&sensor, &scene, alpha, &frame, 0.0), across(&sensor, &scene, alpha, &frame, -9.0));
    eprintln!("lit paper {paper:?}, stripe {stripe:?}");
    assert!(luma(stripe) < luma(paper), "darker in luma: {stripe:?} on {paper:?}");
    assert!(contrast(stripe) > contrast(paper) + 60.0, "bright in R − (G+B)/2: {stripe:?} on {paper:?}");
    // Close and far too bright: every channel saturates in the core (the green and blue filters
    // pass a tenth of the red light), the charge blooms down the columns (a quarter of it; the
    // drain takes the rest), and around the core only red is clipped.
    let close = RenderOptions {
        laser_strength: 400.0 * DEFAULT_LASER_STRENGTH,
        ambient_e: 2000.0,
        bloom: Some(Bloom { axis: BloomAxis::Columns, spill: 0.25 }),
        halo: Some(Halo { fraction: 0.02, sigma_px: 10.0 }),
        ..lit
    };
    let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &close);
    let core = across(&sensor, &scene, alpha, &frame, 0.0);
    let glow: Vec<[u16; 3]> = (4..20).map(|o| across(&sensor, &scene, alpha, &frame, o as f64)).collect();
    eprintln!("saturated core {core:?}, glow {glow:?}");
    assert_eq!(core, [255, 255, 255], "a white core");
    assert!(glow.iter().any(|p| p[0] == 255 && p[1] < 200), "a red glow around it: {glow:?}");
}

#[test]
fn the_real_profile_through_the_lens_keeps_its_light_with_and_without_speckle() {
    // The tail lies mostly in pixels far from the plane, whose laser light the coherent imager
    // takes as uniform cells: the light must be the same as imaged incoherently.
    let (sensor, scene, alpha) = oblique(256);
    let lens = |speckle| RenderOptions {
        imaging: Imaging::Lens { optics: Optics::paper(), speckle },
        profile: SheetProfile::real(),
        stripe_fwhm_px: Some(8.0),
        ..quiet()
    };
    let total = |o: &RenderOptions| {
        let f = render_laser_frame(&sensor, &scene, alpha, 0, &[0], o);
        f.image.data.iter().map(|v| *v as f64).sum::<f64>()
    };
    let (coherent, incoherent) = (total(&lens(true)), total(&lens(false)));
    eprintln!("light with speckle {coherent:.0}, without {incoherent:.0}");
    assert!((coherent / incoherent - 1.0).abs() < 0.03, "{coherent} vs {incoherent}");
}

#[test]
fn the_presets_and_the_blurred_peak_for_detector_tests() {
    let (sensor, scene, alpha) = oblique(256);
    let opts =
        RenderOptions::ideal_noiseless().with_real_stripe(6.0).with_colour(Some(BayerPattern::Grbg), ColourOutput::Raw);
    assert_eq!((opts.profile, opts.stripe_fwhm_px), (SheetProfile::real(), Some(6.0)));
    let colour = opts.colour.as_ref().unwrap();
    assert_eq!((colour.bayer, colour.laser_rgb), (Some(BayerPattern::Grbg), filter_response(650.0)));
    let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &opts);
    assert!(frame.colour.is_none() && frame.image.width == 256, "the raw mosaic is the grey frame");
    let t = frame.truth[frame.truth.len() / 2];
    let g = sheet_gradient_at(&sensor, &scene, alpha, 0, &t).unwrap();
    let peak = blurred_peak_at(&sensor, &scene, alpha, 0, &t, frame.sheet_fwhm_mm[0], &opts).unwrap();
    let (dx, dy) = (peak[0] - t.pixel[0], peak[1] - t.pixel[1]);
    let shift = (dx * dx + dy * dy).sqrt();
    let sheet_px = frame.sheet_fwhm_mm[0] / (g[0] * g[0] + g[1] * g[1]).sqrt();
    let pull = SheetProfile::real().blurred_peak_offset_px(sheet_px, pixel_blur_px());
    assert!((shift - pull).abs() < 1e-9 && dx * g[0] + dy * g[1] > 0.0, "{shift} px towards the tail, pull {pull}");
    let gaussian = RenderOptions::ideal_noiseless();
    assert_eq!(blurred_peak_at(&sensor, &scene, alpha, 0, &t, 0.5, &gaussian), Some(t.pixel));
}

/// A stripe width asked for in px holds on curved surfaces too: on the bench's cylinder and
/// sphere the stripe's FWHM across it, measured on the pixels of a 3 px stretch at the middle of
/// the stripe, is the one asked for (the sheet's width is set where its gradient is known,
/// which a curved surface's turning normal must not hide).
#[test]
fn curved_surfaces_carry_the_stripe_width_asked_for() {
    for object in [crate::BenchObject::Cylinder, crate::BenchObject::Sphere] {
        let scene = Scene::from_file(crate::paper_bench(object)).unwrap();
        let sensor = Sensor::paper_scaled(512);
        let alpha = 20f64.to_radians();
        let target = 6.0;
        let opts = RenderOptions { stripe_fwhm_px: Some(target), ..quiet() };
        let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &opts);
        assert!(frame.sheet_fwhm_mm[0] > 1.5 * opts.beam_fwhm_mm, "{object:?}: sheet {:?} mm", frame.sheet_fwhm_mm);
        let on_stripe: Vec<&TruthPoint> = frame.truth.iter().filter(|t| t.laser == 0).collect();
        let t = on_stripe[on_stripe.len() / 2];
        let g = sheet_gradient_at(&sensor, &scene, alpha, 0, t).expect("the middle point's gradient");
        let norm = (g[0] * g[0] + g[1] * g[1]).sqrt();
        let n = [g[0] / norm, g[1] / norm];
        let (cx, cy) = (t.pixel[0].round() as i64, t.pixel[1].round() as i64);
        let mut samples = vec![];
        for y in cy - 12..=cy + 12 {
            for x in cx - 12..=cx + 12 {
                let (dx, dy) = (x as f64 - t.pixel[0], y as f64 - t.pixel[1]);
                let (across, along) = (dx * n[0] + dy * n[1], dx * n[1] - dy * n[0]);
                if along.abs() <= 1.5 && across.abs() <= 10.0 {
                    samples.push([across, frame.image.get(x as u32, y as u32) as f64]);
                }
            }
        }
        let width = fwhm(&samples);
        assert!((width - target).abs() <= 0.1 * target, "{object:?}: FWHM {width:.2} px, asked {target} px");
    }
}
