//! Stream frames to stripe points: image loading, laser-off subtraction, size checks.

use super::{RidgeDetector, StripePoint};
use crate::image_io::{GrayImage, load_gray};
use omni_formats::stream::Frame;

/// Loads a frame record's image (path resolved against `frames_dir`) and subtracts its
/// laser-off frame (`ambient_path`) if it has one. Errors name the file at fault.
pub fn load_frame_image(frame: &Frame, frames_dir: Option<&str>) -> Result<GrayImage, String> {
    let path = frame.resolve_path(frames_dir, &frame.path);
    let mut img = load_gray(&path).map_err(|e| e.to_string())?;
    if let Some(ambient) = &frame.ambient_path {
        let apath = frame.resolve_path(frames_dir, ambient);
        let off = load_gray(&apath).map_err(|e| format!("laser-off frame {}", e))?;
        if off.bit_depth != img.bit_depth {
            return Err(format!(
                "laser-off frame {}: {}-bit, but the frame is {}-bit",
                apath.display(),
                off.bit_depth,
                img.bit_depth
            ));
        }
        img.subtract_saturating(&off).map_err(|m| format!("laser-off frame {}: {m}", apath.display()))?;
    }
    Ok(img)
}

/// Checks that an image has the size the detector (camera) expects.
pub fn check_size(img: &GrayImage, detector: &RidgeDetector, what: &str) -> Result<(), String> {
    let (w, h) = detector.image_size();
    if (img.width, img.height) != (w, h) {
        return Err(format!("image is {}x{} px, but {what} is {w}x{h} px", img.width, img.height));
    }
    Ok(())
}

/// Stripe points of a loaded image, after the size check.
pub fn frame_points(img: &GrayImage, detector: &RidgeDetector, what: &str) -> Result<Vec<StripePoint>, String> {
    check_size(img, detector, what)?;
    Ok(detector.detect(img))
}
