#!/usr/bin/env python3
"""The whole chain on the real hand-held line-laser photographs: receiver, stripes, fixed light
plane, a number in millimetres.

The frames (../shared/data/real-laser-handheld, README there; read in place, never copied) come
from an ordinary wide-angle camera with a red line laser fixed beside it, a 9 x 6 board of 5 mm
squares (nominal) in view:

1. omni-calib-receiver --model mei on the board frames im18-im36 -> camera.json;
2. omni-calib-plane fixed on the stripe frames im1-im17 (omni-ridge's detector, red laser
   contrast) -> scanner.json (kind fixed_planes), plane.json (report), points.jsonl;
   and again with the laser's cross-section given (--laser-tail 0.17,4), and with the one
   omni-calib-plane tail measures on the same frames;
3. the same plane from a reference estimator's centres: per column, the centroid of
   R - (G+B)/2 within +-10 px of the column's maximum, if it exceeds 20 levels (what open laser
   scanners do), given to omni-calib-plane fixed --stripes;
4. the receiver's other models beside OpenCV's on the same detected corners
   (scripts/receiver_models.py: omniscan mei, pinhole, pinhole-radtan, fisheye, robust and
   --least-squares; OpenCV calibrateCamera pinhole, k3 = 0, rational, and cv2.fisheye);
5. one table: receiver RMS per model, plane residual and leave-one-frame-out RMS (mm), plane uncertainty,
   per-frame straightness (px), both estimators; and a picture (plane.png): the 3-D points in the
   plane's own coordinates coloured by their residual, beside the frames with their stripe points.

Usage: scripts/real_plane.py [--bin DIR] [--out DIR]   (`make real-plane`)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# The frames and the column-centroid reference of the stripe detector's own judge.
from real_laser import BOARD_FRAMES, DATA, ROOT, STRIPE_FRAMES, reference_centres  # noqa: E402
import receiver_models  # noqa: E402

# The printed sheet's white border is flat and carries the stripe in five frames (im1, im2, im5,
# im9, im15: 4-7 mm beyond the pattern); the sheet reaches 1.5 squares beyond the pattern or
# more on the sides the stripe crosses (docs/DECISIONS.md, 2026-12-07).
BOARD = {"format": "omniscan.board", "version": 1, "inner_cols": 9, "inner_rows": 6, "square_mm": 5, "margin_mm": 7.5}
# The red laser's cross-section, measured on these frames (docs/DECISIONS.md, 2026-12-03):
# 17 % of the light in a tail 4 core σ long.
LASER_TAIL = "0.17,4"


def run(cmd: list[str]) -> str:
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"real_plane.py: {Path(cmd[0]).name} failed (exit {p.returncode}): {p.stderr.strip()}")
    return p.stdout


def write_reference_stream(path: Path) -> None:
    """The reference centres of every stripe frame as an omniscan stream (images in place)."""
    lines = [{"type": "header", "format": "omniscan.stream", "version": 1,
              "producers": ["real_plane.py column centroid"], "frames_dir": str(DATA)}]
    for seq, name in enumerate(STRIPE_FRAMES):
        bgr = cv2.imread(str(DATA / name), cv2.IMREAD_COLOR)
        if bgr is None:
            sys.exit(f"real_plane.py: {DATA / name}: cannot read")
        pts = reference_centres(bgr)
        lines.append({"type": "frame", "seq": seq, "path": name, "alpha_deg": 0.0, "facet": 0, "lasers": [0],
                      "stripe": [[float(u), float(v), 0.0, 0.0, 0] for u, v in pts]})
    lines.append({"type": "status", "frames": len(STRIPE_FRAMES), "frames_missing": 0, "frames_failed": 0,
                  "complete": True, "errors": []})
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))


def plane_fit(bin_dir: Path, out: Path, tag: str, extra: list[str]) -> dict:
    run([str(bin_dir / "omni-calib-plane"), "fixed", "--camera", str(out / "camera.json"),
         "--board", str(out / "board.json"), "--report", str(out / f"plane{tag}.json"),
         "--points", str(out / f"points{tag}.jsonl"), "-o", str(out / f"scanner{tag}.json"), *extra])
    return json.loads((out / f"plane{tag}.json").read_text())["report"]


def colour(residual: np.ndarray, scale: float) -> np.ndarray:
    """BGR colours of residuals (mm): blue -scale ... green 0 ... red +scale (jet)."""
    level = np.clip((residual / scale + 1.0) * 127.5, 0, 255).astype(np.uint8).reshape(-1, 1)
    return cv2.applyColorMap(level, cv2.COLORMAP_JET).reshape(-1, 3)


def picture(out: Path, report: dict) -> Path:
    """plane.png: left, the inliers in the plane's coordinates coloured by residual (+-3 x RMS);
    right, the used frames with their stripe points on the board (inliers green, outliers red)."""
    pts = [json.loads(line) for line in (out / "points.jsonl").read_text().splitlines()]
    xyz = np.array([p["xyz_mm"] for p in pts])
    res = np.array([p["residual_mm"] for p in pts])
    inl = np.array([p["inlier"] for p in pts])
    n = np.array(report["plane"]["normal"])
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    c = xyz[inl].mean(axis=0)
    uv = np.stack([(xyz - c) @ e1, (xyz - c) @ e2], axis=1)
    size = 720
    span = np.abs(uv[inl]).max() * 1.05
    img = np.full((size, size, 3), 255, np.uint8)
    scale = 3.0 * report["rms_mm"]
    cols = colour(res, scale)
    for (u, v), col, ok in zip(uv, cols, inl):
        x, y = int((u / span + 1) * size / 2), int((v / span + 1) * size / 2)
        if 0 <= x < size and 0 <= y < size:
            if ok:
                cv2.circle(img, (x, y), 2, tuple(int(k) for k in col), -1)
            else:
                cv2.drawMarker(img, (x, y), (0, 0, 0), cv2.MARKER_CROSS, 5)
    cv2.putText(img, f"residual -{scale:.3f} (blue) .. +{scale:.3f} mm (red); x = outlier; span {2 * span:.0f} mm",
                (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    # The frames, 4 per row, each 320 x 180 with its stripe points.
    names = [f["name"] for f in report["frames"]]
    tiles = []
    for name in names:
        bgr = cv2.imread(name, cv2.IMREAD_COLOR)
        mine = [p for p in pts if p["frame"] == name]
        for p in mine:
            cv2.circle(bgr, (int(round(p["px"][0])), int(round(p["px"][1]))), 2,
                       (0, 255, 0) if p["inlier"] else (0, 0, 255), -1)
        tile = cv2.resize(bgr, (320, 180), interpolation=cv2.INTER_AREA)
        cv2.putText(tile, Path(name).name, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
        tiles.append(tile)
    while len(tiles) % 4:
        tiles.append(np.zeros((180, 320, 3), np.uint8))
    grid = np.vstack([np.hstack(tiles[i:i + 4]) for i in range(0, len(tiles), 4)])
    h = max(size, grid.shape[0])
    canvas = np.full((h, size + grid.shape[1], 3), 255, np.uint8)
    canvas[:size, :size] = img
    canvas[:grid.shape[0], size:] = grid
    path = out / "plane.png"
    cv2.imwrite(str(path), canvas)
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", type=Path, default=Path(os.environ.get("OMNISCAN_BIN", ROOT / "target" / "debug")),
                    help="directory of the omni-* tools (default: $OMNISCAN_BIN or target/debug)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "real-plane", help="output directory")
    a = ap.parse_args()
    if not DATA.is_dir():
        sys.exit(f"real_plane.py: {DATA}: missing (the shared real photographs)")
    out = a.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "board.json").write_text(json.dumps(BOARD, indent=1) + "\n")
    run([str(a.bin / "omni-calib-receiver"), "--model", "mei", "--board", str(out / "board.json"),
         "-o", str(out / "camera.json"), *[str(DATA / n) for n in BOARD_FRAMES]])
    cam = json.loads((out / "camera.json").read_text())["report"]
    ridge = plane_fit(a.bin, out, "", [str(DATA / n) for n in STRIPE_FRAMES])
    # The same with the laser's cross-section given (measured on these frames, docs/DECISIONS.md).
    tailed = plane_fit(a.bin, out, "-tail", ["--laser-tail", LASER_TAIL, *[str(DATA / n) for n in STRIPE_FRAMES]])
    # And with the cross-section omni-calib-plane tail measures on the same frames.
    measured_tail = subprocess.run([str(a.bin / "omni-calib-plane"), "tail", "-q", "--report", str(out / "tail.json"),
                                    *[str(DATA / n) for n in STRIPE_FRAMES]],
                                   check=True, capture_output=True, text=True).stdout.strip()
    measured = plane_fit(a.bin, out, "-measured-tail",
                         ["--laser-tail", measured_tail, *[str(DATA / n) for n in STRIPE_FRAMES]])
    write_reference_stream(out / "reference.jsonl")
    ref = plane_fit(a.bin, out, "-reference", ["--stripes", str(out / "reference.jsonl")])
    png = picture(out, ridge)
    models = receiver_models.compare(a.bin, out / "board.json", [str(DATA / n) for n in BOARD_FRAMES],
                                     out / "receiver-models", float(BOARD["square_mm"]))

    print(f"receiver (mei, im18-im36): {cam['images_used']} of {len(BOARD_FRAMES)} boards, "
          f"RMS {cam['rms_per_corner_px']:.3f} px per corner")
    receiver_models.print_table("receiver RMS per corner (px) per model, beside OpenCV's on the same corners "
                                "(im18-im36, omniscan's detection):", models)
    print("plane from stripe frames im1-im17 (9 x 6 board, 5 mm squares nominal; mm):")
    print(f"{'centres':<22} {'frames':>6} {'points':>7} {'rms_mm':>8} {'loo_mm':>8} {'loo/rms':>7} "
          f"{'normal_sd_deg':>13} {'dist_sd_mm':>10}  (sigma: jackknife over frames)")
    rows = (("omni-ridge", ridge), (f" --laser-tail {LASER_TAIL}", tailed),
            (f" --laser-tail {measured_tail}", measured), ("column centroid", ref))
    for label, r in rows:
        p = r["plane"]
        print(f"{label:<22} {len(r['frames']):>6} {r['inliers']:>7} {r['rms_mm']:>8.4f} "
              f"{r['leave_one_out_rms_mm']:>8.4f} {r['leave_one_out_rms_mm'] / r['rms_mm']:>7.2f} "
              f"{p['jackknife_normal_sigma_deg']:>13.4f} {p['jackknife_distance_sigma_mm']:>10.4f}")
    p = ridge["plane"]
    print(f"plane (omni-ridge): normal ({p['normal'][0]:.5f}, {p['normal'][1]:.5f}, {p['normal'][2]:.5f}), "
          f"distance {p['distance_mm']:.3f} mm; sigma from the fit {p['normal_sigma_deg']:.4f} deg, "
          f"{p['distance_sigma_mm']:.4f} mm")
    print("per frame (straightness: RMS distance from the frame's own 3-D line, as imaged):")
    print(f"{'frame':<8} {'rms_mm':>8} {'loo_mm':>8} {'line_px':>8} | {'ref_rms':>8} {'ref_loo':>8} {'ref_px':>8}")
    refs = {Path(f["name"]).name: f for f in ref["frames"]}
    for f in ridge["frames"]:
        name = Path(f["name"]).name
        g = refs.get(name)
        tail = (f"{g['residual_rms_mm']:>8.4f} {g['leave_one_out_rms_mm']:>8.4f} {g['straightness_px']:>8.3f}"
                if g else f"{'-':>8} {'-':>8} {'-':>8}")
        print(f"{name:<8} {f['residual_rms_mm']:>8.4f} {f['leave_one_out_rms_mm']:>8.4f} "
              f"{f['straightness_px']:>8.3f} | {tail}")
    for s in ridge["skipped"]:
        print(f"skipped {Path(s['name']).name}: {s['reason']}")
    print(f"picture: {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
