#!/usr/bin/env python3
"""omni-ridge on real photographs of a red line laser, judged by geometry.

The frames (../shared/data/real-laser-handheld, README there) have no pixel truth. What is
known: the stripe on the flat board is where two planes meet, so once the image is undistorted
it is a straight line. This module calibrates the camera with OpenCV from the board-only frames
(an undistortion independent of omniscan), finds the board in each stripe frame, and measures,
for omni-ridge and for a reference estimator, on the stripe inside the board's outline:

* coverage: the share of the line's length (sampled every px along it in the frame) with a point
  within 1 px (along the line, and of the line);
* false points: the share of the points on the board more than 3 px off the line;
* RMS (and median absolute distance) of the points within 3 px of the line.

The line of each frame is fitted robustly (in the undistorted image) to both estimators' points
and then refitted to each estimator's own inliers; distances and lengths are measured on its
image in the frame itself (distorted px), so that a constant offset between estimators (an asymmetric
profile's centroid and peak differ) does not count as an error.

The reference is what open laser scanners do: per column of the frame, the centroid of
R - (G+B)/2 within +-10 px of the column's maximum, if the maximum exceeds a threshold.

Run as a script, it prints the per-frame table (`make real-laser`); the tests import it
(bin/omni-ridge/tests/test_real_laser.py).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data" / "real-laser-handheld"
PATTERN = (9, 6)
STRIPE_FRAMES = [f"im{i}.png" for i in range(1, 18)]
BOARD_FRAMES = [f"im{i}.png" for i in range(18, 37)]
# Half-window (px) and threshold (R - (G+B)/2 levels) of the reference column centroid.
REFERENCE_HALF_WINDOW = 10
REFERENCE_THRESHOLD = 20.0
COVERAGE_PX = 1.0
# The board's outline beyond the inner corners (squares): the printed pattern ends 1 square out,
# the paper about 2 more; the stripe often runs on that margin.
MARGIN_SQUARES = 2.5
# Gaps (px along the line) the stripe on the board may have (black squares, speckle).
SPAN_GAP_PX = 40.0
# The stripe's model in the undistorted image: a line bent by a parabola (2), since the paper,
# held by hand, is not quite flat at its edges and OpenCV's undistortion extrapolates there.
BEND_DEGREE = 2
# Red excess (levels) that marks a false point as lying on laser light: a reflection of the
# stripe elsewhere on the board (multipath), a stripe in the image like any other.
GHOST_EXCESS = 4.0
# ... and at least this far (px) off the line: nearer, the laser light is the stripe's own glow,
# and a point there is a wrong centre.
GHOST_MIN_PX = 15.0
SCALE = float(os.environ.get("REAL_LASER_SCALE", "1"))
FALSE_PX = 3.0


def load(name: str) -> np.ndarray:
    img = cv2.imread(str(DATA / name), cv2.IMREAD_COLOR)
    if img is None:
        raise FileNotFoundError(DATA / name)
    return img


def find_board(bgr: np.ndarray) -> np.ndarray | None:
    """The 9 x 6 inner corners (54 x 2, px) refined by cornerSubPix, or None."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, PATTERN, flags)
    if not found:
        # The red stripe over the squares confuses the thresholds in the grey image; the green
        # channel barely sees it.
        found, corners = cv2.findChessboardCorners(bgr[:, :, 1].copy(), PATTERN, flags)
        if not found:
            return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    corners = cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria)
    return corners.reshape(-1, 2)


@dataclass
class Camera:
    """An OpenCV calibration: the model with the lower RMS of pinhole (rational) and fisheye."""

    model: str
    rms: float
    K: np.ndarray
    D: np.ndarray
    size: tuple[int, int]

    def distort(self, pts_u: np.ndarray) -> np.ndarray:
        """Undistorted pixels (N x 2, this camera matrix) back to the frame's pixels."""
        x = cv2.undistortPoints(pts_u.reshape(-1, 1, 2).astype(np.float64), self.K, None)
        obj = np.concatenate([x.reshape(-1, 2), np.ones((len(pts_u), 1))], axis=1).reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.model == "fisheye":
            out, _ = cv2.fisheye.projectPoints(obj, zero, zero, self.K, self.D)
        else:
            out, _ = cv2.projectPoints(obj, zero, zero, self.K, self.D)
        return out.reshape(-1, 2)

    def undistort(self, pts: np.ndarray) -> np.ndarray:
        """Pixels (N x 2) to undistorted pixels with the same camera matrix."""
        if len(pts) == 0:
            return pts.reshape(0, 2)
        p = pts.reshape(-1, 1, 2).astype(np.float64)
        if self.model == "fisheye":
            out = cv2.fisheye.undistortPoints(p, self.K, self.D, P=self.K)
        else:
            out = cv2.undistortPoints(p, self.K, self.D, P=self.K)
        return out.reshape(-1, 2)


def calibrate() -> Camera:
    obj = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float64)
    obj[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * 5.0
    img_pts, obj_pts, size = [], [], None
    for name in BOARD_FRAMES:
        bgr = load(name)
        size = (bgr.shape[1], bgr.shape[0])
        c = find_board(bgr)
        if c is not None:
            img_pts.append(c.astype(np.float64))
            obj_pts.append(obj.copy())
    if len(img_pts) < 8:
        raise RuntimeError(f"only {len(img_pts)} board frames found")
    rms_p, K_p, D_p, _, _ = cv2.calibrateCamera(
        [o.astype(np.float32) for o in obj_pts],
        [i.astype(np.float32) for i in img_pts],
        size,
        None,
        None,
        flags=cv2.CALIB_RATIONAL_MODEL,
    )
    best = Camera("pinhole-rational", rms_p, K_p, D_p, size)
    try:
        K_f = np.zeros((3, 3))
        D_f = np.zeros((4, 1))
        rms_f, K_f, D_f, _, _ = cv2.fisheye.calibrate(
            [o.reshape(-1, 1, 3) for o in obj_pts],
            [i.reshape(-1, 1, 2) for i in img_pts],
            size,
            K_f,
            D_f,
            flags=cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW,
            criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-9),
        )
        if rms_f < best.rms:
            best = Camera("fisheye", rms_f, K_f, D_f, size)
    except cv2.error:
        pass
    return best


def omniscan_boards(binary: Path, names: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The boards omniscan's corner detector finds in `names` (frames of DATA), as (grid indices
    (N x 2: column, row), corners (N x 2, px)) by name: `omni-calib-receiver --save-corners`
    beside `binary`, given the board frames too so that its calibration, and so its corners
    file, never fails for want of boards. For the frames where OpenCV's detector finds no 9 x 6
    board (close-ups whose board is cut or crossed by a saturated stripe): the outline only
    chooses which points are judged, the line and its undistortion stay OpenCV's."""
    if not names:
        return {}
    receiver = binary.parent / "omni-calib-receiver"
    if not receiver.exists():
        raise FileNotFoundError(f"{receiver}: the judge needs it beside {binary.name} for the frames "
                                f"OpenCV finds no board in ({', '.join(names)}); build it")
    with tempfile.TemporaryDirectory() as tmp:
        board = Path(tmp) / "board.json"
        board.write_text(json.dumps({"format": "omniscan.board", "version": 1, "inner_cols": PATTERN[0],
                                     "inner_rows": PATTERN[1], "square_mm": 5}))
        corners = Path(tmp) / "corners.json"
        frames = [str(DATA / n) for n in [*names, *BOARD_FRAMES]]
        p = subprocess.run([str(receiver), "--board", str(board), "--save-corners", str(corners),
                            "-o", str(Path(tmp) / "camera.json"), *frames], capture_output=True, text=True)
        if p.returncode != 0 or not corners.exists():
            raise RuntimeError(f"{receiver.name} failed (exit {p.returncode}): {p.stderr.strip()[-500:]}")
        found = {}
        for image in json.loads(corners.read_text())["images"]:
            c = np.array(image["corners"], np.float64).reshape(-1, 4)
            if Path(image["name"]).name in names and len(c) >= 12:
                found[Path(image["name"]).name] = (c[:, :2], c[:, 2:])
        return found


def board_outline(corners: np.ndarray, margin_squares: float, grid: np.ndarray | None = None) -> np.ndarray:
    """The board's outline (4 x 2, px, distorted image): the inner-corner grid's outer corners
    pushed out by `margin_squares` squares along the grid (a homography of the grid). `grid`:
    the corners' (column, row) indices, if not the whole grid in OpenCV's order."""
    nx, ny = PATTERN
    if grid is None:
        grid = np.mgrid[0:nx, 0:ny].T.reshape(-1, 2).astype(np.float64)
    H, _ = cv2.findHomography(grid, corners)
    m = margin_squares
    quad = np.array([[-m, -m], [nx - 1 + m, -m], [nx - 1 + m, ny - 1 + m], [-m, ny - 1 + m]], np.float64)
    return cv2.perspectiveTransform(quad.reshape(-1, 1, 2), H).reshape(-1, 2)


def inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    if len(pts) == 0:
        return np.zeros(0, bool)
    contour = poly.reshape(-1, 1, 2).astype(np.float32)
    return np.array([cv2.pointPolygonTest(contour, (float(x), float(y)), False) >= 0 for x, y in pts])


def reference_centres(bgr: np.ndarray) -> np.ndarray:
    """Per-column centroid of R - (G+B)/2 within +-10 px of the column maximum (N x 2, px)."""
    b, g, r = (bgr[:, :, k].astype(np.float64) for k in range(3))
    c = np.clip(r - 0.5 * (g + b), 0, None)
    h, w = c.shape
    rows = np.argmax(c, axis=0)
    out = []
    for x in range(w):
        y0 = rows[x]
        if c[y0, x] < REFERENCE_THRESHOLD:
            continue
        lo, hi = max(0, y0 - REFERENCE_HALF_WINDOW), min(h, y0 + REFERENCE_HALF_WINDOW + 1)
        wgt = c[lo:hi, x]
        s = wgt.sum()
        if s > 0:
            out.append((x, float((np.arange(lo, hi) * wgt).sum() / s)))
    return np.array(out, np.float64).reshape(-1, 2)


def fit_line(pts: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Total-least-squares line n.p = d (unit n) through points (N x 2)."""
    if len(pts) < 2:
        return None
    m = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - m)
    n = vt[1]
    return n, float(n @ m)


def robust_line(pts: np.ndarray, tol: float = 2.0, seed: int = 0) -> tuple[np.ndarray, float] | None:
    """RANSAC (pairs of points) then least squares on the points within `tol` px."""
    if len(pts) < 10:
        return None
    rng = np.random.default_rng(seed)
    best, best_count = None, -1
    for _ in range(300):
        i, j = rng.choice(len(pts), 2, replace=False)
        d = pts[j] - pts[i]
        norm = np.hypot(*d)
        if norm < 20:
            continue
        n = np.array([-d[1], d[0]]) / norm
        count = int((np.abs(pts @ n - n @ pts[i]) < tol).sum())
        if count > best_count:
            best, best_count = (n, float(n @ pts[i])), count
    if best is None:
        return None
    for _ in range(3):
        n, d = best
        inl = pts[np.abs(pts @ n - d) < tol]
        refit = fit_line(inl)
        if refit is None:
            return None
        best = refit
    return best


@dataclass
class Curve:
    """A gently bent line in the undistorted image: offset(t) = c0 + c1 t + c2 t^2 along the
    unit normal `n` from the point `p0` + t * tangent (px)."""

    p0: np.ndarray
    n: np.ndarray
    coeffs: np.ndarray

    @property
    def tangent(self) -> np.ndarray:
        return np.array([-self.n[1], self.n[0]])

    def coordinates(self, pts_u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t, offset from the curve) of undistorted points."""
        rel = pts_u - self.p0
        t = rel @ self.tangent
        return t, rel @ self.n - np.polyval(self.coeffs[::-1], t)

    def at(self, t: np.ndarray) -> np.ndarray:
        return self.p0 + t[:, None] * self.tangent + np.polyval(self.coeffs[::-1], t)[:, None] * self.n

    def refit(self, pts_u: np.ndarray, tol: float, iterations: int = 3) -> "Curve":
        """Least squares (degree BEND_DEGREE) on the points within `tol` px, repeated."""
        curve = self
        for _ in range(iterations):
            t, off = curve.coordinates(pts_u)
            inl = np.abs(off) < tol
            if inl.sum() < 10:
                return curve
            rel = pts_u[inl] - self.p0
            c = np.polyfit(rel @ self.tangent, rel @ self.n, BEND_DEGREE)[::-1]
            curve = Curve(self.p0, self.n, np.pad(c, (0, 3 - len(c))))
        return curve

    def sagitta(self, t0: float, t1: float) -> float:
        """Largest distance (px) of the curve from its chord between t0 and t1."""
        t = np.linspace(t0, t1, 50)
        off = np.polyval(self.coeffs[::-1], t)
        chord = off[0] + (off[-1] - off[0]) * (t - t0) / max(t1 - t0, 1e-9)
        return float(np.abs(off - chord).max())


def robust_curve(pts_u: np.ndarray, tol: float = 2.0) -> Curve | None:
    line = robust_line(pts_u, tol)
    if line is None:
        return None
    n, d = line
    t = pts_u @ np.array([-n[1], n[0]])
    p0 = n * d + np.median(t) * np.array([-n[1], n[0]])
    return Curve(p0, n, np.zeros(3)).refit(pts_u, tol)


def segment_on_board(line: tuple[np.ndarray, float], outline_u: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The part of the line inside the (undistorted) outline polygon: its two ends."""
    n, d = line
    t_dir = np.array([-n[1], n[0]])
    p0 = n * d
    ts = []
    k = len(outline_u)
    for i in range(k):
        a, b = outline_u[i], outline_u[(i + 1) % k]
        # Intersect p0 + t * t_dir with a + s (b - a).
        m = np.array([t_dir, a - b]).T
        if abs(np.linalg.det(m)) < 1e-12:
            continue
        t, s = np.linalg.solve(m, a - p0)
        if -1e-9 <= s <= 1 + 1e-9:
            ts.append(t)
    if len(ts) < 2:
        return None
    return p0 + min(ts) * t_dir, p0 + max(ts) * t_dir


def balanced_union(a: np.ndarray, b: np.ndarray, seed: int = 0) -> np.ndarray:
    """Both estimators' points, the larger set subsampled to the smaller's count (when that is
    at least 20), so that neither alone decides where the line is."""
    small, large = sorted((a, b), key=len)
    if len(small) >= 20 and len(large) > len(small):
        keep = np.random.default_rng(seed).choice(len(large), len(small), replace=False)
        large = large[np.sort(keep)]
    return np.vstack([small, large])


def image_curve(cam: Camera, curve: Curve, t0: float, t1: float, step: float = 0.25) -> np.ndarray:
    """The undistorted curve between t0 and t1 as a polyline in the frame itself (distorted
    px), sampled densely enough that consecutive vertices are about `step` px apart there."""
    n = max(2, int(np.ceil(abs(t1 - t0) / step)))
    return cam.distort(curve.at(np.linspace(t0, t1, n)))


def curve_coordinates(curve: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point: its signed distance (px) from the polyline and the arc length (px) of
    its nearest vertex."""
    if len(pts) == 0:
        return np.zeros(0), np.zeros(0)
    seg = np.diff(curve, axis=0)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    tangent = np.vstack([seg, seg[-1:]])
    tangent /= np.hypot(tangent[:, 0], tangent[:, 1])[:, None]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    dist = np.empty(len(pts))
    where = np.empty(len(pts))
    for k in range(0, len(pts), 256):
        chunk = pts[k : k + 256]
        d2 = ((chunk[:, None, :] - curve[None, :, :]) ** 2).sum(axis=2)
        j = d2.argmin(axis=1)
        dist[k : k + 256] = ((chunk - curve[j]) * normal[j]).sum(axis=1)
        where[k : k + 256] = arc[j]
    return dist, where


def stripe_span(curve: np.ndarray, pts: np.ndarray) -> tuple[float, float]:
    """The stretch of the line (arc length along its image, px) where the stripe lies on the
    board: the longest run of points of either estimator within 3 px of the line, with gaps of
    at most SPAN_GAP_PX. Where the stripe leaves the paper (the outline's margin is only nominal)
    it leaves the line, and neither estimator is judged beyond."""
    dist, where = curve_coordinates(curve, pts)
    on = np.sort(where[np.abs(dist) <= FALSE_PX])
    if len(on) == 0:
        return 0.0, 0.0
    breaks = np.flatnonzero(np.diff(on) > SPAN_GAP_PX)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(on) - 1]])
    k = int(np.argmax(on[ends] - on[starts]))
    return float(on[starts[k]]), float(on[ends[k]]) + 1.0


def laser_excess(bgr: np.ndarray) -> np.ndarray:
    """R - (G+B)/2 (3 x 3 mean) above its median over 21 x 21 px, the largest within 2 px: where
    laser light falls."""
    b, g, r = (bgr[:, :, k].astype(np.float32) for k in range(3))
    c = cv2.blur(r - 0.5 * (g + b), (3, 3))
    excess = c - cv2.medianBlur(np.clip(c, 0, 255).astype(np.uint8), 21).astype(np.float32)
    return cv2.dilate(excess, np.ones((5, 5), np.uint8))


def laser_light(excess: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Which points lie on laser light (an excess of at least GHOST_EXCESS levels)."""
    h, w = excess.shape
    x = np.clip(np.round(pts[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.round(pts[:, 1]).astype(int), 0, h - 1)
    return excess[y, x] >= GHOST_EXCESS


@dataclass
class Score:
    points: int = 0
    coverage: float = float("nan")
    false_share: float = float("nan")
    rms: float = float("nan")
    median: float = float("nan")
    # False points on laser light elsewhere (reflections of the stripe): a share of all points.
    ghost_share: float = 0.0


def score(
    cam: Camera,
    pts: np.ndarray,
    curve: Curve | None,
    ends: tuple[float, float],
    span: tuple[float, float],
    laser: np.ndarray | None = None,
) -> Score:
    """Coverage, false points, RMS and median |distance| (px, in the frame) of one estimator's
    points on the board about the common curve refitted to its own inliers, over the stretch
    `span` (arc length along the curve's image, px) where the stripe lies on the board."""
    s = Score(points=len(pts))
    if curve is None:
        return s
    own = curve.refit(cam.undistort(pts), FALSE_PX) if len(pts) >= 10 else curve
    image = image_curve(cam, own, *ends)
    dist, where = curve_coordinates(image, pts)
    lo, hi = span
    keep = (where >= lo) & (where <= hi)
    dist, where = dist[keep], where[keep] - lo
    s.points = int(keep.sum())
    # The line sampled every px; a sample is covered by a point within 1 px of it.
    samples = np.arange(0.5, max(hi - lo, 1.0), 1.0)
    on_line = np.sort(where[np.abs(dist) <= COVERAGE_PX])
    if len(on_line):
        k = np.clip(np.searchsorted(on_line, samples), 1, len(on_line) - 1)
        nearest = np.minimum(np.abs(on_line[k - 1] - samples), np.abs(on_line[k] - samples))
        nearest = np.minimum(nearest, np.abs(on_line[0] - samples))
        s.coverage = float((nearest <= COVERAGE_PX).mean())
    else:
        s.coverage = 0.0
    if s.points:
        off = np.abs(dist) > FALSE_PX
        s.false_share = float(off.mean())
        far = np.abs(dist) > GHOST_MIN_PX
        if laser is not None and far.any():
            s.ghost_share = float(laser_light(laser, pts[keep][far]).sum() / s.points)
        good = np.abs(dist[np.abs(dist) <= FALSE_PX])
        if len(good):
            s.rms = float(np.sqrt((good**2).mean()))
            s.median = float(np.median(good))
    return s


def ridge_points(binary: Path, names: list[str], extra: list[str], frames: Path = DATA) -> dict[str, np.ndarray]:
    """omni-ridge's points (u, v) for each frame, run once over a stream of all of them."""
    with tempfile.TemporaryDirectory() as tmp:
        stream = Path(tmp) / "frames.jsonl"
        lines = [{"type": "header", "format": "omniscan.stream", "version": 1, "producers": ["real_laser.py"], "frames_dir": str(frames)}]
        for k, name in enumerate(names):
            lines.append(
                {"type": "frame", "seq": k, "path": name, "alpha_deg": 0.0, "facet": 0, "revolution": 0,
                 "encoder": 0, "timestamp_us": k, "lasers": [0]}
            )
        lines.append({"type": "status", "frames": len(names), "frames_missing": 0, "frames_failed": 0, "complete": True, "errors": []})
        stream.write_text("".join(json.dumps(x) + "\n" for x in lines))
        run = subprocess.run([str(binary), str(stream), *extra], capture_output=True, text=True)
        if run.returncode != 0:
            raise RuntimeError(f"{binary} failed: {run.stderr.strip()}")
        out = run.stdout
    result = {}
    for line in out.splitlines():
        rec = json.loads(line)
        if rec.get("type") == "frame":
            pts = np.array([[p[0], p[1]] for p in rec.get("stripe", [])], np.float64).reshape(-1, 2)
            pts = pts * SCALE + 0.5 * (SCALE - 1)
            result[names[rec["seq"]]] = pts
    return result


@dataclass
class FrameResult:
    name: str
    board: bool
    # The board found by omniscan's corners, where OpenCV's finds none.
    board_by_omniscan: bool = False
    length_px: float = 0.0
    sagitta_px: float = 0.0
    ridge: Score = field(default_factory=Score)
    reference: Score = field(default_factory=Score)


def evaluate(
    binary: Path,
    extra: list[str],
    names: list[str] = STRIPE_FRAMES,
    margin_squares: float = MARGIN_SQUARES,
    frames: Path = DATA,
) -> tuple[Camera, list[FrameResult]]:
    cam = calibrate()
    ridge = ridge_points(binary, names, extra, frames)
    images = {name: load(name) for name in names}
    boards = {name: find_board(bgr) for name, bgr in images.items()}
    others = omniscan_boards(binary, [n for n, c in boards.items() if c is None])
    results = []
    for name in names:
        bgr = images[name]
        corners, grid = boards[name], None
        if corners is None and name in others:
            grid, corners = others[name]
        if corners is None:
            results.append(FrameResult(name, False))
            continue
        outline = board_outline(corners, margin_squares, grid)
        outline_u = cam.undistort(outline)
        ref = reference_centres(bgr)
        ref_on = ref[inside(outline, ref)]
        rid = ridge.get(name, np.zeros((0, 2)))
        rid_on = rid[inside(outline, rid)]
        ref_u, rid_u = cam.undistort(ref_on), cam.undistort(rid_on)
        curve = robust_curve(balanced_union(ref_u, rid_u))
        seg = segment_on_board((curve.n, float(curve.n @ curve.p0)), outline_u) if curve is not None else None
        fr = FrameResult(name, True, board_by_omniscan=grid is not None)
        if seg is None:
            results.append(fr)
            continue
        ends = tuple(sorted(float((e - curve.p0) @ curve.tangent) for e in seg))
        span = stripe_span(image_curve(cam, curve, *ends), np.vstack([ref_on, rid_on]))
        fr.length_px = span[1] - span[0]
        fr.sagitta_px = curve.sagitta(*ends)
        excess = laser_excess(bgr)
        fr.reference = score(cam, ref_on, curve, ends, span, excess)
        fr.ridge = score(cam, rid_on, curve, ends, span, excess)
        results.append(fr)
    return cam, results


def totals(results: list[FrameResult], which: str) -> Score:
    """One estimator over all frames: coverage weighted by length, false share and RMS over the
    points (RMS pooled, median of the frames' medians)."""
    used = [r for r in results if r.board and r.length_px > 0]
    scores = [getattr(r, which) for r in used]
    out = Score(points=sum(x.points for x in scores))
    length = sum(r.length_px for r in used)
    if length > 0:
        out.coverage = sum(getattr(r, which).coverage * r.length_px for r in used) / length
    if out.points:
        out.false_share = sum(x.false_share * x.points for x in scores if x.points) / out.points
        out.ghost_share = sum(x.ghost_share * x.points for x in scores if x.points) / out.points
        good = [(x.rms, x.points * (1 - x.false_share)) for x in scores if x.points and np.isfinite(x.rms)]
        weight = sum(w for _, w in good)
        out.rms = float(np.sqrt(sum(r * r * w for r, w in good) / weight)) if weight else float("nan")
        out.median = float(np.median([x.median for x in scores if np.isfinite(x.median)]))
    return out


def table(cam: Camera, results: list[FrameResult], label: str = "omni-ridge") -> str:
    def cells(x: Score) -> str:
        return f"{100*x.coverage:6.1f}% {100*x.false_share:5.1f}% {100*x.ghost_share:5.1f}% {x.rms:6.3f} {x.median:6.3f} {x.points:5d}"

    head = f"{'cover':>7} {'false':>6} {'ghost':>6} {'rms':>6} {'med':>6} {'pts':>5}"
    rows = [
        f"camera: OpenCV {cam.model}, RMS {cam.rms:.3f} px on the board frames (the undistortion behind the lines)",
        f"{'':8} {'':7} {'':6} | {label:<41} | reference (column centroid of R-(G+B)/2)",
        f"{'frame':<8} {'len px':>7} {'bend':>6} | {head} | {head}",
    ]
    for r in results:
        if not r.board:
            rows.append(f"{r.name:<8} board not found: skipped")
        elif r.length_px <= 0:
            rows.append(f"{r.name:<8} no stripe on the board")
        else:
            name = r.name + ("*" if r.board_by_omniscan else "")
            rows.append(f"{name:<8} {r.length_px:7.0f} {r.sagitta_px:6.2f} | {cells(r.ridge)} | {cells(r.reference)}")
    length = sum(r.length_px for r in results if r.board)
    rows.append(f"{'total':<8} {length:7.0f} {'':6} | {cells(totals(results, 'ridge'))} | {cells(totals(results, 'reference'))}")
    rows.append("len: the stripe on the board (px along it); bend: its sagitta in the undistorted image (px);")
    rows.append("cover: share of len with a point within 1 px; false: points > 3 px off, of which ghost: > 15 px off")
    rows.append("on laser light (reflections of the stripe: stripes too); rms, med: of the points within 3 px (px)")
    if any(r.board_by_omniscan for r in results):
        rows.append("*: the board's outline from omniscan's corners (OpenCV's detector finds no 9 x 6 board there)")
    return "\n".join(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ridge", default=os.environ.get("OMNI_RIDGE", str(ROOT / "target" / "release" / "omni-ridge")))
    ap.add_argument("--margin", type=float, default=MARGIN_SQUARES, help="board outline margin beyond the inner corners (squares)")
    ap.add_argument("--frames", type=Path, default=DATA, help="where omni-ridge reads the stripe frames (default: the photographs)")
    ap.add_argument("extra", nargs=argparse.REMAINDER, help="omni-ridge options after --")
    args = ap.parse_args()
    extra = [a for a in args.extra if a != "--"]
    cam, results = evaluate(Path(args.ridge), extra, margin_squares=args.margin, frames=args.frames)
    print(table(cam, results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
