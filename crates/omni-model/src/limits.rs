//! Upper bounds on every size read from a file or a flag, so that a typo (`inner_cols: 100000`,
//! `--width 2000000000`) is refused with a message naming the field instead of exhausting
//! memory. Each is far beyond any real sensor or board.

/// Largest image width or height (px), for camera models, frames and pictures.
pub const MAX_IMAGE_SIDE_PX: u32 = 16384;
/// Largest number of polygon facets.
pub const MAX_FACETS: u32 = 360;
/// Largest number of inner corners along one side of a checkerboard.
pub const MAX_BOARD_CORNERS: u32 = 1000;
/// Largest number of planes of a fixed-plane transmitter.
pub const MAX_FIXED_PLANES: usize = 256;
/// The smallest checkerboard square (mm): a micrometre, a microscope's target.
pub const MIN_BOARD_SQUARE_MM: f64 = 1e-3;
/// The largest extent of a checkerboard (mm), squares and margins: 100 m.
pub const MAX_BOARD_EXTENT_MM: f64 = 1e5;

/// The largest coordinate (mm) of a measured point: 1000 km, far beyond any scan; a point beyond
/// it is a wrong number, which a 32-bit cloud could not even hold.
pub const MAX_COORDINATE_MM: f64 = 1e9;

/// A number as a message shows it: plain where that is short, else in exponent form (a value
/// of 1e-300 read from a file is not printed with 300 digits).
pub fn shown(value: f64) -> String {
    if value == 0.0 || (1e-3..1e7).contains(&value.abs()) || !value.is_finite() {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// Checks an image size `width` × `height` against [`MAX_IMAGE_SIDE_PX`] (and for zero); the
/// message names the fields.
pub fn check_image_size(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("width and height must be positive, got {width} × {height}"));
    }
    if width > MAX_IMAGE_SIDE_PX || height > MAX_IMAGE_SIDE_PX {
        return Err(format!("width and height must be at most {MAX_IMAGE_SIDE_PX} px, got {width} × {height}"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_sizes_are_bounded() {
        assert!(check_image_size(1024, 768).is_ok());
        assert!(check_image_size(0, 768).unwrap_err().contains("positive"));
        assert!(check_image_size(100_000, 768).unwrap_err().contains("at most 16384"));
    }

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(shown(30.0), "30");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(1e-300), "1e-300");
        assert_eq!(shown(-2.5e12), "-2.5e12");
        assert_eq!(shown(f64::NAN), "NaN");
    }
}
