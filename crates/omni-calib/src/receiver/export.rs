//! Interoperability: OCamCalib `calib_results.txt` (export and import), Kalibr `camchain.yaml`
//! (`omni` + `radtan`) and OpenCV `omnidir` parameters (K, D, ξ) as an OpenCV YAML file.
//!
//! Frames: Kalibr and OpenCV use a camera frame with z forward; ours has the image centre
//! looking down (−z). The intrinsics are the same numbers (the frames differ by z → −z), so
//! the export copies ξ, fx, fy, cx, cy, k1, k2, p1, p2 unchanged. OCamCalib works in (row,
//! column) order with Matlab's 1-based pixels: the centre is swapped and shifted by one.

use omni_model::{MeiParams, OcamParams};

/// OCamCalib `calib_results.txt` for a polynomial model (the inverse polynomial is fitted if
/// missing, degree 12 as OCamCalib's default).
pub fn ocam_calib_results(p: &OcamParams) -> String {
    let mut p = p.clone();
    if p.inv_poly.is_empty() {
        p.fit_inverse_poly(12);
    }
    let list = |v: &[f64]| v.iter().map(|x| format!("{x:.6e}")).collect::<Vec<_>>().join(" ");
    format!(
        "#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). These are used by cam2world\n\n\
         {} {} \n\n\
         #polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). These are used by world2cam\n\n\
         {} {} \n\n\
         #center: \"row\" and \"column\" coordinates (x and y coordinates) of the center of the image\n\n\
         {:.6} {:.6}\n\n\
         #affine parameters \"c\", \"d\", \"e\"\n\n\
         {:.6} {:.6} {:.6}\n\n\
         #image size: \"height\" and \"width\"\n\n\
         {} {}\n\n",
        p.poly.len(),
        list(&p.poly),
        p.inv_poly.len(),
        list(&p.inv_poly),
        p.cy_px + 1.0,
        p.cx_px + 1.0,
        p.c,
        p.d,
        p.e,
        p.height,
        p.width
    )
}

/// Parses OCamCalib's `calib_results.txt`; the error names the line or section at fault.
pub fn parse_ocam_calib_results(text: &str) -> Result<OcamParams, String> {
    let lines: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
    if lines.len() < 5 {
        return Err(format!("expected 5 data lines (poly, inverse poly, centre, affine, size), found {}", lines.len()));
    }
    let numbers = |k: usize, what: &str| -> Result<Vec<f64>, String> {
        lines[k]
            .split_whitespace()
            .map(|t| t.parse::<f64>().map_err(|_| format!("{what}: \"{t}\" is not a number")))
            .collect::<Result<Vec<f64>, String>>()
            .and_then(|v| {
                if v.iter().all(|x| x.is_finite()) { Ok(v) } else { Err(format!("{what}: values must be finite")) }
            })
    };
    let counted = |k: usize, what: &str| -> Result<Vec<f64>, String> {
        let v = numbers(k, what)?;
        let n = *v.first().ok_or(format!("{what}: empty line"))? as usize;
        if v.len() != n + 1 {
            return Err(format!("{what}: says {n} coefficients but has {}", v.len() - 1));
        }
        Ok(v[1..].to_vec())
    };
    let poly = counted(0, "direct polynomial")?;
    let inv_poly = counted(1, "inverse polynomial")?;
    let centre = numbers(2, "centre")?;
    let affine = numbers(3, "affine parameters")?;
    let size = numbers(4, "image size")?;
    if centre.len() != 2 || affine.len() != 3 || size.len() != 2 {
        return Err("centre needs 2 numbers, affine parameters 3, image size 2".into());
    }
    let p = OcamParams {
        poly,
        inv_poly,
        cx_px: centre[1] - 1.0,
        cy_px: centre[0] - 1.0,
        c: affine[0],
        d: affine[1],
        e: affine[2],
        width: size[1] as u32,
        height: size[0] as u32,
        inner_radius_px: 0.0,
        outer_radius_px: 0.0,
        viewpoint_mm: [0.0; 3],
    };
    p.validate()?;
    Ok(p)
}

/// Kalibr `camchain.yaml` with one camera (`omni` projection, `radtan` distortion).
pub fn kalibr_camchain(p: &MeiParams) -> String {
    format!(
        "cam0:\n  camera_model: omni\n  intrinsics: [{}, {}, {}, {}, {}]\n  distortion_model: radtan\n  \
         distortion_coeffs: [{}, {}, {}, {}]\n  resolution: [{}, {}]\n",
        p.xi, p.fx_px, p.fy_px, p.cx_px, p.cy_px, p.k1, p.k2, p.p1, p.p2, p.width, p.height
    )
}

/// OpenCV `cv::omnidir` parameters as an OpenCV FileStorage YAML file: `K`, `D`, `xi`.
pub fn opencv_omnidir_yaml(p: &MeiParams) -> String {
    format!(
        "%YAML:1.0\n---\nimage_width: {}\nimage_height: {}\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
         data: [ {}, 0., {}, 0., {}, {}, 0., 0., 1. ]\nD: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   \
         data: [ {}, {}, {}, {} ]\nxi: !!opencv-matrix\n   rows: 1\n   cols: 1\n   dt: d\n   data: [ {} ]\n",
        p.width, p.height, p.fx_px, p.cx_px, p.fy_px, p.cy_px, p.k1, p.k2, p.p1, p.p2, p.xi
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_model::{CameraModel, OcamCamera};

    #[test]
    fn ocam_export_import_round_trips_rays() {
        let p = OcamParams {
            poly: vec![-190.0, 0.0, 2.2e-3, -2.5e-6, 6.0e-9],
            inv_poly: vec![],
            cx_px: 380.25,
            cy_px: 241.5,
            c: 1.0003,
            d: 1e-4,
            e: -2e-4,
            width: 752,
            height: 480,
            inner_radius_px: 0.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        };
        let text = ocam_calib_results(&p);
        let q = parse_ocam_calib_results(&text).unwrap();
        let (a, b) = (OcamCamera::new(p).unwrap(), OcamCamera::new(q.clone()).unwrap());
        assert_eq!(q.inv_poly.len(), 13);
        for &(x, y) in &[(100.0, 100.0), (600.0, 400.0), (380.0, 50.0)] {
            let px = omni_geom::Vector2::new(x, y);
            let (ra, rb) = (a.pixel_to_ray(&px).unwrap(), b.pixel_to_ray(&px).unwrap());
            // 6 significant digits in the file: rays agree to ~1e-5 rad.
            assert!(ra.dir.angle(&rb.dir) < 2e-5, "{}", ra.dir.angle(&rb.dir));
        }
        assert!(parse_ocam_calib_results("5 1 2\n").unwrap_err().contains("expected 5 data lines"));
        let bad = text.replacen("-1.900000e2", "x", 1);
        assert!(parse_ocam_calib_results(&bad).unwrap_err().contains("direct polynomial"), "{bad}");
    }
}
