#!/usr/bin/env python3
"""Side-by-side benchmark of omniscan's cloud operations and Open3D's, same cloud, same parameters.

Generates a room-like cloud (points on the walls of a 4 x 3 x 2.5 m box, 0.3 mm noise, plus 0.5 %
scattered outliers), writes it as binary PLY, then times on that file:
  * voxel-grid downsampling at each --voxel size (omniscan anchored like Open3D: min bound -
    size/2; best of three). omniscan uses all cores on fine grids (rayon), Open3D's
    voxel_down_sample is single-threaded. Reported as wall time and as CPU time (omniscan: all its
    threads; Open3D: its one thread): on a machine shared with other work the wall clock also
    measures the other processes (the script prints the load average), the CPU time is the work
    done, and on an idle machine omniscan's wall time is about its CPU time / threads,
  * statistical outlier removal (Open3D remove_statistical_outlier(nb_neighbors, std_ratio)),
  * radius outlier removal (Open3D remove_radius_outlier(nb_points, radius)),
  * binary PLY write, and binary PLY read (best of three each: omni_formats::ply::read_ply through
    the read_ply example, Open3D read_point_cloud),
and checks that the kept sets are identical (same point indices) and that the voxel centroids agree.

Needs: numpy and open3d (`pip install open3d`; on Debian its wheel also needs the system package
libusb-1.0-0). Without open3d the script still times omniscan and says so.

Usage: scripts/bench_cloud.py [--points 2000000] [--voxel 5,10,50] [--k 20] [--std-ratio 2.0]
                              [--nb-points 8] [--radius 15] [--keep DIR]
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np


def room_cloud(n, seed):
    rng = np.random.default_rng(seed)
    half = np.array([2000.0, 1500.0, 1250.0])
    pts = (rng.random((n, 3)) * 2.0 - 1.0) * half
    wall = rng.integers(0, 6, n)
    axis = wall // 2
    sign = np.where(wall % 2 == 0, -1.0, 1.0)
    pts[np.arange(n), axis] = sign * half[axis] + rng.normal(0.0, 0.3, n)
    outliers = n // 200
    pts[:outliers] = (rng.random((outliers, 3)) * 2.0 - 1.0) * half * 0.9
    return pts.astype(np.float32)


def write_ply(path, pts):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(np.ascontiguousarray(pts, dtype="<f4").tobytes())


def build_ours(repo):
    for package, example in [("omni-cloud", "bench_filters"), ("omni-formats", "read_ply")]:
        subprocess.run(["cargo", "build", "--release", "-q", "-p", package, "--example", example], cwd=repo, check=True)
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", repo / "target"))
    return target / "release" / "examples" / "bench_filters", target / "release" / "examples" / "read_ply"


def run_open3d(path, a, out):
    import open3d as o3d

    res = {"read_s": float("inf")}
    for _ in range(3):
        t = time.perf_counter()
        pcd = o3d.io.read_point_cloud(str(path))
        res["read_s"] = min(res["read_s"], time.perf_counter() - t)
    res["voxel"] = []
    for size in a.voxel:
        wall, cpu = float("inf"), float("inf")
        for _ in range(3):
            t, c = time.perf_counter(), time.thread_time()
            down = pcd.voxel_down_sample(size)
            wall, cpu = min(wall, time.perf_counter() - t), min(cpu, time.thread_time() - c)
        res["voxel"].append({"size": size, "s": wall, "cpu_s": cpu, "count": len(down.points),
                             "points": np.asarray(down.points)})
    t = time.perf_counter()
    _, sor_idx = pcd.remove_statistical_outlier(nb_neighbors=a.k, std_ratio=a.std_ratio)
    res["sor_s"] = time.perf_counter() - t
    res["sor_idx"] = np.asarray(sor_idx)
    t = time.perf_counter()
    _, ror_idx = pcd.remove_radius_outlier(nb_points=a.nb_points, radius=a.radius)
    res["ror_s"] = time.perf_counter() - t
    res["ror_idx"] = np.asarray(ror_idx)
    t = time.perf_counter()
    o3d.io.write_point_cloud(str(out / "o3d_written.ply"), pcd, write_ascii=False)
    res["write_s"] = time.perf_counter() - t
    return res


def read_xyz(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    n = int(header.split("element vertex ")[1].split()[0])
    props = [l.split()[-1] for l in header.splitlines() if l.startswith("property")]
    arr = np.frombuffer(data[end:], dtype="<f4", count=n * len(props)).reshape(n, len(props))
    return arr[:, :3].astype(np.float64)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--points", type=int, default=2_000_000)
    p.add_argument("--voxel", type=lambda s: [float(v) for v in s.split(",")], default=[5.0, 10.0, 50.0],
                   help="comma-separated voxel sizes (mm)")
    p.add_argument("--k", type=int, default=20)
    p.add_argument("--std-ratio", type=float, default=2.0)
    p.add_argument("--nb-points", type=int, default=8)
    p.add_argument("--radius", type=float, default=15.0)
    p.add_argument("--keep", help="keep the files in this directory")
    a = p.parse_args()
    repo = pathlib.Path(__file__).resolve().parent.parent
    out = pathlib.Path(a.keep) if a.keep else pathlib.Path(tempfile.mkdtemp(prefix="bench_cloud_"))
    out.mkdir(parents=True, exist_ok=True)
    cloud_path = out / "room.ply"
    write_ply(cloud_path, room_cloud(a.points, 1))
    exe, read_exe = build_ours(repo)
    ours_out = subprocess.run(
        [str(exe), str(cloud_path), str(out), ",".join(str(v) for v in a.voxel), str(a.k), str(a.std_ratio), str(a.nb_points), str(a.radius)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    ours = json.loads(ours_out)
    # Reading: best of three on both sides (omni_formats::ply::read_ply, Open3D read_point_cloud).
    ours["read_s"] = json.loads(subprocess.run([str(read_exe), str(cloud_path), "3"], check=True,
                                               capture_output=True, text=True).stdout)["read_s"]
    n = ours["points"]
    try:
        o3d = run_open3d(cloud_path, a, out)
    except ImportError as e:
        o3d = None
        print(f"open3d is not importable ({e}); timing omniscan only", file=sys.stderr)

    rate = lambda s: n / s / 1e6
    print(f"cloud: {n} points, voxel {a.voxel} mm, SOR k={a.k} std_ratio={a.std_ratio}, "
          f"ROR nb_points={a.nb_points} radius={a.radius} mm; omniscan threads: {ours['threads']}")
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores"
          + (" (busy machine: wall times unreliable, compare CPU times)" if load[0] > 0.5 * (os.cpu_count() or 1) else ""))
    print(f"voxel: omniscan on all {ours['threads']} threads (wall; cpu = all threads' CPU time), "
          "Open3D voxel_down_sample single-threaded (wall = cpu)")
    print(f"{'operation':<22}{'omniscan s':>12}{'Mpts/s':>9}{'Open3D s':>12}{'Mpts/s':>9}{'speed-up':>10}  same result")
    for v, mine_v in enumerate(ours["voxel"]):
        size = mine_v["size"]
        for clock, label in [("s", "wall"), ("cpu_s", "cpu")]:
            op = f"voxel {size:g} mm ({label})"
            ts = mine_v[clock]
            if o3d is None:
                print(f"{op:<22}{ts:>12.3f}{rate(ts):>9.1f}")
                continue
            theirs_v = o3d["voxel"][v]
            to = theirs_v[clock]
            same = ""
            if clock == "s":
                mine = read_xyz(out / f"voxel_{v}.ply")
                theirs = theirs_v["points"]
                # Match centroids by the voxel they lie in (Open3D's grid: min bound - size/2).
                origin = read_xyz(cloud_path).min(axis=0) - size / 2.0
                key = lambda c: [tuple(x) for x in np.floor((c - origin) / size).astype(np.int64)]
                ours_by_voxel = dict(zip(key(mine), mine))
                theirs_by_voxel = dict(zip(key(theirs), theirs))
                common = ours_by_voxel.keys() & theirs_by_voxel.keys()
                dev = max((float(np.abs(ours_by_voxel[k] - theirs_by_voxel[k]).max()) for k in common), default=0.0)
                same = (f"{len(mine)} vs {len(theirs)} voxels, {len(common)} shared, max centroid difference "
                        f"{dev:.1e} mm (ours written as float32)")
            print(f"{op:<22}{ts:>12.3f}{rate(ts):>9.1f}{to:>12.3f}{rate(to):>9.1f}{to / ts:>9.2f}x  {same}")
    for op, key in [("statistical outlier", "sor"), ("radius outlier", "ror"),
                    ("PLY write (binary)", "write"), ("PLY read (best of 3)", "read")]:
        ts = ours[f"{key}_s"]
        if o3d is None:
            print(f"{op:<22}{ts:>12.3f}{rate(ts):>9.1f}")
            continue
        to = o3d[f"{key}_s"]
        same = ""
        if key == "sor" or key == "ror":
            mask = np.fromfile(out / f"{key}_mask.u8", dtype=np.uint8).astype(bool)
            ref = np.zeros(n, dtype=bool)
            ref[o3d[f"{key}_idx"]] = True
            diff = int(np.count_nonzero(mask != ref))
            same = f"kept {int(mask.sum())} vs {int(ref.sum())}, {diff} points differ"
        print(f"{op:<22}{ts:>12.3f}{rate(ts):>9.1f}{to:>12.3f}{rate(to):>9.1f}{to / ts:>9.2f}x  {same}")
    if not a.keep:
        for f in out.iterdir():
            f.unlink()
        out.rmdir()


if __name__ == "__main__":
    main()
