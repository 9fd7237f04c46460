"""omniscan's cloud files and ROS 2 bags, read back by independent readers from PyPI.

A small simulated scan (paper sensor at 256 px, the bench plane) goes through omni-ridge and
omni-triangulate; the PLY that omni-triangulate writes is the reference (read with plyfile), and
every other output must hold the same points, fields and values:
  * PCD, ASCII and binary: pypcd4 (Open3D's reader in tests/cloud/bench_open3d.py, `make bench`:
    its wheel and dependencies are ~0.9 GB, minutes to install, beyond the CI budget);
  * LAS 1.4: laspy (coordinates within the 0.01 mm scale, intensity rounded, extra dimensions);
  * PLY options: uchar colours stay uchar, --double, --units m, --normals against a numpy
    plane fit (brute-force neighbours, eigh) oriented towards the same viewpoint;
  * rosbag2 directories: rosbags (metadata.yaml + MCAP, its own PointCloud2 definition) and
    mcap-ros2-support (decodes with the schema text in the file), per frame and per revolution,
    one message larger than the MCAP chunk size; with --rosbag-images the frames as Image
    (mono8, and mono16 from a 2-frame 16-bit scan) equal to the PNGs as OpenCV reads them, and
    CameraInfo equal to camera.json (hyperbolic, and a Mei model with xi first in D).

Run by `make test-cloud` (mk/cloud.mk) with OMNI_BIN naming the directory of the built binaries.
"""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

try:
    import cv2
    import laspy
    import plyfile
    from pypcd4 import PointCloud as PcdCloud
    from mcap.reader import make_reader
    from mcap_ros2.reader import read_ros2_messages
    from rosbags.rosbag2 import Reader as BagReader
    from rosbags.typesys import Stores, get_typestore
except ImportError as e:  # CI installs them: a missing reader is a failure, not a skip.
    raise SystemExit(f"test_cloud_formats: {e}; run scripts/deps.sh to install the readers") from e

BIN = pathlib.Path(os.environ.get("OMNI_BIN", "target/debug"))
STAMP_PERIOD_MS = 5.0
POINT_FIELD_DTYPES = {1: "i1", 2: "u1", 3: "<i2", 4: "<u2", 5: "<i4", 6: "<u4", 7: "<f4", 8: "<f8"}


def tool(name, *args, check=True):
    exe = BIN / name
    if not exe.exists():
        raise SystemExit(f"{exe} is missing: build the binaries first (make test-cloud does)")
    return subprocess.run([str(exe), *map(str, args)], check=check, capture_output=True, text=True)


@pytest.fixture(scope="session")
def scan(tmp_path_factory):
    d = tmp_path_factory.mktemp("scan")
    tool("omni-sim", "sensor", "--preset", "paper", "--width", "256", "-o", d / "sensor")
    tool("omni-sim", "scene", "--bench", "plane", "-o", d / "plane.json")
    cam, scanner = d / "sensor" / "camera.json", d / "sensor" / "scanner.json"
    tool("omni-sim", "scan", "--camera", cam, "--scanner", scanner, "--scene", d / "plane.json",
         "--angles", "12:24:0.5", "--frames", d / "frames", "-o", d / "scan.jsonl")
    tool("omni-ridge", "--camera", cam, d / "scan.jsonl", "-o", d / "ridges.jsonl")
    tool("omni-triangulate", "--camera", cam, "--scanner", scanner, d / "ridges.jsonl",
         "-o", d / "points.jsonl", "--cloud", d / "ref.ply")
    return {"dir": d, "camera": cam, "scanner": scanner, "ridges": d / "ridges.jsonl",
            "points": d / "points.jsonl", "ref": d / "ref.ply"}


def read_ply(path):
    data = plyfile.PlyData.read(str(path))
    return data, data["vertex"].data


def xyz(v):
    return np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)


def test_reference_cloud_is_not_trivial(scan):
    _, v = read_ply(scan["ref"])
    assert len(v) > 100, len(v)
    assert v.dtype.names[:3] == ("x", "y", "z")


def write_pcd(scan, ascii):
    out = scan["dir"] / f"c_{ascii}.pcd"
    if not out.exists():
        tool("omni-triangulate", "--camera", scan["camera"], "--scanner", scan["scanner"], scan["ridges"],
             "-o", out, *(["--ascii"] if ascii else []))
    return out


@pytest.mark.parametrize("ascii", [False, True])
def test_pcd_reads_back_in_pypcd4(scan, ascii):
    _, ref = read_ply(scan["ref"])
    out = write_pcd(scan, ascii)
    header = out.read_bytes()[:600].decode(errors="replace")
    assert ("DATA ascii" if ascii else "DATA binary") in header
    pc = PcdCloud.from_path(str(out))
    assert list(pc.fields) == list(ref.dtype.names)
    arr = pc.numpy()
    assert arr.shape == (len(ref), len(ref.dtype.names))
    # Both hold float32; ASCII writes the shortest text that reads back exactly.
    for k, name in enumerate(ref.dtype.names):
        assert np.array_equal(arr[:, k].astype(np.float32), ref[name]), name


def test_las_reads_back_in_laspy_with_millimetres_intact(scan):
    _, ref = read_ply(scan["ref"])
    for units, per_mm in (("mm", 1.0), ("m", 1e-3)):
        out = scan["dir"] / f"c_{units}.las"
        tool("omni-merge", scan["points"], "-o", out, "--units", units)
        las = laspy.read(str(out))
        assert (las.header.version.major, las.header.version.minor) == (1, 4)
        assert las.header.point_format.id == 6
        assert len(las.points) == len(ref)
        got = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1) / per_mm
        # Scale 0.01 mm: rounding costs at most 0.005 mm (plus the float32 reference's own).
        assert np.abs(got - xyz(ref)).max() <= 0.005 + 1e-3 * 0.01, units
        assert np.array_equal(np.asarray(las.intensity), np.round(ref["intensity"]).astype(np.uint16))
        extra = set(las.point_format.extra_dimension_names)
        assert {"scalar_frame", "scalar_range", "scalar_u", "scalar_v"} <= extra, extra
        for name in ("scalar_frame", "scalar_range", "scalar_u"):
            assert np.array_equal(np.asarray(las[name]), ref[name]), name


def test_uchar_colours_stay_uchar_through_merge(scan):
    n = 200
    rng = np.random.default_rng(4)
    v = np.zeros(n, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    v["x"], v["y"], v["z"] = rng.random(n) * 100, rng.random(n) * 100, 1000 + rng.random(n)
    v["red"], v["green"], v["blue"] = rng.integers(0, 256, n), 7, 255
    src = scan["dir"] / "colours.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(src))
    out = scan["dir"] / "colours_out.ply"
    tool("omni-merge", src, "-o", out)
    _, got = read_ply(out)
    for c in ("red", "green", "blue"):
        assert got.dtype[c] == np.uint8, got.dtype
        assert np.array_equal(got[c], v[c]), c


def test_double_and_metres(scan):
    _, ref = read_ply(scan["ref"])
    out = scan["dir"] / "d.ply"
    tool("omni-merge", scan["points"], "-o", out, "--double", "--units", "m")
    data, got = read_ply(out)
    assert got.dtype["x"] == np.float64
    assert "units m" in data.comments
    # The reference is float32 mm; the double output is the stream's f64 mm × 0.001.
    assert np.abs(xyz(got) * 1000 - xyz(ref)).max() < 1e-3
    assert np.array_equal(got["scalar_range"], ref["scalar_range"])  # scalars keep their units


def reference_normals(p, k):
    """Least-squares plane normals of each point's k nearest points (itself included), brute
    force, oriented towards the origin: the definition, independent of the k-d tree and solver."""
    out = np.empty_like(p)
    for s in range(0, len(p), 512):
        q = p[s:s + 512]
        d2 = ((q[:, None, :] - p[None, :, :]) ** 2).sum(axis=2)
        idx = np.argpartition(d2, k - 1, axis=1)[:, :k]
        nb = p[idx]
        centred = nb - nb.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", centred, centred)
        _, vecs = np.linalg.eigh(cov)
        n = vecs[:, :, 0]
        flip = np.einsum("ij,ij->i", n, -q) < 0
        n[flip] *= -1
        out[s:s + 512] = n
    return out


def test_normals_match_a_plane_fit_and_face_the_sensor(scan):
    out = scan["dir"] / "n.ply"
    tool("omni-merge", scan["points"], "-o", out, "--normals", "--normal-neighbours", "16")
    _, got = read_ply(out)
    p = xyz(got)
    n = np.stack([got["nx"], got["ny"], got["nz"]], axis=1).astype(np.float64)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    assert (np.einsum("ij,ij->i", n, -p) >= 0).all(), "a normal faces away from the sensor"
    ref = reference_normals(p, 16)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, ref), -1, 1)))
    # Same neighbourhoods, same covariance: equal up to float32 storage and neighbour ties.
    assert np.percentile(angle, 99) < 0.5, np.percentile(angle, 99)


def test_unknown_extension_is_an_error_and_writes_nothing(scan):
    out = scan["dir"] / "c.xyz"
    r = tool("omni-merge", scan["points"], "-o", out, check=False)
    assert r.returncode == 2, r
    assert "unknown point-cloud extension `.xyz`" in r.stderr
    assert not out.exists()


def bag_points_rosbags(bag):
    """(messages, concatenated points) as rosbags decodes them with its own ROS 2 types."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    msgs = []
    with BagReader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == "/omniscan/points"]
        assert len(conns) == 1 and conns[0].msgtype == "sensor_msgs/msg/PointCloud2"
        for conn, t, raw in reader.messages(connections=conns):
            msgs.append((t, typestore.deserialize_cdr(raw, conn.msgtype)))
    return msgs


def cloud_array(msg):
    """A PointCloud2 message's points as a structured array, by its fields."""
    dtype = np.dtype({"names": [f.name for f in msg.fields],
                      "formats": [POINT_FIELD_DTYPES[f.datatype] for f in msg.fields],
                      "offsets": [f.offset for f in msg.fields], "itemsize": msg.point_step})
    assert msg.height == 1 and not msg.is_bigendian and msg.row_step == msg.point_step * msg.width
    return np.frombuffer(bytes(msg.data), dtype=dtype, count=msg.width)


def check_bag_equals_ply(msgs, ref):
    pts = np.concatenate([cloud_array(m) for _, m in msgs])
    assert len(pts) == len(ref)
    names = [f for f in ref.dtype.names]
    assert list(pts.dtype.names) == names
    assert np.allclose(xyz(pts) * 1000, xyz(ref), atol=1e-3)  # metres, float32
    for name in names[3:]:
        assert np.array_equal(pts[name], ref[name]), name


def test_rosbag_per_frame_reads_back_in_rosbags_and_mcap_ros2(scan):
    bag = scan["dir"] / "bag_frames"
    tool("omni-triangulate", "--camera", scan["camera"], "--scanner", scan["scanner"], scan["ridges"],
         "--rosbag", bag, "--stamp-period-ms", STAMP_PERIOD_MS, "--cloud", scan["dir"] / "bag_ref.ply")
    _, ref = read_ply(scan["dir"] / "bag_ref.ply")
    assert sorted(p.name for p in bag.iterdir()) == ["bag_frames_0.mcap", "metadata.yaml"]
    msgs = bag_points_rosbags(bag)
    assert len(msgs) > 5
    check_bag_equals_ply(msgs, ref)
    for t, m in msgs:
        assert m.header.frame_id == "omniscan"
        assert t == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        seq = int(cloud_array(m)["scalar_frame"][0])
        assert t == round(seq * STAMP_PERIOD_MS * 1e6)
    # mcap-ros2-support decodes with the ros2msg schema stored in the file, not its own types.
    decoded = list(read_ros2_messages(str(bag / "bag_frames_0.mcap")))
    assert len(decoded) == len(msgs)
    check_bag_equals_ply([(d.log_time_ns, d.ros_msg) for d in decoded], ref)
    with open(bag / "bag_frames_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == len(msgs)
    assert summary.chunk_indexes and all(ci.message_index_offsets for ci in summary.chunk_indexes)
    chan = next(iter(summary.channels.values()))
    assert chan.message_encoding == "cdr" and "reliability: 1" in chan.metadata["offered_qos_profiles"]
    assert next(iter(summary.schemas.values())).encoding == "ros2msg"


def test_rosbag_message_larger_than_the_chunk(scan):
    bag = scan["dir"] / "bag_rev"
    tool("omni-triangulate", "--camera", scan["camera"], "--scanner", scan["scanner"], scan["ridges"],
         "--rosbag", bag, "--stamp-period-ms", STAMP_PERIOD_MS, "--bag-per", "revolution", "--chunk-kib", "4",
         "--cloud", scan["dir"] / "rev_ref.ply")
    _, ref = read_ply(scan["dir"] / "rev_ref.ply")
    msgs = bag_points_rosbags(bag)
    assert len(msgs) == 1  # one revolution
    check_bag_equals_ply(msgs, ref)
    mcap_file = bag / "bag_rev_0.mcap"
    with open(mcap_file, "rb") as f:
        summary = make_reader(f).get_summary()
    assert max(ci.uncompressed_size for ci in summary.chunk_indexes) > 4 * 1024
    decoded = list(read_ros2_messages(str(mcap_file)))
    assert len(bytes(decoded[0].ros_msg.data)) > 4 * 1024
    check_bag_equals_ply([(d.log_time_ns, d.ros_msg) for d in decoded], ref)


def test_merge_rosbag_holds_the_merged_cloud(scan):
    bag = scan["dir"] / "merged_bag"
    tool("omni-merge", scan["points"], "--voxel", "2", "-o", scan["dir"] / "merged.ply", "--rosbag", bag)
    _, ref = read_ply(scan["dir"] / "merged.ply")
    msgs = bag_points_rosbags(bag)
    assert len(msgs) == 1 and msgs[0][1].header.frame_id == "map"
    check_bag_equals_ply(msgs, ref)


def frames_of(stream):
    """(seq, image path) of each frame record of a stripe stream, its frames_dir resolved
    against the stream's directory."""
    frames, frames_dir = [], stream.parent
    for line in stream.read_text().splitlines():
        rec = json.loads(line)
        if rec["type"] == "header" and rec.get("frames_dir"):
            frames_dir = stream.parent / rec["frames_dir"]
        elif rec["type"] == "frame":
            frames.append((rec["seq"], frames_dir / rec["path"]))
    return frames


def check_image_bag(bag, stream, camera, expect_model):
    """The bag's Image and CameraInfo messages against the PNG files (OpenCV) and camera.json,
    decoded by rosbags (its own types) and mcap-ros2-support (the file's schemas)."""
    frames = frames_of(stream)
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    by_topic = {}
    with BagReader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {"/omniscan/points": "sensor_msgs/msg/PointCloud2",
                         "/omniscan/image_raw": "sensor_msgs/msg/Image",
                         "/omniscan/camera_info": "sensor_msgs/msg/CameraInfo"}, types
        for conn, t, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append((t, typestore.deserialize_cdr(raw, conn.msgtype)))
    images, infos = by_topic["/omniscan/image_raw"], by_topic["/omniscan/camera_info"]
    assert len(images) == len(infos) == len(frames)
    model = json.loads(camera.read_text())["model"]
    for (seq, png), (t, img), (ti, info) in zip(frames, images, infos):
        stamp = round(seq * STAMP_PERIOD_MS * 1e6)
        assert t == ti == stamp == img.header.stamp.sec * 10**9 + img.header.stamp.nanosec
        want = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        assert want is not None and want.ndim == 2, png
        depth = 2 if want.dtype == np.uint16 else 1
        assert img.encoding == ("mono16" if depth == 2 else "mono8") and img.is_bigendian == 0
        assert (img.height, img.width, img.step) == (want.shape[0], want.shape[1], want.shape[1] * depth)
        got = np.frombuffer(bytes(img.data), dtype="<u2" if depth == 2 else "u1").reshape(want.shape)
        assert np.array_equal(got, want), png
        assert img.header.frame_id == info.header.frame_id == "omniscan"
        assert (info.width, info.height) == (model["width"], model["height"])
        assert info.distortion_model == expect_model
        fx, fy, cx, cy = (model[k] for k in ("fx_px", "fy_px", "cx_px", "cy_px"))
        assert list(info.k) == [fx, 0, cx, 0, fy, cy, 0, 0, 1]
        assert list(info.p) == [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]
        assert list(info.r) == [1, 0, 0, 0, 1, 0, 0, 0, 1]
        if expect_model == "mei":
            assert list(info.d) == [model["xi"], model["k1"], model["k2"], model["p1"], model["p2"]]
        else:
            assert list(info.d) == [model["a_mm"], model["b_mm"], model["rim_radius_mm"], model["inner_radius_mm"],
                                    *model["camera_offset_mm"], *model["camera_tilt_deg"]]
    # The file's own order is time order; at one stamp, image and camera info before the points.
    with open(next(bag.glob("*.mcap")), "rb") as f:
        order = [(m.log_time, c.topic) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert order == sorted(order, key=lambda o: (o[0], ["/omniscan/image_raw", "/omniscan/camera_info",
                                                        "/omniscan/points"].index(o[1])))
    decoded = {}
    for d in read_ros2_messages(str(next(bag.glob("*.mcap")))):
        decoded.setdefault(d.channel.topic, []).append(d.ros_msg)
    assert len(decoded["/omniscan/image_raw"]) == len(frames)
    for (_, a), b in zip(images, decoded["/omniscan/image_raw"]):
        assert (a.encoding, a.width, a.height, bytes(a.data)) == (b.encoding, b.width, b.height, bytes(b.data))
    for (_, a), b in zip(infos, decoded["/omniscan/camera_info"]):
        assert (a.distortion_model, list(a.d), list(a.k)) == (b.distortion_model, list(b.d), list(b.k))
    return by_topic["/omniscan/points"] if "/omniscan/points" in by_topic else []


def test_rosbag_images_mono8_and_camera_info_of_the_hyperbolic_model(scan):
    bag = scan["dir"] / "bag_images"
    tool("omni-triangulate", "--camera", scan["camera"], "--scanner", scan["scanner"], scan["ridges"],
         "--rosbag", bag, "--rosbag-images", "--stamp-period-ms", STAMP_PERIOD_MS,
         "--cloud", scan["dir"] / "images_ref.ply")
    points = check_image_bag(bag, scan["ridges"], scan["camera"], "omniscan_hyperbolic")
    _, ref = read_ply(scan["dir"] / "images_ref.ply")
    check_bag_equals_ply(points, ref)


def test_rosbag_images_mono16_and_camera_info_of_a_mei_model(scan):
    d = scan["dir"] / "scan16"
    d.mkdir()
    tool("omni-sim", "scan", "--camera", scan["camera"], "--scanner", scan["scanner"],
         "--scene", scan["dir"] / "plane.json", "--angles", "16:17:0.5", "--bit-depth", "16",
         "--frames", d / "frames", "-o", d / "scan.jsonl")
    tool("omni-ridge", "--camera", scan["camera"], d / "scan.jsonl", "-o", d / "ridges.jsonl")
    # A Mei model with every distortion coefficient distinct, so D's order shows.
    mei = {"format": "omniscan.camera", "version": 1,
           "model": {"kind": "mei", "xi": 0.85, "fx_px": 210.5, "fy_px": 211.25, "cx_px": 127.5, "cy_px": 128.0,
                     "k1": -0.125, "k2": 0.03125, "p1": 0.001, "p2": -0.002, "width": 256, "height": 256}}
    (d / "mei.json").write_text(json.dumps(mei))
    bag = d / "bag"
    tool("omni-triangulate", "--camera", d / "mei.json", "--scanner", scan["scanner"], d / "ridges.jsonl",
         "--rosbag", bag, "--rosbag-images", "--stamp-period-ms", STAMP_PERIOD_MS)
    assert len(frames_of(d / "ridges.jsonl")) == 2
    check_image_bag(bag, d / "ridges.jsonl", d / "mei.json", "mei")
