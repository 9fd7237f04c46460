//! The paper bench: the scenes behind every accuracy figure of this project.
//!
//! The paper gives no placement, so this is ours (issue 3): each object alone in its scene, on
//! the +x side (where the light planes sweep the most), at the height of the camera centre
//! (z = 0), matte white (albedo 0.8):
//! * plane: 400 mm wide (along y) × 300 mm high, facing the sensor, centre at (500, 0, 0);
//! * cylinder: radius 50 mm, height 200 mm, vertical axis through (500, 0), z from −100 to 100;
//! * sphere: radius 50 mm, centre (500, 0, 0);
//! * cone + pyramid: a cone (apex up, radius 60 mm, height 200 mm) at (450, −120) and a
//!   triangular pyramid (base edge ≈ 173 mm, apex 200 mm above the base) at (450, 120).

use omni_formats::scene::{SceneFile, SceneObject, Shape};

/// The objects of the paper bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchObject {
    Plane,
    Cylinder,
    Sphere,
    /// The cone + triangular pyramid scene.
    ConePyramid,
}

/// Albedo of the bench objects (matte white paint).
pub const BENCH_ALBEDO: f64 = 0.8;

/// The scene of one bench object.
pub fn paper_bench(object: BenchObject) -> SceneFile {
    let obj =
        |name: &str, shape: Shape| SceneObject { name: Some(name.into()), albedo: BENCH_ALBEDO, texture: None, shape };
    let (description, objects) = match object {
        BenchObject::Plane => (
            "paper bench: matte plane 400 x 300 mm facing the sensor, centre 500 mm out on +x",
            vec![obj(
                "plane",
                Shape::Rectangle {
                    centre_mm: [500.0, 0.0, 0.0],
                    normal: [-1.0, 0.0, 0.0],
                    up: [0.0, 0.0, 1.0],
                    width_mm: 400.0,
                    height_mm: 300.0,
                },
            )],
        ),
        BenchObject::Cylinder => (
            "paper bench: cylinder r 50 mm, h 200 mm, vertical axis 500 mm out on +x",
            vec![obj(
                "cylinder",
                Shape::Cylinder {
                    base_mm: [500.0, 0.0, -100.0],
                    axis: [0.0, 0.0, 1.0],
                    radius_mm: 50.0,
                    height_mm: 200.0,
                },
            )],
        ),
        BenchObject::Sphere => (
            "paper bench: sphere r 50 mm, centre 500 mm out on +x",
            vec![obj("sphere", Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 })],
        ),
        BenchObject::ConePyramid => {
            let (cx, cy, r) = (450.0, 120.0, 100.0);
            let base = |k: f64| {
                let a = (90.0 + 120.0 * k).to_radians();
                [cx + r * a.cos(), cy + r * a.sin(), -100.0]
            };
            (
                "paper bench: cone (r 60 mm, h 200 mm, apex up) and triangular pyramid, 450 mm out on +x",
                vec![
                    obj(
                        "cone",
                        Shape::Cone {
                            apex_mm: [450.0, -120.0, 100.0],
                            axis: [0.0, 0.0, -1.0],
                            radius_mm: 60.0,
                            height_mm: 200.0,
                        },
                    ),
                    obj("pyramid", Shape::Pyramid { vertices_mm: [base(0.0), base(1.0), base(2.0), [cx, cy, 100.0]] }),
                ],
            )
        }
    };
    SceneFile { description: Some(description.into()), ..SceneFile::new(objects) }
}
