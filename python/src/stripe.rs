//! `omniscan.detect_stripe`: omni-vision's stripe detector (what omni-ridge runs) on a numpy image.

use crate::arrays::rows;
use crate::camera::Camera;
use numpy::{PyArray2, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use omni_vision::image_io::GrayImage;
use omni_vision::stripe::{self, RidgeDetector, RidgeParams};
use pyo3::prelude::*;

/// A 2-D uint8 or uint16 numpy array as the detector's grey image (8- or 16-bit).
fn gray_image(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<GrayImage> {
    let arr = obj.py().import("numpy")?.call_method1("ascontiguousarray", (obj,))?;
    if let Ok(a) = arr.cast::<PyArray2<u8>>() {
        let [h, w] = [a.shape()[0], a.shape()[1]];
        let data = a.readonly().as_slice()?.iter().map(|&v| v as u16).collect();
        return image_of(w, h, 8, data, what);
    }
    if let Ok(a) = arr.cast::<PyArray2<u16>>() {
        let [h, w] = [a.shape()[0], a.shape()[1]];
        return image_of(w, h, 16, a.readonly().as_slice()?.to_vec(), what);
    }
    let (dtype, ndim) = (arr.getattr("dtype")?.str()?.to_string(), arr.getattr("ndim")?.extract::<usize>()?);
    Err(pyo3::exceptions::PyTypeError::new_err(format!(
        "{what}: expected a 2-D uint8 or uint16 array (height, width), got a {ndim}-D {dtype} array"
    )))
}

fn image_of(w: usize, h: usize, bit_depth: u8, data: Vec<u16>, what: &str) -> PyResult<GrayImage> {
    let (width, height) = (u32::try_from(w), u32::try_from(h));
    let (Ok(width), Ok(height)) = (width, height) else {
        return Err(crate::value_error(format!("{what}: {w}x{h} px is too large")));
    };
    omni_model::limits::check_image_size(width, height).map_err(|m| crate::value_error(format!("{what}: {m}")))?;
    Ok(GrayImage { width, height, bit_depth, data })
}

/// Stripe centres in a laser frame, exactly as omni-ridge finds them: `image` is a 2-D uint8
/// (0–255) or uint16 (0–65535) array (height, width). With `camera`, the frame must have the
/// camera's size and is sampled within its mirror annulus; without, from the image centre over
/// the largest circle inside the image (omni-ridge without --camera). `ambient`, a laser-off
/// frame of the same size and depth, is subtracted first. Settings left as None keep
/// omni-ridge's defaults (method windowed, sampling normal, threshold 4 % of full scale; widths
/// in px; `threshold` in the image's units). Returns an (n, 5) float64 array of
/// (u, v, intensity, width, quality) rows: u, v in px, quality a bit set (1 saturated, 2 weak,
/// 4 width marginal).
#[pyfunction]
#[pyo3(signature = (image, camera = None, *, ambient = None, method = None, sampling = None, threshold = None,
    min_width = None, max_width = None, hessian_sigma = None, along_stripe_px = None, optics_blur_px = None))]
pub fn detect_stripe<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    camera: Option<&Camera>,
    ambient: Option<&Bound<'py, PyAny>>,
    method: Option<&str>,
    sampling: Option<&str>,
    threshold: Option<f64>,
    min_width: Option<f64>,
    max_width: Option<f64>,
    hessian_sigma: Option<f64>,
    along_stripe_px: Option<f64>,
    optics_blur_px: Option<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let mut params = RidgeParams::default();
    if let Some(m) = method {
        params.method = m.parse().map_err(crate::value_error)?;
    }
    if let Some(s) = sampling {
        params.sampling = s.parse().map_err(crate::value_error)?;
    }
    params.threshold = threshold.or(params.threshold);
    params.min_width = min_width.unwrap_or(params.min_width);
    params.max_width = max_width.unwrap_or(params.max_width);
    params.hessian_sigma = hessian_sigma.unwrap_or(params.hessian_sigma);
    params.along_stripe_px = along_stripe_px.unwrap_or(params.along_stripe_px);
    params.optics_blur_px = optics_blur_px.or(params.optics_blur_px);
    params.validate().map_err(crate::value_error)?;

    let mut img = gray_image(image, "image")?;
    if let Some(off) = ambient {
        let off = gray_image(off, "ambient")?;
        if off.bit_depth != img.bit_depth {
            return Err(crate::value_error(format!(
                "ambient: {}-bit, but the image is {}-bit",
                off.bit_depth, img.bit_depth
            )));
        }
        img.subtract_saturating(&off).map_err(|m| crate::value_error(format!("ambient: {m}")))?;
    }
    let (detector, what) = match camera {
        Some(cam) => {
            let (w, h) = cam.model.image_size();
            (RidgeDetector::new(w, h, cam.model.mirror_circle(), params), "the camera's image")
        }
        None => (RidgeDetector::for_image_centre(img.width, img.height, params), "the image"),
    };
    let points = py.detach(|| stripe::frame_points(&img, &detector, what)).map_err(crate::value_error)?;
    let table: Vec<[f64; 5]> = points.into_iter().map(<[f64; 5]>::from).collect();
    rows(py, &table)
}
