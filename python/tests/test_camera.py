"""omniscan.Camera: the Mei model against OpenCV's cv2.omnidir (an independent implementation
of Mei's model), and the simulator's exact hyperbolic camera in round trips and against the
simulator's ground-truth pixels."""
import json

import cv2
import numpy as np
import pytest

import omniscan

# A Mei camera with every distortion term, as docs/FORMATS.md describes camera.json.
MEI = {"xi": 0.92, "fx_px": 310.0, "fy_px": 305.0, "cx_px": 321.5, "cy_px": 238.25,
       "k1": -0.12, "k2": 0.03, "p1": 1.5e-3, "p2": -8e-4, "width": 640, "height": 480,
       "viewpoint_mm": [1.0, -2.0, 80.0]}


def mei_camera(**changes):
    model = {"kind": "mei", **MEI, **changes}
    return omniscan.Camera.from_json(json.dumps({"format": "omniscan.camera", "version": 1, "model": model}))


def opencv_intrinsics():
    k = np.array([[MEI["fx_px"], 0.0, MEI["cx_px"]], [0.0, MEI["fy_px"], MEI["cy_px"]], [0.0, 0.0, 1.0]])
    d = np.array([[MEI["k1"], MEI["k2"], MEI["p1"], MEI["p2"]]])
    return k, d, np.array([[MEI["xi"]]])


def opencv_project(directions):
    """cv2.omnidir.projectPoints of world directions. omniscan's Mei convention (omni_model::mei,
    docs): the sphere frame is the world frame with z flipped (the image centre looks down)."""
    k, d, xi = opencv_intrinsics()
    sphere = (directions * [1.0, 1.0, -1.0]).reshape(1, -1, 3).astype(np.float64)
    px, _ = cv2.omnidir.projectPoints(sphere, np.zeros(3), np.zeros(3), k, xi[0, 0], d)
    return px.reshape(-1, 2)


def test_mei_projection_matches_opencv_omnidir():
    rng = np.random.default_rng(1)
    # Directions below the viewpoint's horizon down to 70° off the downward axis.
    polar = np.radians(rng.uniform(0.0, 70.0, 2000))
    azimuth = rng.uniform(0.0, 2 * np.pi, 2000)
    dirs = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), -np.cos(polar)], axis=1)
    cam = mei_camera()
    ours = cam.point_to_pixel(np.array(MEI["viewpoint_mm"]) + 750.0 * dirs)
    theirs = opencv_project(dirs)
    inside = np.isfinite(ours[:, 0])
    assert inside.mean() > 0.5, "most of these points should be in the 640x480 image"
    # The NaN rows are exactly the pixels outside the image.
    w, h = cam.image_size
    out_of_image = (theirs[:, 0] < -0.5) | (theirs[:, 1] < -0.5) | (theirs[:, 0] > w - 0.5) | (theirs[:, 1] > h - 0.5)
    np.testing.assert_array_equal(~inside, out_of_image)
    np.testing.assert_allclose(ours[inside], theirs[inside], atol=1e-9, rtol=0)


def test_mei_rays_reproject_through_opencv_and_match_its_undistortion():
    cam = mei_camera()
    u, v = np.meshgrid(np.arange(0.0, 640.0, 7.5), np.arange(0.0, 480.0, 7.5))
    pixels = np.stack([u, v], axis=-1)
    origins, dirs = cam.pixel_to_ray(pixels)
    assert origins.shape == dirs.shape == pixels.shape[:2] + (3,)
    ok = np.isfinite(dirs[..., 0])
    assert ok.mean() > 0.99
    np.testing.assert_allclose(origins[ok], np.broadcast_to(MEI["viewpoint_mm"], origins[ok].shape), atol=0)
    np.testing.assert_allclose(np.linalg.norm(dirs[ok], axis=-1), 1.0, atol=1e-12)
    # OpenCV projects our rays back onto the pixels they came from.
    np.testing.assert_allclose(opencv_project(dirs[ok]), pixels[ok], atol=1e-6, rtol=0)
    # cv2.omnidir.undistortPoints gives the perspective image (x/z, y/z) of the sphere point.
    k, d, xi = opencv_intrinsics()
    und = cv2.omnidir.undistortPoints(pixels[ok].reshape(1, -1, 2), k, d, xi, np.eye(3)).reshape(-1, 2)
    sphere = dirs[ok] * [1.0, 1.0, -1.0]
    front = sphere[:, 2] > 0.2
    np.testing.assert_allclose(und[front], sphere[front, :2] / sphere[front, 2:], atol=1e-6, rtol=0)


def test_hyperbolic_camera_round_trip_and_truth_pixels(sim):
    cam = omniscan.Camera.load(sim["camera"])
    assert cam.kind == "hyperbolic"
    cx, cy, r_in, r_out = cam.mirror_circle
    radius = np.linspace(r_in + 1.0, r_out - 1.0, 40)
    azimuth = np.linspace(0.0, 2 * np.pi, 90, endpoint=False)
    rr, aa = np.meshgrid(radius, azimuth)
    pixels = np.stack([cx + rr * np.cos(aa), cy + rr * np.sin(aa)], axis=-1).reshape(-1, 2)
    origins, dirs = cam.pixel_to_ray(pixels)
    assert np.isfinite(dirs).all(), "every pixel inside the annulus sees the scene"
    back = cam.point_to_pixel(origins + 800.0 * dirs)
    np.testing.assert_allclose(back, pixels, atol=1e-6, rtol=0)
    # The simulator's true stripe points appear at its true pixels.
    truth = np.array([p for rec in sim["truth"] for p in rec["points"]])
    assert len(truth) > 100
    np.testing.assert_allclose(cam.point_to_pixel(truth[:, :3]), truth[:, 3:5], atol=1e-6, rtol=0)


def test_pixels_outside_the_mirror_have_no_ray(sim):
    cam = omniscan.Camera.load(sim["camera"])
    cx, cy, r_in, _ = cam.mirror_circle
    origins, dirs = cam.pixel_to_ray([[cx, cy], [-5.0, -5.0], [cx + r_in + 2.0, cy]])
    assert np.isnan(dirs[:2]).all() and np.isnan(origins[:2]).all()
    assert np.isfinite(dirs[2]).all()


def test_the_lens_blur_comes_from_the_measurement_else_the_optics():
    doc = {"format": "omniscan.camera", "version": 1, "model": {"kind": "mei", **MEI}}
    assert omniscan.Camera.from_json(json.dumps(doc)).lens_blur_px is None
    # F/4 at 650 nm on 4.65 um pixels, a 1.5 px blur circle: hypot(0.42 * 0.559, 1.5 / 4) px.
    doc["optics"] = {"wavelength_nm": 650.0, "f_number": 4.0, "pixel_pitch_um": 4.65, "defocus_px": 1.5}
    expected = np.hypot(0.42 * 0.65 * 4.0 / 4.65, 1.5 / 4.0)
    assert omniscan.Camera.from_json(json.dumps(doc)).lens_blur_px == pytest.approx(expected, rel=1e-9)
    # Focused at a distance, the blur varies over the image: no one figure.
    focused = dict(doc["optics"], defocus_px=0.0, focus_mm=91.0)
    assert omniscan.Camera.from_json(json.dumps(dict(doc, optics=focused))).lens_blur_px is None
    doc["lens_blur_px"] = 0.6
    assert omniscan.Camera.from_json(json.dumps(doc)).lens_blur_px == 0.6
    doc["lens_blur_px"] = 9.0
    with pytest.raises(omniscan.FormatError, match="lens_blur_px"):
        omniscan.Camera.from_json(json.dumps(doc))


def test_bad_files_and_arguments_are_refused_with_their_names(tmp_path):
    with pytest.raises(OSError, match="missing.json"):
        omniscan.Camera.load(tmp_path / "missing.json")
    doc = {"format": "omniscan.camera", "version": 99, "model": {"kind": "mei", **MEI}}
    (tmp_path / "camera.json").write_text(json.dumps(doc))
    with pytest.raises(omniscan.FormatError, match=r"camera\.json.*version"):
        omniscan.Camera.load(tmp_path / "camera.json")
    with pytest.raises(omniscan.FormatError, match="fx_px"):
        mei_camera(fx_px=-1.0)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        mei_camera().pixel_to_ray(np.zeros((4, 3)))


# The ordinary cameras as the real hand-held set's OpenCV fits (docs/DECISIONS.md).
PINHOLE = {"kind": "pinhole", "fx_px": 740.3, "fy_px": 740.9, "cx_px": 668.2, "cy_px": 313.6, "k1": -0.3275,
           "k2": 0.1156, "p1": -5.6e-4, "p2": 5.4e-4, "k3": -0.0192, "width": 1280, "height": 720,
           "viewpoint_mm": [1.0, -2.0, 3.0]}
FISHEYE = {"kind": "fisheye", "fx_px": 725.95, "fy_px": 726.3, "cx_px": 673.5, "cy_px": 308.6, "k1": -0.0352,
           "k2": -0.0203, "k3": 0.0323, "k4": -0.0158, "width": 1280, "height": 720,
           "viewpoint_mm": [1.0, -2.0, 3.0]}


@pytest.mark.parametrize("model", [PINHOLE, FISHEYE], ids=["pinhole", "fisheye"])
def test_ordinary_cameras_match_opencv(model):
    """Kinds pinhole and fisheye against cv2.projectPoints / cv2.fisheye.projectPoints: OpenCV's
    camera frame is the world frame about the viewpoint with z flipped (the image looks down)."""
    cam = omniscan.Camera.from_json(json.dumps({"format": "omniscan.camera", "version": 1, "model": model}))
    assert cam.kind == model["kind"]
    # (The pinhole fit's distortion turns back just inside the image's corners: no ray there.)
    u, v = np.meshgrid(np.linspace(80, 1200, 15), np.linspace(40, 680, 9))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    origins, dirs = cam.pixel_to_ray(pixels)
    assert np.isfinite(dirs).all()
    np.testing.assert_allclose(origins, np.broadcast_to(model["viewpoint_mm"], origins.shape))
    k = np.array([[model["fx_px"], 0, model["cx_px"]], [0, model["fy_px"], model["cy_px"]], [0, 0, 1.0]])
    pts = (dirs * [1.0, 1.0, -1.0]).reshape(-1, 1, 3)
    if model["kind"] == "fisheye":
        d = np.array([[model["k1"]], [model["k2"]], [model["k3"]], [model["k4"]]])
        px, _ = cv2.fisheye.projectPoints(pts, np.zeros((3, 1)), np.zeros((3, 1)), k, d)
    else:
        d = np.array([[model["k1"], model["k2"], model["p1"], model["p2"], model["k3"]]])
        px, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, d)
    np.testing.assert_allclose(px.reshape(-1, 2), pixels, atol=1e-8, rtol=0)
    back = cam.point_to_pixel(origins + 500.0 * dirs)
    np.testing.assert_allclose(back, pixels, atol=1e-8, rtol=0)
