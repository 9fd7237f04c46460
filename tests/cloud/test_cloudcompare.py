"""omniscan's PLY files read by CloudCompare's command line (`make test-cloudcompare`, optional:
Debian's `cloudcompare` package takes about a minute to install, beyond CI's budget).

Each cloud is opened with `CloudCompare -SILENT -O FILE` and saved as ASCII (`-C_EXPORT_FMT ASC
-ADD_HEADER`); the point count, coordinates, scalar fields (CloudCompare drops the `scalar_`
prefix of PLY scalar properties) and colours must equal the PLY's as plyfile reads it. Qt runs
with the `offscreen` platform, so no display (or xvfb) is needed. Debian's build (2.11) reads no
PCD (the qPCL plugin) and no LAS (libLAS/PDAL): those cases are skipped when CloudCompare says so,
and run with a build that has the plugins.

Needs the binaries (OMNI_BIN) and the tests/cloud readers; CloudCompare on PATH.
"""

import os
import pathlib
import shutil
import subprocess

import numpy as np
import plyfile
import pytest

from test_cloud_formats import read_ply, scan, tool, xyz  # noqa: F401 (scan is a fixture)

CLOUDCOMPARE = shutil.which("CloudCompare")
if CLOUDCOMPARE is None:
    raise SystemExit("test_cloudcompare: CloudCompare is not on PATH (apt-get install -y cloudcompare)")


def cloudcompare(src, out):
    """CloudCompare's reading of `src` as (column names, float64 array), via its ASCII export."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    r = subprocess.run([CLOUDCOMPARE, "-SILENT", "-AUTO_SAVE", "OFF", "-O", str(src), "-C_EXPORT_FMT", "ASC",
                        "-PREC", "9", "-SEP", "SPACE", "-ADD_HEADER", "-SAVE_CLOUDS", "FILE", str(out)],
                       capture_output=True, text=True, env=env, timeout=120)
    if "unhandled file extension" in r.stdout + r.stderr:
        pytest.skip(f"this CloudCompare build reads no {src.suffix} files")
    assert r.returncode == 0 and out.exists(), r.stdout + r.stderr
    lines = out.read_text().splitlines()
    assert lines[0].startswith("//"), lines[0]
    names = lines[0][2:].split()
    return names, np.loadtxt(lines[1:], ndmin=2)


def test_ply_fields_and_values_equal_in_cloudcompare(scan):
    _, ref = read_ply(scan["ref"])
    for extra in ([], ["--ascii"], ["--double"]):
        src = scan["dir"] / f"cc{''.join(extra)}.ply"
        tool("omni-merge", scan["points"], "-o", src, *extra)
        _, ply = read_ply(src)
        names, got = cloudcompare(src, scan["dir"] / f"{src.stem}.asc")
        assert got.shape == (len(ref), len(ref.dtype.names)), (extra, got.shape)
        want_names = ["X", "Y", "Z"] + [n.removeprefix("scalar_") for n in ref.dtype.names[3:]]
        assert names == want_names, (extra, names)
        # CloudCompare holds coordinates and scalars as float32: 9 decimals give them back exactly.
        assert np.array_equal(got[:, :3].astype(np.float32), xyz(ref).astype(np.float32)), extra
        for k, name in enumerate(ref.dtype.names[3:], start=3):
            assert np.array_equal(got[:, k].astype(np.float32), ref[name]), (extra, name)
        if extra == ["--double"]:
            assert ply.dtype["x"] == np.float64  # written as double, read into CloudCompare's floats


def test_uchar_colours_come_through_as_rgb(scan):
    n = 300
    rng = np.random.default_rng(8)
    v = np.zeros(n, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    v["x"], v["y"], v["z"] = rng.random(n) * 100, rng.random(n) * 100, 1000 + rng.random(n)
    v["red"], v["green"], v["blue"] = rng.integers(0, 256, n), rng.integers(0, 256, n), 3
    src = scan["dir"] / "cc_colours_in.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(src))
    out = scan["dir"] / "cc_colours.ply"
    tool("omni-merge", src, "-o", out)
    names, got = cloudcompare(out, scan["dir"] / "cc_colours.asc")
    assert names[:6] == ["X", "Y", "Z", "R", "G", "B"], names
    for k, c in zip((3, 4, 5), ("red", "green", "blue")):
        assert np.array_equal(got[:, k].astype(np.uint8), v[c]), c
    assert np.array_equal(got[:, :3].astype(np.float32), xyz(v).astype(np.float32))


@pytest.mark.parametrize("ext", ["pcd", "las"])
def test_pcd_and_las_points_in_cloudcompare(scan, ext):
    _, ref = read_ply(scan["ref"])
    src = scan["dir"] / f"cc.{ext}"
    tool("omni-merge", scan["points"], "-o", src)
    names, got = cloudcompare(src, scan["dir"] / f"cc_{ext}.asc")
    assert names[:3] == ["X", "Y", "Z"] and len(got) == len(ref), (names, got.shape)
    # LAS stores 0.01 mm integers; PCD float32 as the PLY.
    assert np.abs(got[:, :3] - xyz(ref)).max() <= (0.005 + 1e-4 if ext == "las" else 1e-4)
