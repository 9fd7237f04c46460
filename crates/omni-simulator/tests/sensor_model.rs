//! The camera's signal chain against its documented model: mean level, photon + read noise,
//! gamma, saturation.

use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_simulator::{
    BenchObject, Imaging, Optics, RenderOptions, Scene, Sensor, paper_bench, render_ambient_frame, render_laser_frame,
};

/// A room seen in every direction, albedo 0.5: every pixel in the mirror annulus collects
/// 0.5 · ambient_e electrons.
fn grey_room() -> Scene {
    let room = Shape::Room { centre_mm: [0.0, 0.0, 0.0], size_mm: [3000.0, 3000.0, 3000.0] };
    Scene::from_file(SceneFile::new(vec![SceneObject { name: None, albedo: 0.5, texture: None, shape: room }])).unwrap()
}

/// Pixels well inside the mirror annulus (away from the rim and blind centre, blurred there).
fn annulus_pixels(sensor: &Sensor) -> Vec<usize> {
    let c = sensor.camera.mirror_circle();
    let (w, h) = sensor.camera.image_size();
    (0..(w * h) as usize)
        .filter(|&i| {
            let (x, y) = ((i % w as usize) as f64, (i / w as usize) as f64);
            let r = (x - c.centre.x).hypot(y - c.centre.y);
            r > c.inner_radius + 4.0 && r < c.outer_radius - 4.0
        })
        .collect()
}

#[test]
fn level_and_noise_follow_photon_and_read_noise() {
    let sensor = Sensor::paper_scaled(192);
    let scene = grey_room();
    let opts = RenderOptions { bit_depth: 16, ..RenderOptions::ideal() };
    let gain = 65535.0 / opts.full_well_e; // DN per electron
    let signal_e = 0.5 * opts.ambient_e;
    let a = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 1, ..opts.clone() });
    let b = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 2, ..opts.clone() });
    let px = annulus_pixels(&sensor);
    let n = px.len() as f64;
    let mean = px.iter().map(|&i| a.data[i] as f64).sum::<f64>() / n;
    let var_diff = px.iter().map(|&i| (a.data[i] as f64 - b.data[i] as f64).powi(2)).sum::<f64>() / n;
    let sigma = (var_diff / 2.0).sqrt();
    let expected = (signal_e + opts.read_noise_e.powi(2)).sqrt() * gain;
    eprintln!("{n} px: mean {mean:.1} DN (expected {:.1}), σ {sigma:.1} DN (expected {expected:.1})", signal_e * gain);
    assert!((mean / (signal_e * gain) - 1.0).abs() < 0.005, "mean {mean}");
    assert!((sigma / expected - 1.0).abs() < 0.05, "σ {sigma}, expected {expected}");
}

#[test]
fn gamma_and_quantisation() {
    let sensor = Sensor::paper_scaled(96);
    let scene = grey_room();
    let opts = RenderOptions { gamma: 2.2, ..RenderOptions::ideal_noiseless() };
    let f = render_ambient_frame(&sensor, &scene, &opts);
    let expected = (255.0 * (0.5 * opts.ambient_e / opts.full_well_e).powf(1.0 / 2.2)).round() as u16;
    assert!(annulus_pixels(&sensor).iter().all(|&i| f.data[i] == expected), "expected {expected}");
}

#[test]
fn strong_laser_saturates_at_full_scale() {
    let sensor = Sensor::paper_scaled(256);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let normal = render_laser_frame(&sensor, &scene, 0.35, 0, &[0], &RenderOptions::ideal_noiseless());
    let strong = RenderOptions {
        laser_strength: 10.0 * RenderOptions::ideal().laser_strength,
        ..RenderOptions::ideal_noiseless()
    };
    let hot = render_laser_frame(&sensor, &scene, 0.35, 0, &[0], &strong);
    let saturated = |f: &omni_simulator::Frame16| f.data.iter().filter(|v| **v == 255).count();
    assert_eq!(saturated(&normal.image), 0, "the default stripe is unsaturated");
    assert!(saturated(&hot.image) > 50, "a 10× laser saturates: {}", saturated(&hot.image));
    assert!(hot.image.data.iter().all(|v| *v <= 255));
}

#[test]
fn speckle_modulates_the_stripe_and_keeps_its_mean() {
    let sensor = Sensor::paper_scaled(512);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let alpha = 20f64.to_radians();
    let lens = |speckle| Imaging::Lens { optics: Optics::paper(), speckle };
    // A weak laser: no bright speckle may clip at the full well.
    let clean = RenderOptions {
        ambient_e: 0.0,
        noise: false,
        bit_depth: 16,
        laser_strength: 0.25 * RenderOptions::default().laser_strength,
        imaging: lens(false),
        ..RenderOptions::default()
    };
    let speckled = |seed| RenderOptions { seed, imaging: lens(true), ..clean.clone() };
    let a = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &clean);
    let b = render_laser_frame(&sensor, &scene, alpha, 0, &[0], &speckled(0));
    assert_eq!(b.image, render_laser_frame(&sensor, &scene, alpha, 0, &[0], &speckled(0)).image, "deterministic");
    assert_ne!(b.image, render_laser_frame(&sensor, &scene, alpha, 0, &[0], &speckled(1)).image, "a new pattern");
    // Stripe energy across the stripe (5 × 5 sum at each truth pixel, every 4th sample).
    let energy = |f: &omni_simulator::Frame16| -> Vec<f64> {
        a.truth
            .iter()
            .step_by(4)
            .filter(|t| t.xyz[1].abs() < 150.0)
            .map(|t| {
                let (x, y) = (t.pixel[0].round() as i64, t.pixel[1].round() as i64);
                let mut s = 0.0;
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        s += f.get((x + dx) as u32, (y + dy) as u32) as f64;
                    }
                }
                s
            })
            .collect()
    };
    let rel_std = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        ((v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt() / m, m)
    };
    let (s0, m0) = rel_std(&energy(&a.image));
    // The total of one stripe's speckle fluctuates by a few % (a few hundred grains): four
    // patterns are averaged for the mean.
    let patterns: Vec<(f64, f64)> = (0..4)
        .map(|seed| rel_std(&energy(&render_laser_frame(&sensor, &scene, alpha, 0, &[0], &speckled(seed)).image)))
        .collect();
    let s1 = patterns.iter().map(|p| p.0).sum::<f64>() / 4.0;
    let m1 = patterns.iter().map(|p| p.1).sum::<f64>() / 4.0;
    eprintln!("stripe energy relative std: clean {s0:.3}, speckle → {s1:.3}; mean {m0:.0} → {m1:.0}");
    assert!(s1 > s0 + 0.1, "speckle must modulate the stripe: {s0} → {s1}");
    // The 5 × 5 sum misses the diffraction rings' far tail (a few %) that the Gaussian lacks.
    assert!((m1 / m0 - 1.0).abs() < 0.08, "speckle keeps the mean: {m0} → {m1}");
}

#[test]
fn named_conditions_are_what_they_say() {
    let sensor = Sensor::paper_scaled(512);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let peak = |o: RenderOptions| {
        let f = render_laser_frame(&sensor, &scene, 20f64.to_radians(), 0, &[0], &RenderOptions { noise: false, ..o });
        *f.image.data.iter().max().unwrap()
    };
    let (normal, weak, hot) = (
        peak(RenderOptions::ideal()),
        peak(RenderOptions::ideal_weak_stripe()),
        peak(RenderOptions::ideal_saturated()),
    );
    eprintln!("peaks at 512 px: default {normal}, weak {weak}, saturated {hot}");
    assert!(hot == 255 && normal < 255 && weak < normal);
    let ambient =
        render_ambient_frame(&sensor, &scene, &RenderOptions { noise: false, ..RenderOptions::ideal_strong_ambient() });
    let plane_level = *ambient.data.iter().max().unwrap();
    assert!((115..=130).contains(&plane_level), "bench plane under strong ambient: {plane_level}");
}
