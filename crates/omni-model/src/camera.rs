use omni_geom::{Point3, Ray, Vector2};

/// The region of the image that sees the scene through the mirror: an annulus around `centre`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MirrorCircle {
    /// Image point (px) of the mirror axis.
    pub centre: Vector2<f64>,
    /// Radius (px) below which the camera sees itself (blind centre).
    pub inner_radius: f64,
    /// Radius (px) of the mirror rim.
    pub outer_radius: f64,
}

impl MirrorCircle {
    /// Whether a pixel lies in the annulus.
    pub fn contains(&self, px: &Vector2<f64>) -> bool {
        let r = (px - self.centre).norm();
        r >= self.inner_radius && r <= self.outer_radius
    }
}

/// A calibrated (or ideal) receiver: pixels ↔ world rays.
///
/// Pixel coordinates: x right, y down, (0, 0) at the centre of the top-left pixel. Rays are in
/// the world frame (mm). For a central camera every ray starts at the single viewpoint.
pub trait CameraModel: Send + Sync + std::fmt::Debug {
    /// Image width and height in pixels.
    fn image_size(&self) -> (u32, u32);

    /// The world ray seen by a pixel, or `None` if the pixel does not see the scene through the
    /// mirror (outside the rim, in the blind centre, or outside the image).
    fn pixel_to_ray(&self, px: &Vector2<f64>) -> Option<Ray>;

    /// The pixel at which a world point appears, or `None` if it is not visible through the
    /// mirror (beyond the rim, in the blind centre, behind the mirror or outside the image).
    fn point_to_pixel(&self, p: &Point3<f64>) -> Option<Vector2<f64>>;

    /// The valid mirror annulus in the image.
    fn mirror_circle(&self) -> MirrorCircle;

    /// Whether the pixel lies inside the image bounds (pixel edges at −0.5 and size − 0.5).
    fn in_image(&self, px: &Vector2<f64>) -> bool {
        let (w, h) = self.image_size();
        px.x >= -0.5 && px.y >= -0.5 && px.x <= w as f64 - 0.5 && px.y <= h as f64 - 0.5
    }
}
