//! Stream frames to stripe points: image loading, laser-off subtraction, size checks.

use super::{RidgeDetector, StripePoint};
use crate::image_io::{GrayImage, load_gray};
use omni_formats::stream::Frame;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// Laser-off frames decoded once and shared: a scan's frames usually share one laser-off frame
/// per facet or revolution. Holds the most recently used [`LaserOffCache::CAPACITY`] of them.
#[derive(Debug, Default)]
pub struct LaserOffCache {
    entries: Mutex<Vec<(PathBuf, Arc<GrayImage>)>>,
}

impl LaserOffCache {
    /// Distinct laser-off frames kept (a 1024² 16-bit frame is 2 MB).
    pub const CAPACITY: usize = 16;

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(PathBuf, Arc<GrayImage>)>> {
        self.entries.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The decoded frame at `path`, decoded now if it is not held.
    pub fn get(&self, path: &std::path::Path) -> Result<Arc<GrayImage>, String> {
        if let Some(hit) = self.lock().iter().find(|(p, _)| p == path).map(|(_, img)| img.clone()) {
            return Ok(hit);
        }
        // Decoded outside the lock; two threads may both decode a new frame once.
        let img = Arc::new(load_gray(path).map_err(|e| format!("laser-off frame {e}"))?);
        let mut entries = self.lock();
        if entries.len() == Self::CAPACITY {
            entries.remove(0);
        }
        entries.push((path.to_path_buf(), img.clone()));
        Ok(img)
    }
}

/// Loads a frame record's image (path resolved against `frames_dir`) and subtracts its
/// laser-off frame (`ambient_path`) if it has one. Errors name the file at fault.
pub fn load_frame_image(frame: &Frame, frames_dir: Option<&str>) -> Result<GrayImage, String> {
    load_frame_image_cached(frame, frames_dir, &LaserOffCache::default())
}

/// [`load_frame_image`] with the laser-off frames taken from (and added to) `cache`.
pub fn load_frame_image_cached(
    frame: &Frame,
    frames_dir: Option<&str>,
    cache: &LaserOffCache,
) -> Result<GrayImage, String> {
    let path = frame.resolve_path(frames_dir, &frame.path);
    let mut img = load_gray(&path).map_err(|e| e.to_string())?;
    if let Some(ambient) = &frame.ambient_path {
        let apath = frame.resolve_path(frames_dir, ambient);
        let off = cache.get(&apath)?;
        if off.bit_depth != img.bit_depth {
            return Err(format!(
                "laser-off frame {}: {}-bit, but the frame is {}-bit",
                apath.display(),
                off.bit_depth,
                img.bit_depth
            ));
        }
        img.subtract_saturating(off.as_ref()).map_err(|m| format!("laser-off frame {}: {m}", apath.display()))?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_laser_off_frame_is_decoded_once_and_errors_name_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("off.png");
        image::GrayImage::from_pixel(8, 6, image::Luma([7u8])).save(&path).unwrap();
        let cache = LaserOffCache::default();
        let (a, b) = (cache.get(&path).unwrap(), cache.get(&path).unwrap());
        assert!(Arc::ptr_eq(&a, &b), "decoded twice");
        assert_eq!((a.width, a.height, a.data[0]), (8, 6, 7));
        let missing = dir.path().join("missing.png");
        let e = cache.get(&missing).unwrap_err();
        assert!(e.contains("laser-off frame") && e.contains("missing.png"), "{e}");
    }
}
