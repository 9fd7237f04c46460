//! `scene.json`: the simulator's scene description (format `omniscan.scene`, version 1).
//!
//! A scene is a list of objects in the world frame (mm, origin at the camera's optical centre,
//! +z up). Each object has a primitive shape (tagged by `type`), a Lambertian `albedo` in [0, 1]
//! and an optional `name`:
//!
//! ```json
//! {
//!   "format": "omniscan.scene", "version": 1,
//!   "objects": [
//!     {"name": "plane", "albedo": 0.8, "type": "rectangle", "centre_mm": [500, 0, 0],
//!      "normal": [-1, 0, 0], "up": [0, 0, 1], "width_mm": 400, "height_mm": 300},
//!     {"type": "sphere", "centre_mm": [500, 200, 0], "radius_mm": 50}
//!   ]
//! }
//! ```
//!
//! Lighting (optional, `lighting`): the ambient light of laser and board frames varies as in
//! real rooms. `level` scales the renderer's ambient light (0.1 a dark room, 3 a bright one);
//! `gradient` makes it change smoothly (by `per_m`, a fraction per metre, along `direction`,
//! from the origin); `patches` are hard-edged pools of light (sun through a window, a lamp):
//! inside a sphere of `radius_mm` about `centre_mm` the ambient light is `gain` times brighter.
//! Any object can carry a `texture` that modulates its albedo: `stripes` (bands across
//! `direction`), `checker` (a 3-D checker) or `blocks` (cubes of random albedo), of `period_mm`
//! and `contrast` (albedo × (1 ± contrast)):
//!
//! ```json
//! "lighting": {"level": 1.5, "gradient": {"direction": [1, 0, 0], "per_m": 0.6},
//!              "patches": [{"centre_mm": [600, -300, 200], "radius_mm": 250, "gain": 2.5}]},
//! "objects": [{"type": "room", "centre_mm": [0, 0, 300], "size_mm": [1600, 1600, 1200],
//!              "texture": {"pattern": "stripes", "period_mm": 6, "contrast": 0.4}}]
//! ```
//!
//! Planar frames (rectangle, checkerboard): `normal` is the side the face looks to, `up` the
//! in-plane "up" (need not be exactly perpendicular to `normal`; it is orthogonalised). The face's
//! x axis (width, checkerboard columns) is `up × normal`, i.e. to the right for a viewer facing
//! the face. Values are checked by the simulator when it builds the scene (positive sizes,
//! non-zero directions, albedo in [0, 1]); this module only defines the file.

use crate::Versioned;
use serde::{Deserialize, Serialize};

fn default_albedo() -> f64 {
    0.8
}

fn default_dark_albedo() -> f64 {
    0.05
}

/// `scene.json`: a list of objects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub format: String,
    pub version: u32,
    /// Free text: what the scene is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// How the ambient light varies (default: uniform, as rendered).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lighting: Option<Lighting>,
    pub objects: Vec<SceneObject>,
}

fn one() -> f64 {
    1.0
}

fn z_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// The ambient light across the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lighting {
    /// Ambient light relative to the renderer's (1 = as rendered).
    #[serde(default = "one")]
    pub level: f64,
    /// A smooth change of the level across the room.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradient: Option<Gradient>,
    /// Hard-edged pools of brighter light.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub patches: Vec<LightPatch>,
}

/// The ambient level changes by the fraction `per_m` per metre along `direction` (from the
/// origin; never below zero).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gradient {
    pub direction: [f64; 3],
    pub per_m: f64,
}

/// A sphere inside which the ambient light is `gain` times brighter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightPatch {
    pub centre_mm: [f64; 3],
    pub radius_mm: f64,
    pub gain: f64,
}

/// An albedo pattern on an object's surface (a solid texture: the pattern of 3-D space the
/// surface cuts through).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Texture {
    pub pattern: TexturePattern,
    /// Period of the pattern (mm): a pair of bands, two checker cells, or one block.
    pub period_mm: f64,
    /// Albedo × (1 ± contrast), in [0, 1].
    pub contrast: f64,
    /// For stripes: the bands run across this direction (default z: horizontal bands).
    #[serde(default = "z_axis")]
    pub direction: [f64; 3],
}

/// Texture patterns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TexturePattern {
    Stripes,
    Checker,
    Blocks,
}

impl Versioned for SceneFile {
    const FORMAT: &'static str = "omniscan.scene";
    const VERSION: u32 = 1;

    fn check(&self) -> Result<(), String> {
        self.validate()
    }
}

impl SceneFile {
    /// A scene with the given objects.
    pub fn new(objects: Vec<SceneObject>) -> Self {
        SceneFile { format: Self::FORMAT.into(), version: Self::VERSION, description: None, lighting: None, objects }
    }

    /// Checks every object's sizes (positive, finite, boards within
    /// [`omni_model::limits::MAX_BOARD_CORNERS`]) and positions (finite); the message names
    /// the object (`objects[i] (kind "name")`) and the field.
    pub fn validate(&self) -> Result<(), String> {
        for (i, o) in self.objects.iter().enumerate() {
            o.shape.validate().map_err(|m| match &o.name {
                Some(n) => format!("objects[{i}] ({} \"{n}\"): {m}", o.shape.kind()),
                None => format!("objects[{i}] ({}): {m}", o.shape.kind()),
            })?;
        }
        Ok(())
    }
}

/// One object: a shape with a Lambertian albedo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneObject {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Diffuse reflectance in [0, 1] (default 0.8, matte white paint). For a checkerboard this
    /// is the albedo of the white squares and margin.
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// An albedo pattern (default: plain).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Texture>,
    #[serde(flatten)]
    pub shape: Shape,
}

impl SceneObject {
    /// An unnamed object with albedo 0.8.
    pub fn new(shape: Shape) -> Self {
        SceneObject { name: None, albedo: default_albedo(), texture: None, shape }
    }

    /// The same object with a name.
    pub fn named(mut self, name: &str) -> Self {
        self.name = Some(name.into());
        self
    }
}

/// The primitive shapes, tagged by `type` (lengths mm, angles degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Shape {
    /// A finite plane: `width_mm` along `up × normal`, `height_mm` along `up`, centred at
    /// `centre_mm`. Two-sided.
    Rectangle { centre_mm: [f64; 3], normal: [f64; 3], up: [f64; 3], width_mm: f64, height_mm: f64 },
    /// A solid box with edge lengths `size_mm` along its own x, y, z, turned by `rotation_deg`
    /// (about world x, then y, then z) around its centre.
    Box {
        centre_mm: [f64; 3],
        size_mm: [f64; 3],
        #[serde(default)]
        rotation_deg: [f64; 3],
    },
    /// A solid sphere.
    Sphere { centre_mm: [f64; 3], radius_mm: f64 },
    /// A closed solid cylinder from `base_mm` along `axis` for `height_mm`.
    Cylinder { base_mm: [f64; 3], axis: [f64; 3], radius_mm: f64, height_mm: f64 },
    /// A closed solid right circular cone: apex at `apex_mm`, axis from the apex towards the base
    /// disc of radius `radius_mm` at distance `height_mm`.
    Cone { apex_mm: [f64; 3], axis: [f64; 3], radius_mm: f64, height_mm: f64 },
    /// A triangular pyramid (tetrahedron) given by its four vertices.
    Pyramid { vertices_mm: [[f64; 3]; 4] },
    /// A planar checkerboard: (`inner_cols` + 1) × (`inner_rows` + 1) squares of side
    /// `square_mm` with a white margin of `margin_mm`, centred at `centre_mm`, printed on the side
    /// `normal` looks to (the back is plain grey). The top-left square (seen from the front, `up`
    /// is up) is black. Board frame (OpenCV convention): origin at the top-left inner corner,
    /// x along `up × normal`, y = −`up`, z = −`normal`.
    Checkerboard {
        centre_mm: [f64; 3],
        normal: [f64; 3],
        up: [f64; 3],
        square_mm: f64,
        inner_cols: u32,
        inner_rows: u32,
        #[serde(default)]
        margin_mm: f64,
        /// Albedo of the black squares (default 0.05).
        #[serde(default = "default_dark_albedo")]
        dark_albedo: f64,
    },
    /// A room: the inside of an axis-aligned box (floor, ceiling and four walls), centred at
    /// `centre_mm` with inner dimensions `size_mm`.
    Room { centre_mm: [f64; 3], size_mm: [f64; 3] },
}

impl Shape {
    /// Checks sizes and positions (see [`SceneFile::validate`]).
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err(format!("{name} must be a positive number, got {v}")) }
        };
        let finite = |name: &str, v: &[f64; 3]| {
            if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(format!("{name} must be finite")) }
        };
        let length = |v: &[f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let direction = |name: &str, v: &[f64; 3]| {
            finite(name, v)?;
            if length(v) > 1e-12 { Ok(()) } else { Err(format!("{name} must be a non-zero direction")) }
        };
        // A face's `up` fixes its turn about `normal`: it must not run along it.
        let face = |normal: &[f64; 3], up: &[f64; 3]| {
            direction("normal", normal)?;
            direction("up", up)?;
            let [a, b] = [normal, up];
            let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            if length(&cross) > 1e-9 * length(a) * length(b) {
                Ok(())
            } else {
                Err("up must not be parallel to normal".to_string())
            }
        };
        match self {
            Shape::Rectangle { centre_mm, normal, up, width_mm, height_mm } => {
                finite("centre_mm", centre_mm)?;
                face(normal, up)?;
                positive("width_mm", *width_mm)?;
                positive("height_mm", *height_mm)
            }
            Shape::Box { centre_mm, size_mm, rotation_deg } => {
                finite("centre_mm", centre_mm)?;
                finite("rotation_deg", rotation_deg)?;
                (0..3).try_for_each(|k| positive(&format!("size_mm[{k}]"), size_mm[k]))
            }
            Shape::Room { centre_mm, size_mm } => {
                finite("centre_mm", centre_mm)?;
                (0..3).try_for_each(|k| positive(&format!("size_mm[{k}]"), size_mm[k]))
            }
            Shape::Sphere { centre_mm, radius_mm } => {
                finite("centre_mm", centre_mm)?;
                positive("radius_mm", *radius_mm)
            }
            Shape::Cylinder { base_mm: p, axis, radius_mm, height_mm }
            | Shape::Cone { apex_mm: p, axis, radius_mm, height_mm } => {
                finite(if matches!(self, Shape::Cone { .. }) { "apex_mm" } else { "base_mm" }, p)?;
                direction("axis", axis)?;
                positive("radius_mm", *radius_mm)?;
                positive("height_mm", *height_mm)
            }
            Shape::Pyramid { vertices_mm } => {
                if vertices_mm.iter().all(|v| v.iter().all(|x| x.is_finite())) {
                    Ok(())
                } else {
                    Err("vertices_mm must be finite".into())
                }
            }
            Shape::Checkerboard { centre_mm, normal, up, square_mm, inner_cols, inner_rows, margin_mm, .. } => {
                finite("centre_mm", centre_mm)?;
                face(normal, up)?;
                positive("square_mm", *square_mm)?;
                let max = omni_model::limits::MAX_BOARD_CORNERS;
                for (name, v) in [("inner_cols", *inner_cols), ("inner_rows", *inner_rows)] {
                    if !(1..=max).contains(&v) {
                        return Err(format!("{name} must be in 1..={max}, got {v}"));
                    }
                }
                if margin_mm.is_finite() && *margin_mm >= 0.0 {
                    Ok(())
                } else {
                    Err(format!("margin_mm must be non-negative, got {margin_mm}"))
                }
            }
        }
    }

    /// The `type` tag of the shape (for messages).
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Rectangle { .. } => "rectangle",
            Shape::Box { .. } => "box",
            Shape::Sphere { .. } => "sphere",
            Shape::Cylinder { .. } => "cylinder",
            Shape::Cone { .. } => "cone",
            Shape::Pyramid { .. } => "pyramid",
            Shape::Checkerboard { .. } => "checkerboard",
            Shape::Room { .. } => "room",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::docs::parse_doc;

    /// A face needs a direction for its normal and an `up` off it; an axis must be a direction:
    /// every reader of scene.json refuses them (omni-eval compare once counted every point stray).
    #[test]
    fn directions_must_be_directions() {
        let rectangle = |normal: [f64; 3], up: [f64; 3]| Shape::Rectangle {
            centre_mm: [500.0, 0.0, 0.0],
            normal,
            up,
            width_mm: 100.0,
            height_mm: 100.0,
        };
        let z = [0.0, 0.0, 1.0];
        assert!(rectangle([-1.0, 0.0, 0.0], z).validate().is_ok());
        assert!(rectangle([0.0; 3], z).validate().unwrap_err().contains("normal must be a non-zero direction"));
        assert!(rectangle([0.0, 0.0, -2.0], z).validate().unwrap_err().contains("up must not be parallel"));
        let cylinder = Shape::Cylinder { base_mm: [0.0; 3], axis: [0.0; 3], radius_mm: 5.0, height_mm: 5.0 };
        assert!(cylinder.validate().unwrap_err().contains("axis must be a non-zero direction"));
    }

    #[test]
    fn scene_round_trips_and_names_unknown_primitives() {
        let scene = SceneFile::new(vec![
            SceneObject::new(Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 }).named("ball"),
            SceneObject::new(Shape::Room { centre_mm: [0.0; 3], size_mm: [4000.0, 3000.0, 2500.0] }),
        ]);
        let text = serde_json::to_vec(&scene).unwrap();
        let back: SceneFile = parse_doc(&text, "scene.json").unwrap();
        assert_eq!(back, scene);
        let bad = String::from_utf8(text).unwrap().replace("\"sphere\"", "\"torus\"");
        let e = parse_doc::<SceneFile>(bad.as_bytes(), "scene.json").unwrap_err().to_string();
        assert!(e.contains("scene.json") && e.contains("torus"), "{e}");
    }

    #[test]
    fn bad_sizes_are_refused_naming_the_object() {
        let scene = SceneFile::new(vec![
            SceneObject::new(Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 }),
            SceneObject::new(Shape::Rectangle {
                centre_mm: [700.0, 0.0, 0.0],
                normal: [-1.0, 0.0, 0.0],
                up: [0.0, 0.0, 1.0],
                width_mm: -200.0,
                height_mm: 100.0,
            })
            .named("wall"),
        ]);
        let text = serde_json::to_vec(&scene).unwrap();
        let e = parse_doc::<SceneFile>(&text, "scene.json").unwrap_err().to_string();
        assert!(
            e.contains("scene.json") && e.contains("objects[1] (rectangle \"wall\")") && e.contains("width_mm"),
            "{e}"
        );
        let board = SceneFile::new(vec![SceneObject::new(Shape::Checkerboard {
            centre_mm: [500.0, 0.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            square_mm: 30.0,
            inner_cols: 100_000,
            inner_rows: 6,
            margin_mm: 0.0,
            dark_albedo: 0.05,
        })]);
        let e = board.validate().unwrap_err();
        assert!(e.contains("inner_cols must be in 1..=1000"), "{e}");
    }
}
