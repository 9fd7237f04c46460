//! Image processing for omniscan: laser-stripe centres ([`stripe`]), checkerboard corners
//! ([`corners`]) and image I/O helpers ([`image_io`]).

pub mod colour;
pub mod corners;
pub mod image_io;
pub mod rim;
pub mod stripe;

/// Variance (px²) of a pixel's area as a blur along any direction: a unit square's, 1/12.
pub(crate) const PIXEL_AREA_VARIANCE_PX2: f64 = 1.0 / 12.0;
