//! Scene lighting: level, smooth gradients, hard-edged patches and textured albedo reach the
//! rendered ambient frame as described.

use omni_formats::scene::{Gradient, LightPatch, Lighting, SceneFile, SceneObject, Shape, Texture, TexturePattern};
use omni_simulator::{RenderOptions, Scene, Sensor, render_ambient_frame};

fn room(lighting: Option<Lighting>, texture: Option<Texture>) -> Scene {
    let shape = Shape::Room { centre_mm: [0.0, 0.0, 0.0], size_mm: [2000.0, 2000.0, 2000.0] };
    let object = SceneObject { name: None, albedo: 0.5, texture, shape };
    Scene::from_file(SceneFile { lighting, ..SceneFile::new(vec![object]) }).unwrap()
}

/// Mean level of the pixels whose rays go towards +x (right half of the image ring) and −x.
fn halves(scene: &Scene) -> (f64, f64) {
    let sensor = Sensor::paper_scaled(256);
    let opts = RenderOptions { noise: false, bit_depth: 16, ..RenderOptions::default() };
    let img = render_ambient_frame(&sensor, scene, &opts);
    let (mut right, mut left) = (vec![], vec![]);
    for y in 0..256u32 {
        for x in 0..256u32 {
            let v = img.get(x, y) as f64;
            if v == 0.0 {
                continue;
            }
            let dx = x as f64 - 127.5;
            if dx > 20.0 {
                right.push(v);
            } else if dx < -20.0 {
                left.push(v);
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    (mean(&right), mean(&left))
}

#[test]
fn level_gradient_and_patches_shape_the_ambient_light() {
    let (r0, l0) = halves(&room(None, None));
    assert!((r0 / l0 - 1.0).abs() < 0.02, "uniform room: {r0} vs {l0}");
    let bright = Lighting { level: 2.0, gradient: None, patches: vec![] };
    let (r1, _) = halves(&room(Some(bright), None));
    assert!((r1 / r0 - 2.0).abs() < 0.02, "level 2: {r1} vs {r0}");
    // Brighter towards +x: the walls at x = ±1 m differ by 1 ± 0.5.
    let gradient =
        Lighting { level: 1.0, gradient: Some(Gradient { direction: [1.0, 0.0, 0.0], per_m: 0.5 }), patches: vec![] };
    let (r2, l2) = halves(&room(Some(gradient), None));
    assert!(r2 > 1.3 * l2, "gradient: right {r2}, left {l2}");
    // A pool of light on the +x wall: brighter there, and the rest unchanged.
    let patch = LightPatch { centre_mm: [1000.0, 0.0, 0.0], radius_mm: 600.0, gain: 3.0 };
    let pooled = Lighting { level: 1.0, gradient: None, patches: vec![patch] };
    let (r3, l3) = halves(&room(Some(pooled), None));
    assert!(r3 > 1.3 * r0 && (l3 / l0 - 1.0).abs() < 0.02, "patch: right {r3} (was {r0}), left {l3} (was {l0})");
}

#[test]
fn textured_albedo_has_its_contrast_and_period() {
    let texture =
        Texture { pattern: TexturePattern::Stripes, period_mm: 300.0, contrast: 0.5, direction: [0.0, 0.0, 1.0] };
    let sensor = Sensor::paper_scaled(256);
    let opts = RenderOptions { noise: false, bit_depth: 16, ..RenderOptions::default() };
    let plain = render_ambient_frame(&sensor, &room(None, None), &opts);
    let striped = render_ambient_frame(&sensor, &room(None, Some(texture)), &opts);
    let ratios: Vec<f64> =
        plain.data.iter().zip(&striped.data).filter(|(p, _)| **p > 100).map(|(p, s)| *s as f64 / *p as f64).collect();
    let above = ratios.iter().filter(|r| **r > 1.3).count() as f64 / ratios.len() as f64;
    let below = ratios.iter().filter(|r| **r < 0.7).count() as f64 / ratios.len() as f64;
    // Bands of albedo × 1.5 and × 0.5 in about equal shares (blur mixes the edges).
    assert!(above > 0.25 && below > 0.25, "bright share {above:.2}, dark share {below:.2}");
    let bad = Texture {
        contrast: 1.5,
        ..Texture { pattern: TexturePattern::Blocks, period_mm: 5.0, contrast: 0.0, direction: [0.0, 0.0, 1.0] }
    };
    let shape = Shape::Sphere { centre_mm: [0.0; 3], radius_mm: 1.0 };
    let e = Scene::from_file(SceneFile::new(vec![SceneObject { name: None, albedo: 0.5, texture: Some(bad), shape }]))
        .unwrap_err();
    assert!(e.contains("texture.contrast"), "{e}");
}

#[test]
fn bad_lighting_names_the_field() {
    let patch = LightPatch { centre_mm: [0.0; 3], radius_mm: -1.0, gain: 2.0 };
    let l = Lighting { level: 1.0, gradient: None, patches: vec![patch] };
    let shape = Shape::Sphere { centre_mm: [0.0; 3], radius_mm: 1.0 };
    let file = SceneFile { lighting: Some(l), ..SceneFile::new(vec![SceneObject::new(shape)]) };
    let e = Scene::from_file(file).unwrap_err();
    assert!(e.contains("lighting") && e.contains("patches[0].radius_mm"), "{e}");
}
