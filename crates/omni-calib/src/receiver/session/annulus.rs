//! The mirror annulus of a calibration: given as numbers, or found ([`omni_vision::rim`]) in an
//! image of a lit scene, or in the board images (their per-pixel range, or the best single one).

use super::{Error, Reporter};
use omni_vision::corners::{GrayF32, load_gray};
use omni_vision::image_io::expand_image_paths;
use omni_vision::rim;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// `CX,CY,R_IN,R_OUT` (px): four finite numbers with 0 ≤ R_IN < R_OUT.
pub fn parse_annulus(s: &str) -> Result<[f64; 4], Error> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
    match v[..] {
        [cx, cy, r0, r1]
            if v.iter().all(|c: &f64| c.is_finite()) && s.split(',').count() == 4 && r0 >= 0.0 && r0 < r1 =>
        {
            Ok([cx, cy, r0, r1])
        }
        _ => Err(Error::Usage(format!("--annulus: expected CX,CY,R_IN,R_OUT in px with 0 ≤ R_IN < R_OUT, got {s:?}"))),
    }
}

/// Where a detected annulus came from: the image's size (to check against the board images) and
/// its name for messages.
pub(super) type RimSource = (usize, usize, String);

/// The annulus to use (px), with its source if it was detected.
pub(super) struct Resolved {
    pub annulus: [f64; 4],
    pub source: Option<RimSource>,
}

/// The annulus as the options give it: `--annulus CX,CY,R_IN,R_OUT` parsed, `--annulus auto`,
/// or `--rim-image FILE` (`--annulus` wins if both are given).
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Given<'a> {
    Numbers([f64; 4]),
    Auto,
    RimImage(&'a Path),
}

const AUTO_NEEDS_IMAGES: &str = "--annulus auto needs board images (not --corners); give --rim-image or numbers";

/// Reads the annulus options before anything else is: numbers parsed ([`parse_annulus`]),
/// `auto` refused without board images; `None` if neither option is given.
pub(super) fn given<'a>(
    annulus: Option<&str>,
    rim_image: Option<&'a Path>,
    have_images: bool,
) -> Result<Option<Given<'a>>, Error> {
    Ok(match (annulus, rim_image) {
        (None, None) => None,
        (Some("auto"), _) if !have_images => return Err(Error::Usage(AUTO_NEEDS_IMAGES.into())),
        (Some("auto"), _) => Some(Given::Auto),
        (Some(numbers), _) => Some(Given::Numbers(parse_annulus(numbers)?)),
        (None, Some(path)) => Some(Given::RimImage(path)),
    })
}

/// The annulus to use: the numbers given, or the rim found in the board images (`auto`: their
/// range image or the best single one) or in the rim image.
pub(super) fn resolve(
    given: Option<&Given>,
    boards: &[PathBuf],
    out: &dyn Reporter,
) -> Result<Option<Resolved>, Error> {
    let (img, source) = match given {
        None => return Ok(None),
        Some(Given::Numbers(a)) => return Ok(Some(Resolved { annulus: *a, source: None })),
        Some(Given::Auto) if boards.is_empty() => return Err(Error::Usage(AUTO_NEEDS_IMAGES.into())),
        Some(Given::Auto) => (rim_input(boards, out)?, "--annulus auto (board images)".to_string()),
        Some(Given::RimImage(path)) => (load_gray(path)?, path.display().to_string()),
    };
    let annulus = detect(&img, &source, out)?;
    Ok(Some(Resolved { annulus, source: Some((img.width, img.height, source)) }))
}

/// One image as it is, several as their per-pixel range or the best single one
/// ([`rim::rim_image`]); says when a single image was taken.
fn rim_input(paths: &[PathBuf], out: &dyn Reporter) -> Result<GrayF32, Error> {
    let images: Vec<GrayF32> = paths.par_iter().map(|p| load_gray(p)).collect::<Result<_, _>>()?;
    if let Some(k) = images.iter().position(|i| (i.width, i.height) != (images[0].width, images[0].height)) {
        return Err(Error::Failed(format!(
            "{}: image is {} × {} px but {} is {} × {} px (all images must come from one camera)",
            paths[k].display(),
            images[k].width,
            images[k].height,
            paths[0].display(),
            images[0].width,
            images[0].height
        )));
    }
    let name = |k: usize| paths[k].display().to_string();
    let source = if paths.len() == 1 { name(0) } else { format!("{} images", paths.len()) };
    let chosen = rim::rim_image(&images, &rim::RimOptions::default()).map_err(|e| format!("{source}: {e}"))?;
    if let (rim::RimSource::Single(k), Some(why)) = (chosen.source, &chosen.range_error) {
        out.say(&format!(
            "the range of the {source} shows no mirror rim ({why}); using the best single image, {}",
            name(k)
        ));
    }
    Ok(chosen.image)
}

/// The annulus of [`rim::detect_rim`], reported; errors name `source`.
fn detect(img: &GrayF32, source: &str, out: &dyn Reporter) -> Result<[f64; 4], Error> {
    let found = rim::detect_rim(img, &rim::RimOptions::default()).map_err(|e| format!("{source}: {e}"))?;
    let a = found.annulus();
    out.say(&format!(
        "mirror annulus from {source}: centre ({:.2}, {:.2}) px, radii {:.2}–{:.2} px (rim fit RMS {:.3} px, {:.0} % of the rays{})",
        a[0],
        a[1],
        a[2],
        a[3],
        found.outer.rms_px,
        100.0 * found.outer.support,
        if found.inner.is_some() { "" } else { "; no blind-centre circle" }
    ));
    Ok(a)
}

/// The annulus `[cx, cy, r_in, r_out]` (px) of one lit image, or of the per-pixel range of several
/// (files or directories), as `omni-calib-receiver find-annulus` prints it.
pub fn find_annulus(images: &[PathBuf], out: &dyn Reporter) -> Result<[f64; 4], Error> {
    let paths = expand_image_paths(images)?;
    let img = rim_input(&paths, out)?;
    let source = match &paths[..] {
        [one] => one.display().to_string(),
        _ => format!("{} images", paths.len()),
    };
    detect(&img, &source, out)
}
