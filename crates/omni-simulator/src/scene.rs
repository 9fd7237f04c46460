//! Scene geometry: primitives built from [`omni_formats::scene`] and ray casting.
//!
//! All shapes are opaque Lambertian reflectors. Ray casting returns the first hit with its
//! outward geometric normal and the albedo at the hit (checkerboards and textures vary across
//! the face). The scene's lighting gives the ambient light's level at any point.

use nalgebra::Translation3;
use omni_formats::scene::{Lighting, SceneFile, SceneObject, Shape, Texture, TexturePattern};
use omni_geom::{Isometry3, Point3, Rotation3, UnitQuaternion, Vector3};
use std::path::Path;

/// A ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray direction (mm).
    pub t: f64,
    pub point: Point3<f64>,
    /// Outward unit normal of the surface (for a room: pointing into the room).
    pub normal: Vector3<f64>,
    /// Diffuse reflectance at the hit.
    pub albedo: f64,
    /// Index of the object in the scene.
    pub object: usize,
    /// For checkerboards: which face and square colour was hit (used to find edges); 0 otherwise.
    pub pattern: u8,
    /// Which texture cell and light patches the hit is in (changes across every hard edge of
    /// albedo or light, so that the renderer supersamples there).
    pub class: u32,
}

/// A primitive in its local frame (`local` maps local → world).
#[derive(Debug, Clone)]
enum Prim {
    /// Rectangle in local z = 0, |x| ≤ hw, |y| ≤ hh; local +z = face normal.
    Rect {
        hw: f64,
        hh: f64,
    },
    /// Axis-aligned box |x| ≤ h.x etc.; `inside` = room (seen from inside).
    Cuboid {
        half: Vector3<f64>,
        inside: bool,
    },
    Sphere {
        r: f64,
    },
    /// Cylinder around local z from z = 0 to z = h.
    Cylinder {
        r: f64,
        h: f64,
    },
    /// Cone with apex at the origin, axis +z, base radius r at z = h.
    Cone {
        r: f64,
        h: f64,
    },
    /// Tetrahedron (world coordinates; `local` is the identity).
    Tetra {
        v: [Point3<f64>; 4],
    },
    /// Checkerboard in local z = 0 (board frame: origin at the first inner corner, x right,
    /// y down, printed face towards local −z).
    Board {
        cols: u32,
        rows: u32,
        square: f64,
        margin: f64,
        dark: f64,
    },
}

#[derive(Debug, Clone)]
struct Object {
    prim: Prim,
    local: Isometry3<f64>,
    albedo: f64,
    texture: Option<SolidTexture>,
}

/// A texture with its direction normalised.
#[derive(Debug, Clone)]
struct SolidTexture {
    pattern: TexturePattern,
    period: f64,
    contrast: f64,
    direction: Vector3<f64>,
}

impl SolidTexture {
    /// The albedo factor at `p` (world, mm) and the cell it belongs to.
    fn at(&self, p: &Point3<f64>) -> (f64, u32) {
        let cell = |x: f64| (x / (0.5 * self.period)).floor() as i64;
        let (sign, id) = match self.pattern {
            TexturePattern::Stripes => {
                let k = cell(p.coords.dot(&self.direction));
                (if k.rem_euclid(2) == 0 { 1.0 } else { -1.0 }, k as u64)
            }
            TexturePattern::Checker => {
                let (i, j, k) = (cell(p.x), cell(p.y), cell(p.z));
                (if (i + j + k).rem_euclid(2) == 0 { 1.0 } else { -1.0 }, mix3(i, j, k))
            }
            TexturePattern::Blocks => {
                let c = |x: f64| (x / self.period).floor() as i64;
                let id = mix3(c(p.x), c(p.y), c(p.z));
                (2.0 * (id >> 11) as f64 / (1u64 << 53) as f64 - 1.0, id)
            }
        };
        (1.0 + self.contrast * sign, (id ^ (id >> 32)) as u32)
    }
}

fn mix3(i: i64, j: i64, k: i64) -> u64 {
    use omni_geom::rng::mix;
    mix(mix(mix(i as u64) ^ j as u64) ^ k as u64)
}

/// The scene's ambient lighting, checked.
#[derive(Debug, Clone)]
struct AmbientField {
    level: f64,
    gradient: Option<(Vector3<f64>, f64)>,
    patches: Vec<(Point3<f64>, f64, f64)>,
}

/// A scene ready for ray casting.
#[derive(Debug, Clone)]
pub struct Scene {
    objects: Vec<Object>,
    ambient: Option<AmbientField>,
    file: SceneFile,
}

/// Albedo of a checkerboard's back (plain grey board material).
const BOARD_BACK_ALBEDO: f64 = 0.5;

impl Scene {
    /// Reads and validates a `scene.json` (`-` = stdin); errors name the file and the object.
    pub fn load(path: &Path) -> omni_formats::Result<Scene> {
        let file: SceneFile = omni_formats::read_doc(path)?;
        let name = omni_formats::io::display_name(path, "stdin");
        Scene::from_file(file).map_err(|m| omni_formats::Error::new(name, "", m))
    }

    /// Builds the scene; the error names the object (`objects[i] "name"`) and field at fault.
    pub fn from_file(file: SceneFile) -> Result<Scene, String> {
        let objects = file
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                build_object(o).map_err(|m| match &o.name {
                    Some(n) => format!("objects[{i}] ({} \"{n}\"): {m}", o.shape.kind()),
                    None => format!("objects[{i}] ({}): {m}", o.shape.kind()),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let ambient = file.lighting.as_ref().map(build_lighting).transpose().map_err(|m| format!("lighting: {m}"))?;
        Ok(Scene { objects, ambient, file })
    }

    /// The ambient light at `p` relative to the renderer's (1 without lighting).
    pub fn ambient_factor(&self, p: &Point3<f64>) -> f64 {
        let Some(a) = &self.ambient else { return 1.0 };
        let mut f = a.level;
        if let Some((dir, per_m)) = &a.gradient {
            f *= (1.0 + per_m * p.coords.dot(dir) / 1000.0).max(0.0);
        }
        for (c, r, gain) in &a.patches {
            if (p - c).norm_squared() <= r * r {
                f *= gain;
            }
        }
        f
    }

    /// Bits of the light patches `p` is in.
    fn patch_bits(&self, p: &Point3<f64>) -> u32 {
        let Some(a) = &self.ambient else { return 0 };
        a.patches
            .iter()
            .enumerate()
            .filter(|(_, (c, r, _))| (p - c).norm_squared() <= r * r)
            .fold(0, |b, (i, _)| b | 1u32.rotate_left(i as u32))
    }

    /// The description this scene was built from.
    pub fn file(&self) -> &SceneFile {
        &self.file
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// The first hit along `origin + t·dir` (`dir` unit) with `t_min < t < t_max`.
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, obj) in self.objects.iter().enumerate() {
            let limit = best.map_or(t_max, |b| b.t);
            if let Some(h) = obj.intersect(origin, dir, t_min, limit) {
                best = Some(Hit { object: i, ..h });
            }
        }
        let mut hit = best?;
        if let Some(t) = &self.objects[hit.object].texture {
            let (factor, cell) = t.at(&hit.point);
            hit.albedo = (hit.albedo * factor).clamp(0.0, 1.0);
            hit.class = cell;
        }
        hit.class ^= self.patch_bits(&hit.point).rotate_left(16);
        Some(hit)
    }

    /// Whether anything blocks the open segment from `a` to `b` (ends excluded by `eps` mm).
    pub fn occluded(&self, a: &Point3<f64>, b: &Point3<f64>, eps: f64) -> bool {
        let d = b - a;
        let len = d.norm();
        if len <= 2.0 * eps {
            return false;
        }
        let dir = d / len;
        self.objects.iter().any(|o| o.intersect(a, &dir, eps, len - eps).is_some())
    }

    /// The checkerboards of the scene: (object index, board → world pose, inner corners in the
    /// board frame, row-major: index = row · inner_cols + col).
    pub fn checkerboards(&self) -> Vec<(usize, Isometry3<f64>, Vec<Point3<f64>>)> {
        self.objects
            .iter()
            .enumerate()
            .filter_map(|(i, o)| match o.prim {
                Prim::Board { cols, rows, square, .. } => Some((i, o.local, board_corners(cols, rows, square))),
                _ => None,
            })
            .collect()
    }
}

/// Inner corners of a board in its own frame (row-major, z = 0).
pub fn board_corners(cols: u32, rows: u32, square: f64) -> Vec<Point3<f64>> {
    (0..rows).flat_map(|r| (0..cols).map(move |c| Point3::new(c as f64 * square, r as f64 * square, 0.0))).collect()
}

fn vec3(name: &str, v: [f64; 3]) -> Result<Vector3<f64>, String> {
    let v = Vector3::from(v);
    if !v.iter().all(|x| x.is_finite()) {
        return Err(format!("{name} must be finite"));
    }
    Ok(v)
}

fn direction(name: &str, v: [f64; 3]) -> Result<Vector3<f64>, String> {
    let v = vec3(name, v)?;
    v.try_normalize(1e-12).ok_or_else(|| format!("{name} must be a non-zero direction"))
}

fn positive(name: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 { Ok(v) } else { Err(format!("{name} must be a positive number, got {v}")) }
}

/// A frame whose local z is `z` (unit), with origin `origin`.
fn frame_z(origin: Vector3<f64>, z: &Vector3<f64>) -> Isometry3<f64> {
    let rot = UnitQuaternion::rotation_between(&Vector3::z(), z)
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
    Isometry3::from_parts(Translation3::from(origin), rot)
}

/// A planar frame from `normal` and `up`: local x = up × normal, y = up, z = normal.
fn face_frame(centre: Vector3<f64>, normal: &Vector3<f64>, up: &Vector3<f64>) -> Result<Isometry3<f64>, String> {
    let up_perp = up - normal * normal.dot(up);
    let y = up_perp.try_normalize(1e-9).ok_or("up must not be parallel to normal")?;
    let x = y.cross(normal);
    let rot = Rotation3::from_basis_unchecked(&[x, y, *normal]);
    Ok(Isometry3::from_parts(Translation3::from(centre), UnitQuaternion::from_rotation_matrix(&rot)))
}

fn build_lighting(l: &Lighting) -> Result<AmbientField, String> {
    if !(l.level.is_finite() && l.level >= 0.0) {
        return Err(format!("level must be a non-negative number, got {}", l.level));
    }
    let gradient = match &l.gradient {
        Some(g) => {
            if !g.per_m.is_finite() {
                return Err(format!("gradient.per_m must be finite, got {}", g.per_m));
            }
            Some((direction("gradient.direction", g.direction)?, g.per_m))
        }
        None => None,
    };
    if l.patches.len() > 32 {
        return Err(format!("at most 32 patches, got {}", l.patches.len()));
    }
    let patches = l
        .patches
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = vec3(&format!("patches[{i}].centre_mm"), p.centre_mm)?;
            let r = positive(&format!("patches[{i}].radius_mm"), p.radius_mm)?;
            if !(p.gain.is_finite() && p.gain >= 0.0) {
                return Err(format!("patches[{i}].gain must be a non-negative number, got {}", p.gain));
            }
            Ok((Point3::from(c), r, p.gain))
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok(AmbientField { level: l.level, gradient, patches })
}

fn build_texture(t: &Texture) -> Result<SolidTexture, String> {
    let period = positive("texture.period_mm", t.period_mm)?;
    if !(t.contrast.is_finite() && (0.0..=1.0).contains(&t.contrast)) {
        return Err(format!("texture.contrast must be in [0, 1], got {}", t.contrast));
    }
    let direction = direction("texture.direction", t.direction)?;
    Ok(SolidTexture { pattern: t.pattern, period, contrast: t.contrast, direction })
}

fn build_object(o: &SceneObject) -> Result<Object, String> {
    if !(o.albedo.is_finite() && (0.0..=1.0).contains(&o.albedo)) {
        return Err(format!("albedo must be in [0, 1], got {}", o.albedo));
    }
    let texture = o.texture.as_ref().map(build_texture).transpose()?;
    let (prim, local) = match &o.shape {
        Shape::Rectangle { centre_mm, normal, up, width_mm, height_mm } => {
            let n = direction("normal", *normal)?;
            let frame = face_frame(vec3("centre_mm", *centre_mm)?, &n, &direction("up", *up)?)?;
            let hw = positive("width_mm", *width_mm)? / 2.0;
            (Prim::Rect { hw, hh: positive("height_mm", *height_mm)? / 2.0 }, frame)
        }
        Shape::Box { centre_mm, size_mm, rotation_deg } => {
            let half = Vector3::new(
                positive("size_mm[0]", size_mm[0])?,
                positive("size_mm[1]", size_mm[1])?,
                positive("size_mm[2]", size_mm[2])?,
            ) / 2.0;
            let r = vec3("rotation_deg", *rotation_deg)?.map(f64::to_radians);
            let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), r.z)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), r.y)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), r.x);
            (Prim::Cuboid { half, inside: false }, Isometry3::from_parts(vec3("centre_mm", *centre_mm)?.into(), rot))
        }
        Shape::Sphere { centre_mm, radius_mm } => (
            Prim::Sphere { r: positive("radius_mm", *radius_mm)? },
            Isometry3::translation(centre_mm[0], centre_mm[1], centre_mm[2]),
        ),
        Shape::Cylinder { base_mm, axis, radius_mm, height_mm } => (
            Prim::Cylinder { r: positive("radius_mm", *radius_mm)?, h: positive("height_mm", *height_mm)? },
            frame_z(vec3("base_mm", *base_mm)?, &direction("axis", *axis)?),
        ),
        Shape::Cone { apex_mm, axis, radius_mm, height_mm } => (
            Prim::Cone { r: positive("radius_mm", *radius_mm)?, h: positive("height_mm", *height_mm)? },
            frame_z(vec3("apex_mm", *apex_mm)?, &direction("axis", *axis)?),
        ),
        Shape::Pyramid { vertices_mm } => {
            let v = [0, 1, 2, 3].map(|i| Point3::from(Vector3::from(vertices_mm[i])));
            if !v.iter().all(|p| p.coords.iter().all(|x| x.is_finite())) {
                return Err("vertices_mm must be finite".into());
            }
            let vol = (v[1] - v[0]).cross(&(v[2] - v[0])).dot(&(v[3] - v[0])) / 6.0;
            if !(vol.abs() > 1e-6) {
                return Err("vertices_mm must not be coplanar (zero volume)".into());
            }
            (Prim::Tetra { v }, Isometry3::identity())
        }
        Shape::Checkerboard { centre_mm, normal, up, square_mm, inner_cols, inner_rows, margin_mm, dark_albedo } => {
            let square = positive("square_mm", *square_mm)?;
            if *inner_cols < 1 || *inner_rows < 1 {
                return Err("inner_cols and inner_rows must be at least 1".into());
            }
            if !(margin_mm.is_finite() && *margin_mm >= 0.0) {
                return Err(format!("margin_mm must be non-negative, got {margin_mm}"));
            }
            if !(dark_albedo.is_finite() && (0.0..=1.0).contains(dark_albedo)) {
                return Err(format!("dark_albedo must be in [0, 1], got {dark_albedo}"));
            }
            let n = direction("normal", *normal)?;
            let face = face_frame(vec3("centre_mm", *centre_mm)?, &n, &direction("up", *up)?)?;
            // Board frame: x = face x, y = −up, z = −normal; origin at the top-left inner corner.
            let flip = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
            let centre_in_board =
                Vector3::new(*inner_cols as f64 - 1.0, *inner_rows as f64 - 1.0, 0.0) * (square / 2.0);
            let board =
                face * Isometry3::from_parts(Translation3::identity(), flip) * Translation3::from(-centre_in_board);
            let prim =
                Prim::Board { cols: *inner_cols, rows: *inner_rows, square, margin: *margin_mm, dark: *dark_albedo };
            (prim, board)
        }
        Shape::Room { centre_mm, size_mm } => {
            let half = Vector3::new(
                positive("size_mm[0]", size_mm[0])?,
                positive("size_mm[1]", size_mm[1])?,
                positive("size_mm[2]", size_mm[2])?,
            ) / 2.0;
            let c = vec3("centre_mm", *centre_mm)?;
            (Prim::Cuboid { half, inside: true }, Isometry3::translation(c.x, c.y, c.z))
        }
    };
    Ok(Object { prim, local, albedo: o.albedo, texture })
}

/// A local-frame hit before it is mapped back to the world.
struct LocalHit {
    t: f64,
    normal: Vector3<f64>,
    albedo: f64,
    pattern: u8,
}

impl Object {
    fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>, t_min: f64, t_max: f64) -> Option<Hit> {
        let o = self.local.inverse_transform_point(origin);
        let d = self.local.inverse_transform_vector(dir);
        let h = self.intersect_local(&o, &d, t_min, t_max)?;
        let normal = self.local.transform_vector(&h.normal);
        Some(Hit {
            t: h.t,
            point: origin + dir * h.t,
            normal,
            albedo: h.albedo,
            object: 0,
            pattern: h.pattern,
            class: 0,
        })
    }

    fn intersect_local(&self, o: &Point3<f64>, d: &Vector3<f64>, t0: f64, t1: f64) -> Option<LocalHit> {
        let a = self.albedo;
        let plain = |t: f64, normal: Vector3<f64>| LocalHit { t, normal, albedo: a, pattern: 0 };
        match &self.prim {
            Prim::Rect { hw, hh } => {
                let t = plane_z(o, d, t0, t1)?;
                let p = o + d * t;
                (p.x.abs() <= *hw && p.y.abs() <= *hh).then(|| plain(t, Vector3::z()))
            }
            Prim::Cuboid { half, inside } => {
                let (t, n) = slab(o, d, half, t0, t1, *inside)?;
                Some(plain(t, n))
            }
            Prim::Sphere { r } => {
                let b = o.coords.dot(d);
                let c = o.coords.norm_squared() - r * r;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                let t = [-b - s, -b + s].into_iter().find(|t| *t > t0 && *t < t1)?;
                Some(plain(t, (o + d * t).coords / *r))
            }
            Prim::Cylinder { r, h } => cylinder(o, d, *r, *h, t0, t1).map(|(t, n)| plain(t, n)),
            Prim::Cone { r, h } => cone(o, d, *r, *h, t0, t1).map(|(t, n)| plain(t, n)),
            Prim::Tetra { v } => tetra(v, o, d, t0, t1).map(|(t, n)| plain(t, n)),
            Prim::Board { cols, rows, square, margin, dark } => {
                let t = plane_z(o, d, t0, t1)?;
                let p = o + d * t;
                let (x0, x1) = (-square - margin, *cols as f64 * square + margin);
                let (y0, y1) = (-square - margin, *rows as f64 * square + margin);
                if p.x < x0 || p.x > x1 || p.y < y0 || p.y > y1 {
                    return None;
                }
                // The printed face looks to local −z; seen from +z it is the plain back.
                if o.z > 0.0 {
                    return Some(LocalHit { t, normal: Vector3::z(), albedo: BOARD_BACK_ALBEDO, pattern: 1 });
                }
                let (i, j) = ((p.x / square).floor() + 1.0, (p.y / square).floor() + 1.0);
                let in_squares = i >= 0.0 && j >= 0.0 && i <= *cols as f64 && j <= *rows as f64;
                let black = in_squares && (i as i64 + j as i64) % 2 == 0;
                let (albedo, pattern) = if black { (dark * 1.0, 2) } else { (a, 3) };
                Some(LocalHit { t, normal: -Vector3::z(), albedo, pattern })
            }
        }
    }
}

/// Ray hit with the local plane z = 0.
fn plane_z(o: &Point3<f64>, d: &Vector3<f64>, t0: f64, t1: f64) -> Option<f64> {
    if d.z.abs() < 1e-15 {
        return None;
    }
    let t = -o.z / d.z;
    (t > t0 && t < t1).then_some(t)
}

/// Slab test for an axis-aligned box; `inside` returns the exit (the room's walls seen from
/// within) with the normal pointing inwards.
fn slab(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    half: &Vector3<f64>,
    t0: f64,
    t1: f64,
    inside: bool,
) -> Option<(f64, Vector3<f64>)> {
    let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut n_near, mut n_far) = (Vector3::zeros(), Vector3::zeros());
    for k in 0..3 {
        if d[k].abs() < 1e-15 {
            if o[k].abs() > half[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-half[k] - o[k]) / d[k], (half[k] - o[k]) / d[k]);
        let (ta, tb) = if a < b { (a, b) } else { (b, a) };
        let mut axis = Vector3::zeros();
        axis[k] = 1.0;
        if ta > near {
            near = ta;
            n_near = -axis * d[k].signum();
        }
        if tb < far {
            far = tb;
            n_far = -axis * d[k].signum();
        }
    }
    if near > far {
        return None;
    }
    if !inside && near > t0 && near < t1 {
        return Some((near, n_near));
    }
    if far > t0 && far < t1 {
        // Exit face: for a solid box this is its back (seen only from inside the box).
        return Some((far, if inside { n_far } else { -n_far }));
    }
    None
}

fn cylinder(o: &Point3<f64>, d: &Vector3<f64>, r: f64, h: f64, t0: f64, t1: f64) -> Option<(f64, Vector3<f64>)> {
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let mut consider = |t: f64, n: Vector3<f64>| {
        if t > t0 && t < t1 && best.is_none_or(|b| t < b.0) {
            best = Some((t, n));
        }
    };
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-300 {
        let b = o.x * d.x + o.y * d.y;
        let c = o.x * o.x + o.y * o.y - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let s = disc.sqrt();
            for t in [(-b - s) / a, (-b + s) / a] {
                let p = o + d * t;
                if p.z >= 0.0 && p.z <= h {
                    consider(t, Vector3::new(p.x / r, p.y / r, 0.0));
                }
            }
        }
    }
    for (z, nz) in [(0.0, -1.0), (h, 1.0)] {
        if d.z.abs() > 1e-15 {
            let t = (z - o.z) / d.z;
            let p = o + d * t;
            if p.x * p.x + p.y * p.y <= r * r {
                consider(t, Vector3::new(0.0, 0.0, nz));
            }
        }
    }
    best
}

fn cone(o: &Point3<f64>, d: &Vector3<f64>, r: f64, h: f64, t0: f64, t1: f64) -> Option<(f64, Vector3<f64>)> {
    let k = r / h;
    let k2 = k * k;
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let mut consider = |t: f64, n: Vector3<f64>| {
        if t > t0 && t < t1 && best.is_none_or(|b| t < b.0) {
            best = Some((t, n));
        }
    };
    // x² + y² = k²·z², 0 ≤ z ≤ h.
    let a = d.x * d.x + d.y * d.y - k2 * d.z * d.z;
    let b = o.x * d.x + o.y * d.y - k2 * o.z * d.z;
    let c = o.x * o.x + o.y * o.y - k2 * o.z * o.z;
    let roots: Vec<f64> = if a.abs() > 1e-300 {
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let s = disc.sqrt();
            vec![(-b - s) / a, (-b + s) / a]
        } else {
            vec![]
        }
    } else if b.abs() > 1e-300 {
        vec![-c / (2.0 * b)]
    } else {
        vec![]
    };
    for t in roots {
        let p = o + d * t;
        if p.z >= 0.0 && p.z <= h {
            let rho = p.x.hypot(p.y).max(1e-300);
            consider(t, Vector3::new(p.x / rho, p.y / rho, -k).normalize());
        }
    }
    if d.z.abs() > 1e-15 {
        let t = (h - o.z) / d.z;
        let p = o + d * t;
        if p.x * p.x + p.y * p.y <= r * r {
            consider(t, Vector3::z());
        }
    }
    best
}

fn tetra(v: &[Point3<f64>; 4], o: &Point3<f64>, d: &Vector3<f64>, t0: f64, t1: f64) -> Option<(f64, Vector3<f64>)> {
    let centroid = Point3::from((v[0].coords + v[1].coords + v[2].coords + v[3].coords) / 4.0);
    let faces = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]];
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for f in faces {
        let (a, b, c) = (v[f[0]], v[f[1]], v[f[2]]);
        if let Some(t) = triangle(&a, &b, &c, o, d)
            && t > t0
            && t < t1
            && best.is_none_or(|x| t < x.0)
        {
            let mut n = (b - a).cross(&(c - a)).normalize();
            if n.dot(&(a - centroid)) < 0.0 {
                n = -n;
            }
            best = Some((t, n));
        }
    }
    best
}

/// Möller–Trumbore ray–triangle intersection (distance along `d`).
fn triangle(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
    let e1 = b - a;
    let e2 = c - a;
    let p = d.cross(&e2);
    let det = e1.dot(&p);
    if det.abs() < 1e-15 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(&p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let v = d.dot(&q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(&q) * inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_formats::scene::SceneObject;

    fn scene(shapes: Vec<Shape>) -> Scene {
        Scene::from_file(SceneFile::new(shapes.into_iter().map(SceneObject::new).collect())).unwrap()
    }

    #[test]
    fn primitives_hit_where_geometry_says() {
        let x = Vector3::x();
        let o = Point3::origin();
        let s = scene(vec![Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 }]);
        assert!((s.cast(&o, &x, 1e-9, 1e9).unwrap().t - 450.0).abs() < 1e-9);
        let s = scene(vec![Shape::Cylinder {
            base_mm: [500.0, 0.0, -100.0],
            axis: [0.0, 0.0, 1.0],
            radius_mm: 50.0,
            height_mm: 200.0,
        }]);
        let h = s.cast(&o, &x, 1e-9, 1e9).unwrap();
        assert!((h.t - 450.0).abs() < 1e-9 && (h.normal + x).norm() < 1e-12);
        let s = scene(vec![Shape::Cone {
            apex_mm: [500.0, 0.0, 100.0],
            axis: [0.0, 0.0, -1.0],
            radius_mm: 50.0,
            height_mm: 200.0,
        }]);
        // At z = 0 the cone's radius is 25 mm.
        assert!((s.cast(&o, &x, 1e-9, 1e9).unwrap().t - 475.0).abs() < 1e-9);
        let s = scene(vec![Shape::Box {
            centre_mm: [500.0, 0.0, 0.0],
            size_mm: [20.0, 100.0, 100.0],
            rotation_deg: [0.0, 0.0, 0.0],
        }]);
        assert!((s.cast(&o, &x, 1e-9, 1e9).unwrap().t - 490.0).abs() < 1e-9);
        let s = scene(vec![Shape::Room { centre_mm: [0.0; 3], size_mm: [2000.0, 2000.0, 2000.0] }]);
        let h = s.cast(&o, &x, 1e-9, 1e9).unwrap();
        assert!((h.t - 1000.0).abs() < 1e-9 && (h.normal + x).norm() < 1e-12);
        let s = scene(vec![Shape::Pyramid {
            vertices_mm: [[400.0, -50.0, -50.0], [400.0, 50.0, -50.0], [400.0, 0.0, 50.0], [500.0, 0.0, 0.0]],
        }]);
        assert!((s.cast(&o, &x, 1e-9, 1e9).unwrap().t - 400.0).abs() < 1e-9);
    }

    #[test]
    fn bad_objects_are_named() {
        let f = SceneFile::new(vec![
            SceneObject::new(Shape::Sphere { centre_mm: [0.0; 3], radius_mm: -1.0 }).named("ball"),
        ]);
        let e = Scene::from_file(f).unwrap_err();
        assert!(e.contains("objects[0]") && e.contains("ball") && e.contains("radius_mm"), "{e}");
    }

    #[test]
    fn checkerboard_frame_follows_opencv_convention() {
        let s = scene(vec![Shape::Checkerboard {
            centre_mm: [500.0, 0.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            square_mm: 20.0,
            inner_cols: 5,
            inner_rows: 3,
            margin_mm: 20.0,
            dark_albedo: 0.05,
        }]);
        let (_, pose, corners) = s.checkerboards().remove(0);
        // Board z points away from the viewer at the origin; first corner top-left seen from it.
        assert!((pose.transform_vector(&Vector3::z()) - Vector3::x()).norm() < 1e-12);
        let first = pose * corners[0];
        assert!((first - Point3::new(500.0, 40.0, 20.0)).norm() < 1e-9, "{first}");
    }
}
