use omni_geom::{Point3, Ray, Vector2, Vector3};

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

    /// Checks that the annulus can be searched in a `width` × `height` frame (px): finite, its
    /// centre within [`MAX_CENTRE_DIAGONALS`] frame diagonals of the frame, and some of it on
    /// the frame. A camera file whose numbers put the mirror far off the image would otherwise
    /// size the search for an image that does not exist.
    pub fn check_in_frame(&self, width: u32, height: u32) -> Result<(), String> {
        let (w, h) = (width as f64, height as f64);
        let describe = || {
            format!(
                "the mirror's annulus (centre ({:.1}, {:.1}) px, radii {:.1}–{:.1} px)",
                self.centre.x, self.centre.y, self.inner_radius, self.outer_radius
            )
        };
        let values = [self.centre.x, self.centre.y, self.inner_radius, self.outer_radius];
        if !values.iter().all(|v| v.is_finite()) || self.inner_radius < 0.0 || self.outer_radius <= self.inner_radius {
            return Err(format!("{}: not finite radii with 0 ≤ inner < outer", describe()));
        }
        let (x, y) = (self.centre.x, self.centre.y);
        if (x - 0.5 * w).hypot(y - 0.5 * h) > MAX_CENTRE_DIAGONALS * w.hypot(h) {
            return Err(format!("{} lies far off the {width} × {height} frame", describe()));
        }
        // The frame's nearest and farthest points from the centre.
        let nearest = (x.clamp(0.0, w) - x).hypot(y.clamp(0.0, h) - y);
        let farthest = x.abs().max((x - w).abs()).hypot(y.abs().max((y - h).abs()));
        if self.outer_radius < nearest || self.inner_radius > farthest {
            return Err(format!("{} does not reach the {width} × {height} frame", describe()));
        }
        Ok(())
    }
}

/// How far (in frame diagonals from the frame's centre) a mirror's centre may lie.
pub const MAX_CENTRE_DIAGONALS: f64 = 10.0;

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

    /// σ (px) of the defocus blur disc (σ = diameter / 4) of the scene point `distance_mm`
    /// along the pixel's ray ([`Self::pixel_to_ray`]) through a lens of `optics` focused at
    /// `optics.focus_mm`; `None` without a focus distance, or where the model does not hold the
    /// physical geometry that sets the focus (the fitted models: Mei, OCam, ...).
    fn defocus_sigma_px(&self, _px: &Vector2<f64>, _distance_mm: f64, _optics: &crate::Optics) -> Option<f64> {
        None
    }

    /// Whether the pixel lies inside the image bounds (pixel edges at −0.5 and size − 0.5).
    fn in_image(&self, px: &Vector2<f64>) -> bool {
        let (w, h) = self.image_size();
        px.x >= -0.5 && px.y >= -0.5 && px.x <= w as f64 - 0.5 && px.y <= h as f64 - 0.5
    }
}

/// What a generic central model (Mei, OCam) defines; [`CentralCamera`] adds what they share:
/// finite-input and annulus checks, one viewpoint for every ray, the parameters precomputed once.
pub trait CentralParams: Clone + std::fmt::Debug + Send + Sync {
    /// Checks that the parameters are finite and meaningful; names the field at fault.
    fn check(&self) -> Result<(), String>;
    /// The intrinsics as the flat vector the maps below take (computed once per camera).
    fn to_intrinsics(&self) -> Vec<f64>;
    /// Image width and height (px).
    fn size_px(&self) -> (u32, u32);
    /// The single viewpoint (mm, world frame).
    fn viewpoint(&self) -> Point3<f64>;
    /// Centre (px) and inner/outer radius (px) of the annulus; outer 0 means the whole image.
    fn annulus_px(&self) -> ([f64; 2], f64, f64);
    /// Viewing direction (any length, camera axes) of a pixel, `None` outside the model's domain.
    fn direction_of(&self, intrinsics: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>>;
    /// Pixel of a viewing direction (any length, camera axes), `None` outside the model's domain.
    fn pixel_of(&self, intrinsics: &[f64], dir: &Vector3<f64>) -> Option<Vector2<f64>>;
}

/// A generic central camera, ready to use ([`crate::MeiCamera`], [`crate::OcamCamera`]).
#[derive(Debug, Clone)]
pub struct CentralCamera<P> {
    params: P,
    intrinsics: Vec<f64>,
}

impl<P: CentralParams> CentralCamera<P> {
    /// Builds the camera; fails with the name of an invalid field.
    pub fn new(params: P) -> Result<Self, String> {
        params.check()?;
        let intrinsics = params.to_intrinsics();
        Ok(CentralCamera { params, intrinsics })
    }

    pub fn params(&self) -> &P {
        &self.params
    }
}

impl<P: CentralParams> CameraModel for CentralCamera<P> {
    fn image_size(&self) -> (u32, u32) {
        self.params.size_px()
    }

    fn pixel_to_ray(&self, px: &Vector2<f64>) -> Option<Ray> {
        if !px.x.is_finite() || !px.y.is_finite() || !self.in_image(px) || !self.mirror_circle().contains(px) {
            return None;
        }
        Some(Ray::new(self.params.viewpoint(), self.params.direction_of(&self.intrinsics, px)?))
    }

    fn point_to_pixel(&self, p: &Point3<f64>) -> Option<Vector2<f64>> {
        if !p.coords.iter().all(|x| x.is_finite()) {
            return None;
        }
        let px = self.params.pixel_of(&self.intrinsics, &(p - self.params.viewpoint()))?;
        (self.in_image(&px) && self.mirror_circle().contains(&px)).then_some(px)
    }

    fn mirror_circle(&self) -> MirrorCircle {
        let (centre, inner, outer) = self.params.annulus_px();
        let (w, h) = self.image_size();
        // A model fitted without a known rim is valid over the whole image.
        let outer = if outer > 0.0 { outer } else { (w as f64).hypot(h as f64) };
        MirrorCircle { centre: Vector2::new(centre[0], centre[1]), inner_radius: inner, outer_radius: outer }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(x: f64, y: f64, inner: f64, outer: f64) -> MirrorCircle {
        MirrorCircle { centre: Vector2::new(x, y), inner_radius: inner, outer_radius: outer }
    }

    /// An annulus on the frame passes, whether it fits inside, spills over the edges or has its
    /// centre off the frame; one beyond the frame, far off it or not an annulus is refused.
    #[test]
    fn an_annulus_is_searchable_only_where_it_meets_the_frame() {
        for ok in [circle(50.0, 50.0, 10.0, 40.0), circle(50.0, 50.0, 0.0, 500.0), circle(-30.0, 50.0, 0.0, 40.0)] {
            assert_eq!(ok.check_in_frame(100, 100), Ok(()), "{ok:?}");
        }
        let refused = [
            (circle(50.0, 50.0, 80.0, 90.0), "does not reach"),
            (circle(-60.0, 50.0, 0.0, 50.0), "does not reach"),
            (circle(5e3, 50.0, 0.0, 6e3), "far off"),
            (circle(50.0, 50.0, 40.0, 10.0), "0 ≤ inner < outer"),
            (circle(f64::NAN, 50.0, 0.0, 10.0), "not finite"),
        ];
        for (bad, why) in refused {
            let err = bad.check_in_frame(100, 100).unwrap_err();
            assert!(err.contains(why) && err.starts_with("the mirror's annulus"), "{bad:?}: {err}");
        }
    }
}
