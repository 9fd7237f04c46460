//! `omniscan.detect_stripe`: omni-vision's stripe detector (what omni-ridge runs) on a numpy image.

use crate::arrays::rows;
use crate::camera::Camera;
use numpy::{PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use omni_vision::colour::{Channel, ColourSpec, RgbImage};
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

/// The detector's grey image of `obj` read as `spec` says: a 2-D array as it is (or, with a Bayer
/// order, demosaiced and then read), an (h, w, 3) RGB array through its channel or laser contrast.
fn frame_image(obj: &Bound<'_, PyAny>, what: &str, spec: &ColourSpec) -> PyResult<GrayImage> {
    Ok(frame_images(obj, what, spec, None)?.0)
}

/// [`frame_image`], and with `also` that channel of the same colour samples (`None` for a grey
/// array read as it is), the array converted once.
fn frame_images(
    obj: &Bound<'_, PyAny>,
    what: &str,
    spec: &ColourSpec,
    also: Option<Channel>,
) -> PyResult<(GrayImage, Option<GrayImage>)> {
    let arr = obj.py().import("numpy")?.call_method1("ascontiguousarray", (obj,))?;
    let ndim = arr.getattr("ndim")?.extract::<usize>()?;
    let read = |rgb: RgbImage| (rgb.channel(spec.channel), also.map(|c| rgb.channel(c)));
    if ndim != 3 {
        let grey = gray_image(&arr, what)?;
        return match spec.bayer {
            Some(order) => {
                let rgb = spec
                    .read_mosaic(&grey, order)
                    .map_err(|m| crate::value_error(format!("{what}: bayer {}: {m}", order.name())))?;
                Ok(read(rgb))
            }
            None if spec.channel.needs_colour() => Err(crate::value_error(format!(
                "{what}: a 2-D (grey) array has no colour to read for {}: give an (h, w, 3) RGB array, or bayer= for a raw mosaic",
                spec.describe()
            ))),
            None => Ok((grey, None)),
        };
    }
    if spec.bayer.is_some() {
        return Err(crate::value_error(format!(
            "{what}: bayer= reads a raw 2-D mosaic, but the array is 3-D (already colour): drop bayer="
        )));
    }
    Ok(read(rgb_image(&arr, what)?))
}

/// An (h, w, 3) uint8 or uint16 RGB array.
fn rgb_image(arr: &Bound<'_, PyAny>, what: &str) -> PyResult<RgbImage> {
    let wrong = |arr: &Bound<'_, PyAny>| -> PyResult<PyErr> {
        let (dtype, shape) = (arr.getattr("dtype")?.str()?.to_string(), arr.getattr("shape")?.str()?.to_string());
        Ok(pyo3::exceptions::PyTypeError::new_err(format!(
            "{what}: expected an (height, width, 3) uint8 or uint16 RGB array, got shape {shape} of {dtype}"
        )))
    };
    let (shape, data, bit_depth): (Vec<usize>, Vec<[u16; 3]>, u8) = if let Ok(a) = arr.cast::<PyArray3<u8>>() {
        let px = a.readonly().as_slice()?.chunks_exact(3).map(|c| [c[0] as u16, c[1] as u16, c[2] as u16]).collect();
        (a.shape().to_vec(), px, 8)
    } else if let Ok(a) = arr.cast::<PyArray3<u16>>() {
        let px = a.readonly().as_slice()?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        (a.shape().to_vec(), px, 16)
    } else {
        return Err(wrong(arr)?);
    };
    if shape[2] != 3 {
        return Err(wrong(arr)?);
    }
    // The grey image's size checks (its samples are not needed for them).
    let size = image_of(shape[1], shape[0], bit_depth, Vec::new(), what)?;
    Ok(RgbImage { width: size.width, height: size.height, bit_depth, data })
}

/// The colour reading of `detect_stripe`'s keywords.
fn colour_spec(channel: Option<&str>, laser: Option<&str>, bayer: Option<&str>, sites: bool) -> PyResult<ColourSpec> {
    let channel = match (channel, laser) {
        (Some(_), Some(_)) => return Err(crate::value_error("give channel= or laser=, not both")),
        (None, Some(c)) => Channel::Laser(c.parse().map_err(|m| crate::value_error(format!("laser: {m}")))?),
        (None | Some("luma"), None) => Channel::Luma,
        (Some(c), None) => Channel::Single(
            c.parse()
                .map_err(|_| crate::value_error(format!("channel: unknown \"{c}\" (known: luma, red, green, blue)")))?,
        ),
    };
    let bayer = bayer
        .map(|b| omni_vision::colour::BayerPattern::parse(b).map_err(|m| crate::value_error(format!("bayer: {m}"))))
        .transpose()?;
    let spec = ColourSpec { channel, bayer, sites };
    spec.validate().map_err(|m| crate::value_error(m.replace("--bayer-sites", "bayer_sites").replace("--", "")))?;
    Ok(spec)
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
/// (0–255) or uint16 (0–65535) array (height, width), or an (height, width, 3) RGB array of
/// either type (OpenCV's BGR images reversed: `img[..., ::-1]`). Colour is read as `channel`
/// ("luma", the default, "red", "green", "blue") or as a laser's colour contrast (`laser`="red":
/// R − (G+B)/2, rising into saturated cores, as omni-ridge --laser); a 2-D raw Bayer mosaic is
/// demosaiced first with `bayer` ("rggb", "bggr", "grbg", "gbrg"; red and blue are sampled one
/// pixel in four, so a stripe's centre moves by up to about 0.1 px with where it falls between
/// their columns); with `bayer_sites`=True and a red or blue `laser` or `channel`, the mosaic is
/// read at that colour's own sites instead (half the size, no sample interpolated; the points in
/// the frame's pixels; wide stripes about twice as precise). With `camera`, the frame must
/// have the camera's size and is searched within its mirror annulus; without, over the whole
/// image (omni-ridge without --camera). `ambient`, a laser-off frame of the same size, depth and
/// kind, read the same way, is subtracted first. `max_scale` (1–16) is the coarsest scale at
/// which stripes too wide for `max_width` are searched. `optics_blur_px` is the lens's PSF σ
/// whose pull on curved stripes is removed and whose shift of a lopsided laser's peak is
/// undone (default: from `camera`, its lens_blur_px or its
/// optics, else measured on the frame's stripes, as omni-ridge). `laser_tail` = (share,
/// length) is the laser's cross-section if known, a core with a one-sided tail holding that
/// share of the light, that many core σ long (omni-ridge --laser-tail; give the lens's blur
/// too). `one_stripe_per` ("column" or "row"), for an ordinary triangulation sensor whose laser
/// lights one point per image column (row): dimmer stripes sharing a column with a twice
/// brighter one are dropped as its reflections (omni-ridge --one-stripe-per). Settings left as
/// None keep omni-ridge's defaults (method windowed, sampling normal, threshold 4 % of full
/// scale; widths in px; `threshold` in the image's units). Returns an (n, 5) float64 array of
/// (u, v, intensity, width, quality) rows: u, v in px, quality a bit set (1 saturated, 2 weak,
/// 4 width marginal).
#[pyfunction]
#[pyo3(signature = (image, camera = None, *, ambient = None, method = None, sampling = None, threshold = None,
    min_width = None, max_width = None, hessian_sigma = None, along_stripe_px = None, optics_blur_px = None,
    channel = None, laser = None, bayer = None, bayer_sites = false, max_scale = None, laser_tail = None, one_stripe_per = None))]
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
    channel: Option<&str>,
    laser: Option<&str>,
    bayer: Option<&str>,
    bayer_sites: bool,
    max_scale: Option<u32>,
    laser_tail: Option<Vec<f64>>,
    one_stripe_per: Option<&str>,
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
    params.max_scale = max_scale.unwrap_or(params.max_scale);
    params.mosaic = bayer.is_some();
    params.laser_profile = match laser_tail.as_deref() {
        None => None,
        Some(&[share, length]) => {
            let p = omni_model::LaserProfile::tailed(share, length);
            p.validate().map_err(|e| crate::value_error(format!("laser_tail: {e}")))?;
            Some(p)
        }
        Some(other) => {
            return Err(crate::value_error(format!(
                "laser_tail: expected (share, length), got {} numbers",
                other.len()
            )));
        }
    };
    if let Some(lines) = one_stripe_per {
        params.one_stripe_per = Some(lines.parse().map_err(|e| crate::value_error(format!("one_stripe_per: {e}")))?);
    }
    params.validate().map_err(crate::value_error)?;
    let spec = colour_spec(channel, laser, bayer, bayer_sites)?;
    // As omni-ridge does after the detector: points on stripes shorter than the fit's window go.
    let along_window = (params.along_stripe_px > 0.0).then(|| params.along_stripe_window_px());

    let mut img = frame_image(image, "image", &spec)?;
    if let Some(off) = ambient {
        let off = frame_image(off, "ambient", &spec)?;
        if off.bit_depth != img.bit_depth {
            return Err(crate::value_error(format!(
                "ambient: {}-bit, but the image is {}-bit",
                off.bit_depth, img.bit_depth
            )));
        }
        img.subtract_saturating(&off).map_err(|m| crate::value_error(format!("ambient: {m}")))?;
    }
    // A mosaic read at its sites is half the frame's size; its points come back in frame pixels.
    let origin = spec.site_origin();
    let scale = if origin.is_some() { 2 } else { 1 };
    let (detector, what) = match camera {
        Some(cam) => {
            let (w, h) = cam.model.image_size();
            let params = params.with_lens_blur_of(&cam.file).map_err(|e| crate::value_error(format!("camera: {e}")))?;
            (RidgeDetector::new(w, h, cam.model.mirror_circle(), params), "the camera's image")
        }
        None => (RidgeDetector::whole_frame(scale * img.width, scale * img.height, params), "the image"),
    };
    let points = py
        .detach(|| match origin {
            Some(origin) => {
                stripe::mosaic_site_points(&img, &detector, &detector.for_mosaic_sites(origin), origin, what)
            }
            None => stripe::frame_points(&img, &detector, what),
        })
        .map_err(crate::value_error)?;
    let points = match along_window {
        Some(window) => stripe::refuse_short_stripes(points, window).kept,
        None => points,
    };
    let table: Vec<[f64; 5]> = points.into_iter().map(<[f64; 5]>::from).collect();
    rows(py, &table)
}

/// The laser's cross-section measured on one frame's stripe (`omni-calib-plane tail` per frame):
/// `image` read as `detect_stripe` reads it (the same `channel=` / `laser=`), `stripe` its points
/// (an `(n, 5)` array from `detect_stripe`); a catadioptric `camera`'s mirror centre turns a ring
/// stripe's normals away from it. Returns a dict: `tail_weight`, `tail_length` (core σ), their
/// σ, `core_sigma_px`, `fwhm_px`, `side`, `profiles`, `residual_rms`, `gaussian_residual_rms`; a
/// ValueError says why a frame shows no tail to measure.
#[pyfunction]
#[pyo3(signature = (image, stripe, camera = None, *, optics_blur_px = 0.0, min_profiles = 30, channel = None,
    laser = None))]
#[allow(clippy::too_many_arguments)]
pub fn measure_laser_tail<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    stripe: &Bound<'py, PyAny>,
    camera: Option<&Camera>,
    optics_blur_px: f64,
    min_profiles: usize,
    channel: Option<&str>,
    laser: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    if !(optics_blur_px.is_finite() && optics_blur_px >= 0.0) {
        return Err(crate::value_error(format!("optics_blur_px: expected a finite number >= 0, got {optics_blur_px}")));
    }
    if min_profiles < 5 {
        return Err(crate::value_error(format!("min_profiles: expected at least 5, got {min_profiles}")));
    }
    let spec = colour_spec(channel, laser, None, false)?;
    // With a laser colour, its own channel too: where the contrast compresses (`measure_frame`).
    let own = match spec.channel {
        Channel::Laser(c) => Some(Channel::Single(c)),
        _ => None,
    };
    let (img, laser_channel) = frame_images(image, "image", &spec, own)?;
    let rows = crate::arrays::Vectors::<5>::extract(stripe, "stripe")?;
    let points = (0..rows.len())
        .map(|i| {
            omni_formats::stream::StripePoint::try_from(rows.get(i))
                .map_err(|e| crate::value_error(format!("stripe row {i}: {e}")))
        })
        .collect::<PyResult<Vec<_>>>()?;
    let mirror = camera.map(|c| c.model.mirror_circle());
    let opts = omni_calib::laser_tail::TailOptions { blur_px: optics_blur_px, min_profiles, mirror };
    let tail = py
        .detach(|| omni_calib::laser_tail::measure_frame("image", &img, &points, laser_channel.as_ref(), &opts))
        .map_err(crate::value_error)?;
    let dict = crate::readers::to_python(py, &tail)?;
    dict.del_item("name")?;
    Ok(dict)
}
