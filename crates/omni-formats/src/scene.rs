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
    pub objects: Vec<SceneObject>,
}

impl Versioned for SceneFile {
    const FORMAT: &'static str = "omniscan.scene";
    const VERSION: u32 = 1;
}

impl SceneFile {
    /// A scene with the given objects.
    pub fn new(objects: Vec<SceneObject>) -> Self {
        SceneFile { format: Self::FORMAT.into(), version: Self::VERSION, description: None, objects }
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
    #[serde(flatten)]
    pub shape: Shape,
}

impl SceneObject {
    /// An unnamed object with albedo 0.8.
    pub fn new(shape: Shape) -> Self {
        SceneObject { name: None, albedo: default_albedo(), shape }
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
}
