"""Open3D reads omniscan's PCD and PLY outputs (`make bench`; Open3D is too big for CI's budget).

Same scan fixture as test_cloud_formats.py: PCD (ASCII, binary) points and scalar fields through
Open3D's legacy and tensor readers, uchar PLY colours as Open3D colours, and omniscan's normals
against Open3D's estimate_normals + orient_normals_towards_camera_location.
"""

import numpy as np
import open3d as o3d
import pytest

from test_cloud_formats import read_ply, scan, tool, write_pcd, xyz  # noqa: F401 (scan is a fixture)


@pytest.mark.parametrize("ascii", [False, True])
def test_pcd_reads_back_in_open3d(scan, ascii):
    _, ref = read_ply(scan["ref"])
    out = write_pcd(scan, ascii)
    pts = np.asarray(o3d.io.read_point_cloud(str(out)).points)
    assert np.array_equal(pts.astype(np.float32), xyz(ref).astype(np.float32))
    t = o3d.t.io.read_point_cloud(str(out))
    for name in ("intensity", "scalar_frame", "scalar_range"):
        assert np.array_equal(t.point[name].numpy().ravel().astype(np.float32), ref[name]), name


def test_uchar_colours_are_open3d_colours(scan):
    n = 100
    v = np.zeros(n, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    v["x"], v["y"], v["z"] = np.arange(n), 2.0, 1000.0
    v["red"], v["green"], v["blue"] = np.arange(n) * 2, 7, 255
    import plyfile

    src, out = scan["dir"] / "o3d_colours.ply", scan["dir"] / "o3d_colours_out.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(src))
    tool("omni-merge", src, "-o", out)
    cols = np.asarray(o3d.io.read_point_cloud(str(out)).colors)
    assert np.allclose(cols[:, 0] * 255, v["red"], atol=1e-6)


def test_normals_match_open3d(scan):
    out = scan["dir"] / "o3d_n.ply"
    tool("omni-merge", scan["points"], "-o", out, "--normals", "--normal-neighbours", "16")
    _, got = read_ply(out)
    p = xyz(got)
    n = np.stack([got["nx"], got["ny"], got["nz"]], axis=1).astype(np.float64)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(16))
    pcd.orient_normals_towards_camera_location(np.zeros(3))
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, np.asarray(pcd.normals)), -1, 1)))
    print(f"normals vs Open3D: median {np.median(angle):.3g}°, 99th percentile {np.percentile(angle, 99):.3g}°")
    assert np.percentile(angle, 99) < 0.5
