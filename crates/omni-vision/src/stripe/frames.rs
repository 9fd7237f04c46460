//! Stream frames to stripe points: image loading, laser-off subtraction, size checks.

use super::{RidgeDetector, StripePoint};
use crate::colour::ColourSpec;
use crate::image_io::{DecodedGray, GrayImage, load_frame_channel_decoded};
use omni_formats::stream::Frame;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// Laser-off frames decoded once and shared: a scan's frames usually share one laser-off frame
/// per facet or revolution. Holds the most recently used [`LaserOffCache::CAPACITY`] of them,
/// read as `spec` says (the same reading as the laser frames they are subtracted from).
#[derive(Debug, Default)]
pub struct LaserOffCache {
    entries: Mutex<Vec<(PathBuf, Arc<DecodedGray>)>>,
    spec: ColourSpec,
}

impl LaserOffCache {
    /// Distinct laser-off frames kept (a 1024² frame is 1 MB at 8 bits, 2 MB at 16).
    pub const CAPACITY: usize = 16;

    /// An empty cache whose frames are read as `spec` says.
    pub fn new(spec: ColourSpec) -> Self {
        LaserOffCache { entries: Mutex::default(), spec }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(PathBuf, Arc<DecodedGray>)>> {
        self.entries.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The decoded frame at `path`, decoded now if it is not held.
    pub fn get(&self, path: &std::path::Path) -> Result<Arc<DecodedGray>, String> {
        if let Some(hit) = self.lock().iter().find(|(p, _)| p == path).map(|(_, img)| img.clone()) {
            return Ok(hit);
        }
        // Decoded outside the lock; two threads may both decode a new frame once.
        let img = Arc::new(load_frame_channel_decoded(path, &self.spec).map_err(|e| format!("laser-off frame {e}"))?);
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

/// [`load_frame_image`] with the laser-off frames taken from (and added to) `cache`, and the
/// frame (like them) read as the cache's [`ColourSpec`] says.
pub fn load_frame_image_cached(
    frame: &Frame,
    frames_dir: Option<&str>,
    cache: &LaserOffCache,
) -> Result<GrayImage, String> {
    Ok(load_frame_decoded_cached(frame, frames_dir, cache)?.into_gray())
}

/// [`load_frame_image_cached`], an 8-bit frame kept in its bytes (the detector reads them as
/// they are; widening costs a pass and slows the detection).
pub fn load_frame_decoded_cached(
    frame: &Frame,
    frames_dir: Option<&str>,
    cache: &LaserOffCache,
) -> Result<DecodedGray, String> {
    let path = frame.resolve_path(frames_dir, &frame.path);
    let mut img = load_frame_channel_decoded(&path, &cache.spec).map_err(|e| e.to_string())?;
    if let Some(ambient) = &frame.ambient_path {
        let apath = frame.resolve_path(frames_dir, ambient);
        let off = cache.get(&apath)?;
        if off.bit_depth() != img.bit_depth() {
            return Err(format!(
                "laser-off frame {}: {}-bit, but the frame is {}-bit",
                apath.display(),
                off.bit_depth(),
                img.bit_depth()
            ));
        }
        img.subtract_saturating(off.as_ref()).map_err(|m| format!("laser-off frame {}: {m}", apath.display()))?;
    }
    Ok(img)
}

/// Frames a static-ambient estimate uses at most, evenly spaced over the scan.
pub const STATIC_AMBIENT_MAX_FRAMES: usize = 31;
/// Fewest laser frames, at as many distinct mirror angles, a static-ambient estimate needs.
pub const STATIC_AMBIENT_MIN_FRAMES: usize = 5;

/// The scene without the laser, estimated from the laser frames of a sensor that does not move
/// during the scan: the per-pixel median of frames taken at different mirror angles. A sweeping
/// stripe lights each pixel in a few frames only, so the median is that pixel's ambient level;
/// lighting and texture that stay put cancel when it is subtracted, the stripe does not.
pub fn static_ambient(frames: &[GrayImage]) -> Result<GrayImage, String> {
    let first = frames.first().ok_or("no frames to estimate the ambient light from")?;
    if let Some((i, f)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| (f.width, f.height, f.bit_depth) != (first.width, first.height, first.bit_depth))
    {
        return Err(format!(
            "frame {i} is {}x{} px, {}-bit, but the first is {}x{} px, {}-bit",
            f.width, f.height, f.bit_depth, first.width, first.height, first.bit_depth
        ));
    }
    let mut out = GrayImage::new(first.width, first.height, first.bit_depth);
    let mut values = vec![0u16; frames.len()];
    for (k, pixel) in out.data.iter_mut().enumerate() {
        for (v, f) in values.iter_mut().zip(frames) {
            *v = f.data[k];
        }
        let mid = values.len() / 2;
        *pixel = *values.select_nth_unstable(mid).1;
    }
    Ok(out)
}

/// The laser frames (indices into `frames`) a static-ambient estimate of a scan uses: frames
/// with a laser on and no laser-off frame of their own, at most [`STATIC_AMBIENT_MAX_FRAMES`]
/// evenly spaced ones.
/// Refused when fewer than [`STATIC_AMBIENT_MIN_FRAMES`] distinct mirror angles remain: with
/// the stripe in the same place in most frames, the median would be the stripe.
pub fn static_ambient_frames(frames: &[Frame]) -> Result<Vec<usize>, String> {
    let laser: Vec<usize> =
        (0..frames.len()).filter(|&i| !frames[i].lasers.is_empty() && frames[i].ambient_path.is_none()).collect();
    let mut angles: Vec<(u32, i64)> =
        laser.iter().map(|&i| (frames[i].facet, (frames[i].alpha_deg * 100.0).round() as i64)).collect();
    angles.sort_unstable();
    angles.dedup();
    if angles.len() < STATIC_AMBIENT_MIN_FRAMES {
        return Err(format!(
            "a static-ambient estimate needs laser frames at {STATIC_AMBIENT_MIN_FRAMES} or more mirror angles, the stream has {}",
            angles.len()
        ));
    }
    let n = laser.len().min(STATIC_AMBIENT_MAX_FRAMES);
    Ok((0..n).map(|i| laser[i * laser.len() / n]).collect())
}

/// Checks that an image has the size the detector (camera) expects.
pub fn check_size(img: &GrayImage, detector: &RidgeDetector, what: &str) -> Result<(), String> {
    check_frame_size(img.width, img.height, detector, what)
}

/// [`check_size`] of a frame `width` × `height` px.
pub fn check_frame_size(width: u32, height: u32, detector: &RidgeDetector, what: &str) -> Result<(), String> {
    let (w, h) = detector.image_size();
    if (width, height) != (w, h) {
        return Err(format!("image is {width}x{height} px, but {what} is {w}x{h} px"));
    }
    Ok(())
}

/// Stripe points of a loaded image, after the size check.
pub fn frame_points(img: &GrayImage, detector: &RidgeDetector, what: &str) -> Result<Vec<StripePoint>, String> {
    check_size(img, detector, what)?;
    Ok(detector.detect(img))
}

/// [`frame_points`] of an image read at a colour mosaic's sites whose first is frame pixel
/// `origin` ([`crate::colour::mosaic_sites`]: half the size of `detector`'s frames), found by
/// `at_sites` (`detector.for_mosaic_sites(origin)`, built once for many frames) and given in
/// `detector`'s frame pixels.
pub fn mosaic_site_points(
    img: &GrayImage,
    detector: &RidgeDetector,
    at_sites: &RidgeDetector,
    origin: (u32, u32),
    what: &str,
) -> Result<Vec<StripePoint>, String> {
    check_frame_size(2 * img.width, 2 * img.height, detector, what)?;
    Ok(detector.points_from_mosaic_sites(at_sites.detect(img), origin))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_static_ambient_is_the_per_pixel_median_of_frames_of_one_size() {
        let frames: Vec<GrayImage> = [3u16, 200, 5, 4, 6]
            .iter()
            .map(|&v| GrayImage { width: 2, height: 1, bit_depth: 8, data: vec![v, 7] })
            .collect();
        assert_eq!(static_ambient(&frames).unwrap().data, vec![5, 7]);
        let mut mixed = frames.clone();
        mixed[3] = GrayImage::new(3, 1, 8);
        let e = static_ambient(&mixed).unwrap_err();
        assert!(e.contains("frame 3 is 3x1 px") && e.contains("first is 2x1"), "{e}");
        assert!(static_ambient(&[]).is_err());
    }

    #[test]
    fn a_laser_off_frame_is_decoded_once_and_errors_name_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("off.png");
        image::GrayImage::from_pixel(8, 6, image::Luma([7u8])).save(&path).unwrap();
        let cache = LaserOffCache::default();
        let (a, b) = (cache.get(&path).unwrap(), cache.get(&path).unwrap());
        assert!(Arc::ptr_eq(&a, &b), "decoded twice");
        assert_eq!(*a, DecodedGray::Eight { width: 8, height: 6, data: vec![7; 48] }, "8-bit, as its bytes");
        let missing = dir.path().join("missing.png");
        let e = cache.get(&missing).unwrap_err();
        assert!(e.contains("laser-off frame") && e.contains("missing.png"), "{e}");
    }

    #[test]
    fn a_laser_off_frame_is_subtracted_alike_from_8_and_16_bit_samples() {
        let eight = |data: Vec<u8>| DecodedGray::Eight { width: 3, height: 1, data };
        let wide = |data: Vec<u16>| DecodedGray::Wide(GrayImage { width: 3, height: 1, bit_depth: 8, data });
        let off = [eight(vec![5, 9, 0]), wide(vec![5, 9, 0])];
        for frame in [eight(vec![7, 3, 255]), wide(vec![7, 3, 255])] {
            for off in &off {
                let mut f = frame.clone();
                f.subtract_saturating(off).unwrap();
                assert_eq!(f.into_gray().data, vec![2, 0, 255]);
            }
        }
        let mut f = eight(vec![1, 2, 3]);
        let small = DecodedGray::Eight { width: 2, height: 1, data: vec![0, 0] };
        assert_eq!(f.subtract_saturating(&small).unwrap_err(), "size 2x1 differs from the frame's 3x1");
        let e = DecodedGray::from_gray(GrayImage { width: 3, height: 1, bit_depth: 8, data: vec![1, 2, 3] });
        assert_eq!(e, eight(vec![1, 2, 3]));
    }
}
