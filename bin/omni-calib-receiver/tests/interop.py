#!/usr/bin/env python3
"""Interop of omni-calib-receiver's calibration files with independent implementations.

Run by `make test-calib-interop` (mk/calib.mk):  .venv/bin/python interop.py BINARY

References, none of them omniscan code:
* OpenCV's omnidir module (cv2.omnidir.projectPoints, cv2.FileStorage), on both sides of every
  OpenCV and Kalibr round trip: files we export are read and used by OpenCV; files OpenCV (or
  PyYAML, as Kalibr) writes are imported and compared with OpenCV's projection.
* OCamCalib's cam2world / world2cam, written below from the toolbox's documentation: a pixel
  (row, column) minus the centre (xc, yc), through the inverse of the affine matrix [c d; e 1],
  gives (x, y), and the direction is (x, y, f(rho)) with f the direct polynomial; world2cam
  takes theta = atan(z / sqrt(x^2 + y^2)), rho = invpol(theta), and
  (row, column) = (x' c + y' d + xc, x' e + y' + yc) with (x', y') = (x, y) rho / sqrt(x^2 + y^2).

Frames (docs/FORMATS.md): OpenCV's and Kalibr's unit sphere is (x, y, -z) of the omniscan world
about the viewpoint; OCamCalib's (x, y, z) is (y, x, z) of it (rows first).
Prints the measured agreement per format; exits 1 on the first failed check.
"""
import json
import math
import os
import subprocess
import sys
import tempfile

try:
    import cv2
    import numpy as np
    import yaml
except ImportError as e:
    sys.exit(f"interop.py: {e}: run scripts/deps.sh (installs numpy, opencv-contrib-python-headless, pyyaml into .venv)")

BIN = sys.argv[1] if len(sys.argv) > 1 else "omni-calib-receiver"
HERE = os.path.dirname(os.path.abspath(__file__))
OCAM_SAMPLE = os.path.join(HERE, "..", "..", "..", "testdata", "ocam", "calib_results_v3.txt")
RESULTS = []


def run(*args, stdin=None):
    p = subprocess.run([BIN, *args], input=stdin, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"interop.py: {' '.join(args)} failed: {p.stderr.strip()}")
    return p


def check(name, value, limit, unit):
    RESULTS.append((name, value, limit, unit))
    if not value <= limit:
        sys.exit(f"interop.py: FAILED {name}: {value:.3g} {unit} > {limit:g} {unit}")


def query(camera, rows):
    """omni-calib-receiver query --json: rows of 2 (pixels) or 3 (points) numbers."""
    lines = "\n".join(json.dumps(list(map(float, r))) for r in rows) + "\n"
    out = run("query", "--camera", camera, "--json", stdin=lines).stdout.splitlines()
    return [json.loads(line) for line in out]


def write_camera(path, model):
    with open(path, "w") as f:
        json.dump({"format": "omniscan.camera", "version": 1, "model": model}, f)


MEI = {"kind": "mei", "xi": 0.93, "fx_px": 310.5, "fy_px": 311.25, "cx_px": 377.1, "cy_px": 239.7,
       "k1": -0.21, "k2": 0.034, "p1": 1.2e-3, "p2": -7e-4, "width": 752, "height": 480,
       "inner_radius_px": 40.0, "outer_radius_px": 235.0, "viewpoint_mm": [5.0, -3.0, 80.0]}


def annulus_pixels(cx, cy, r0, r1, n=24):
    """A polar grid of pixels inside the annulus."""
    out = []
    for i in range(n):
        r = r0 + (r1 - r0) * (i + 0.5) / n
        for k in range(36):
            a = 2 * math.pi * (k + 0.25 * i) / 36
            out.append((cx + r * math.cos(a), cy + r * math.sin(a)))
    return out


def to_cv(points, viewpoint):
    """omniscan world points -> OpenCV/Kalibr camera frame: (x, y, -z) about the viewpoint."""
    p = np.asarray(points, float) - np.asarray(viewpoint, float)
    return p * np.array([1.0, 1.0, -1.0])


def cv_project(points_cv, K, D, xi):
    pts = np.ascontiguousarray(points_cv, dtype=np.float64).reshape(-1, 1, 3)
    zero = np.zeros((3, 1))
    img, _ = cv2.omnidir.projectPoints(pts, zero, zero, np.asarray(K, float), float(xi), np.asarray(D, float).reshape(1, 4))
    return img.reshape(-1, 2)


def ray_angle_from_pixels(K, D, xi, dirs_cv, pixels, h=1e-4):
    """The angle (deg) between each ray and the ray OpenCV sees at its pixel: the pixel error
    divided by OpenCV's angular scale at that ray (numerical, from projectPoints)."""
    dirs = np.asarray(dirs_cv, float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    base = cv_project(dirs, K, D, xi)
    err = np.linalg.norm(base - np.asarray(pixels, float), axis=1)
    # Smallest angular scale (px/rad) of two perpendicular nudges bounds the angle from above.
    a = np.cross(dirs, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(dirs, a)
    scale = np.minimum(*(np.linalg.norm(cv_project(dirs + h * v, K, D, xi) - base, axis=1) / h for v in (a, b)))
    return np.degrees(err / scale), err


def mei_checks(tmp):
    cam = os.path.join(tmp, "mei.json")
    write_camera(cam, MEI)
    vp = MEI["viewpoint_mm"]
    pixels = annulus_pixels(MEI["cx_px"], MEI["cy_px"], MEI["inner_radius_px"] + 1, MEI["outer_radius_px"] - 1)
    rays = query(cam, pixels)
    dirs = np.array([r["dir"] for r in rays])
    assert all(r["origin_mm"] == vp for r in rays), "rays start at the viewpoint"
    points = np.asarray(vp) + 1500.0 * dirs
    ours = np.array([r["px"] for r in query(cam, points)])

    # Export -> OpenCV reads the file (cv2.FileStorage) and projects (cv2.omnidir).
    yml = os.path.join(tmp, "omnidir.yaml")
    run("export", cam, "--to", "opencv", "-o", yml)
    fs = cv2.FileStorage(yml, cv2.FILE_STORAGE_READ)
    K, D, xi = fs.getNode("K").mat(), fs.getNode("D").mat(), fs.getNode("xi").mat()[0, 0]
    assert (fs.getNode("image_width").real(), fs.getNode("image_height").real()) == (752, 480)
    fs.release()
    cv = cv_project(to_cv(points, vp), K, D, xi)
    check("opencv export: points -> pixels, ours vs cv2", np.abs(cv - ours).max(), 1e-6, "px")
    angle, err = ray_angle_from_pixels(K, D, xi, to_cv(points, vp), pixels)
    check("opencv export: pixel -> ray, cv2 reprojection", err.max(), 1e-6, "px")
    check("opencv export: pixel -> ray angle", angle.max(), 1e-6, "deg")

    # Without the frame change OpenCV is far off: the check above can fail.
    wrong = cv_project(np.asarray(points) - np.asarray(vp), K, D, xi)
    assert np.nanmax(np.abs(wrong - ours)) > 50, "the frame change matters"

    # Import: OpenCV writes the file (cv2.FileStorage), we read it.
    src = os.path.join(tmp, "opencv_written.yaml")
    K2 = np.array([[295.0, 0, 370.0], [0, 296.5, 245.0], [0, 0, 1]])
    D2, xi2 = np.array([[-0.18, 0.02, 5e-4, -2e-4]]), 1.07
    fs = cv2.FileStorage(src, cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 752)
    fs.write("image_height", 480)
    fs.write("K", K2)
    fs.write("D", D2)
    fs.write("xi", np.array([[xi2]]))
    fs.release()
    imported = os.path.join(tmp, "from_opencv.json")
    run("import-opencv", src, "-o", imported)
    pix2 = annulus_pixels(370.0, 245.0, 40, 230)
    dirs2 = np.array([r["dir"] for r in query(imported, pix2)])
    pts2 = 1500.0 * dirs2
    ours2 = np.array([r["px"] for r in query(imported, pts2)])
    cv2_px = cv_project(to_cv(pts2, [0, 0, 0]), K2, D2, xi2)
    check("opencv import: points -> pixels, ours vs cv2", np.abs(cv2_px - ours2).max(), 1e-6, "px")
    angle, err = ray_angle_from_pixels(K2, D2, xi2, to_cv(pts2, [0, 0, 0]), pix2)
    check("opencv import: pixel -> ray angle", angle.max(), 1e-6, "deg")

    # Kalibr: our camchain read by PyYAML (as Kalibr does) and used through cv2.omnidir.
    chain = os.path.join(tmp, "camchain.yaml")
    run("export", cam, "--to", "kalibr", "--rostopic", "/test/image", "-o", chain)
    with open(chain) as f:
        c0 = yaml.safe_load(f)["cam0"]
    assert c0["rostopic"] == "/test/image" and c0["cam_overlaps"] == [], c0
    assert c0["camera_model"] == "omni" and c0["distortion_model"] == "radtan" and c0["resolution"] == [752, 480]
    xi_k, fu, fv, pu, pv = c0["intrinsics"]
    Kk = np.array([[fu, 0, pu], [0, fv, pv], [0, 0, 1]])
    kal = cv_project(to_cv(points, vp), Kk, c0["distortion_coeffs"], xi_k)
    check("kalibr export: points -> pixels, ours vs cv2", np.abs(kal - ours).max(), 1e-6, "px")
    # A camchain written by PyYAML in Kalibr's layout (plus a second camera) imports.
    written = os.path.join(tmp, "kalibr_written.yaml")
    chain2 = {"cam0": {"camera_model": "omni", "intrinsics": [xi2, 295.0, 296.5, 370.0, 245.0],
                       "distortion_model": "radtan", "distortion_coeffs": D2[0].tolist(),
                       "resolution": [752, 480], "rostopic": "/cam0/image_raw", "cam_overlaps": [1]},
              "cam1": {"T_cn_cnm1": np.eye(4).tolist(), "camera_model": "pinhole"}}
    for style in (None, False):  # Kalibr's flow lists, and block lists
        with open(written, "w") as f:
            yaml.safe_dump(chain2, f, default_flow_style=style)
        from_kalibr = os.path.join(tmp, "from_kalibr.json")
        run("import-kalibr", written, "-o", from_kalibr)
        ours_k = np.array([r["px"] for r in query(from_kalibr, pts2)])
        check(f"kalibr import ({'block' if style is False else 'flow'} lists): points -> pixels vs cv2",
              np.abs(cv2_px - ours_k).max(), 1e-6, "px")


# --- OCamCalib, written from its documentation (see the module docstring) -----------------

def read_calib_results(path):
    rows = [line.split() for line in open(path) if line.strip() and not line.startswith("#")]
    ss = [float(v) for v in rows[0][1:]]
    invpol = [float(v) for v in rows[1][1:]]
    xc, yc = map(float, rows[2])
    c, d, e = map(float, rows[3])
    height, width = map(int, rows[4])
    return dict(ss=ss, invpol=invpol, xc=xc, yc=yc, c=c, d=d, e=e, height=height, width=width)


def cam2world(m, row, col):
    det = m["c"] - m["d"] * m["e"]
    x = ((row - m["xc"]) - m["d"] * (col - m["yc"])) / det
    y = (-m["e"] * (row - m["xc"]) + m["c"] * (col - m["yc"])) / det
    rho = math.hypot(x, y)
    z = sum(a * rho**k for k, a in enumerate(m["ss"]))
    n = math.sqrt(x * x + y * y + z * z)
    return np.array([x, y, z]) / n


def world2cam(m, X):
    x, y, z = X
    norm = math.hypot(x, y)
    if norm == 0:
        return m["xc"], m["yc"]
    theta = math.atan(z / norm)
    rho = sum(a * theta**k for k, a in enumerate(m["invpol"]))
    xs, ys = x / norm * rho, y / norm * rho
    return xs * m["c"] + ys * m["d"] + m["xc"], xs * m["e"] + ys + m["yc"]


def ocam_ray_angles(m, camera, pixels):
    """Angles (deg) between our rays and cam2world's for (u, v) pixels."""
    ours = [r["dir"] for r in query(camera, pixels)]
    angles = []
    for (u, v), d in zip(pixels, ours):
        ref = cam2world(m, v, u)  # OCamCalib: (row, column)
        ref = np.array([ref[1], ref[0], ref[2]])  # its (x, y, z) is our (y, x, z)
        d = np.asarray(d)
        angles.append(math.degrees(math.atan2(np.linalg.norm(np.cross(ref, d)), float(np.dot(ref, d)))))
    return np.array(angles)


def ocam_checks(tmp):
    # The v3 sample layout: the centre imports unchanged, rays agree with cam2world.
    imported = os.path.join(tmp, "from_ocam.json")
    run("import-ocam", OCAM_SAMPLE, "-o", imported)
    model = json.load(open(imported))["model"]
    assert (model["cy_px"], model["cx_px"]) == (241.019976, 385.783141), model
    m = read_calib_results(OCAM_SAMPLE)
    pixels = annulus_pixels(m["yc"], m["xc"], 20, 235)
    check("ocam import (v3 sample): pixel -> ray angle vs cam2world", ocam_ray_angles(m, imported, pixels).max(), 1e-9, "deg")
    # world2cam with the file's own inverse polynomial against our exact projection.
    dirs = [r["dir"] for r in query(imported, pixels)]
    ours = np.array([r["px"] for r in query(imported, [1000 * np.array(d) for d in dirs])])
    ref = np.array([world2cam(m, (d[1], d[0], d[2]))[::-1] for d in dirs])
    check("ocam import (v3 sample): world2cam (file invpol) vs ours", np.abs(ref - ours).max(), 0.02, "px")

    # Export of a camera with an annulus: world2cam of the written invpol within 0.01 px.
    cam = os.path.join(tmp, "ocam.json")
    write_camera(cam, {"kind": "ocam", "poly": [-190.0, 0.0, 2.2e-3, -2.5e-6, 6.0e-9], "cx_px": 380.25,
                       "cy_px": 241.5, "c": 1.0003, "d": 1e-4, "e": -2e-4, "width": 752, "height": 480,
                       "inner_radius_px": 30.0, "outer_radius_px": 235.0})
    txt = os.path.join(tmp, "calib_results.txt")
    run("export", cam, "--to", "ocam", "-o", txt)
    m = read_calib_results(txt)
    assert (m["xc"], m["yc"]) == (241.5, 380.25), "centre written 0-based, rows first"
    pixels = annulus_pixels(380.25, 241.5, 31, 234)
    check("ocam export: pixel -> ray angle vs cam2world", ocam_ray_angles(m, cam, pixels).max(), 1e-9, "deg")
    dirs = [r["dir"] for r in query(cam, pixels)]
    ours = np.array([r["px"] for r in query(cam, [1000 * np.array(d) for d in dirs])])
    ref = np.array([world2cam(m, (d[1], d[0], d[2]))[::-1] for d in dirs])
    check("ocam export: world2cam (written invpol) vs ours", np.abs(ref - ours).max(), 0.011, "px")


def main():
    with tempfile.TemporaryDirectory() as tmp:
        mei_checks(tmp)
        ocam_checks(tmp)
    for name, value, limit, unit in RESULTS:
        print(f"  ok  {name}: {value:.2e} {unit} (limit {limit:g})")
    print(f"interop.py: {len(RESULTS)} checks passed")


if __name__ == "__main__":
    main()
