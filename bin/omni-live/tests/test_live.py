"""omni-live's live outputs read by independent clients: ROS 2 by a ROS-free DDS implementation
(Cyclone DDS from PyPI) in a network namespace of the test's own (`unshare --net`: only `lo`,
nothing leaves the machine); Foxglove by a WebSocket client (`websockets`) decoding with the
protobuf schemas the server advertises, on 127.0.0.1.

A small scan of the paper bench's plane is rendered by omni-sim and measured by the offline
pipeline (`omni-ridge | omni-triangulate`); its frames are replayed as five sweeps through two
omni-live runs in turn (a publisher restart), beside a subscriber that never reads and one
killed after the first sweep. Every received cloud must carry exactly the offline points.
"""

import asyncio
import base64
import json
import os
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
BIN = Path(os.environ.get("OMNI_BIN", ROOT / "target" / "debug"))
PYTHON = sys.executable
PEER = Path(__file__).with_name("ros2_peer.py")
ANGLES = "14:29:3"  # 5 frames per sweep
FRAME_PERIOD_US = 5000  # 200 fps
FIRST_STAMP_US = 1_700_000_000_123_456

FIELDS = [["x", 0, 7, 1], ["y", 4, 7, 1], ["z", 8, 7, 1], ["intensity", 12, 7, 1], ["t", 16, 6, 1],
          ["frame", 20, 6, 1], ["alpha", 24, 7, 1], ["ring", 28, 4, 1], ["laser", 30, 2, 1]]
POINT = np.dtype({"names": ["x", "y", "z", "intensity", "t", "frame", "alpha", "ring", "laser"],
                  "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<u4", "<f4", "<u2", "u1"],
                  "offsets": [0, 4, 8, 12, 16, 20, 24, 28, 30], "itemsize": 32})


def tool(name: str) -> str:
    path = BIN / name
    if not path.exists():
        pytest.fail(f"{path} is missing: build the workspace first (make test-build)")
    return str(path)


def replay(frames: list, sweeps: range, header: dict) -> str:
    """The measured frames as consecutive sweeps (facet k mod 12), 200 fps timestamps."""
    lines = [dict(header, angles=ANGLES)]
    for k in sweeps:
        for i, f in enumerate(frames):
            seq = k * len(frames) + i
            lines.append(dict(f, seq=seq, revolution=k // 12, facet=k % 12,
                              timestamp_us=FIRST_STAMP_US + FRAME_PERIOD_US * seq,
                              last_of_sweep=i == len(frames) - 1))
    n = len(lines) - 1
    lines.append({"type": "status", "frames": n, "frames_missing": 0, "frames_failed": 0, "complete": True,
                  "errors": []})
    return "".join(json.dumps(r) + "\n" for r in lines)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.fail("unshare (util-linux) and ip (iproute2) are needed: scripts/deps.sh installs them")
    d = tmp_path_factory.mktemp("live")
    subprocess.run([tool("omni-sim"), "sensor", "--preset", "paper", "-o", d / "s"], check=True,
                   capture_output=True)
    subprocess.run([tool("omni-sim"), "scan", "--camera", d / "s/camera.json", "--scanner", d / "s/scanner.json",
                    "--scene", ROOT / "testdata/scenes/plane.json", "--angles", ANGLES, "--ideal",
                    "--frames", d / "f", "-o", d / "scan.jsonl"], check=True, capture_output=True)
    stripes = subprocess.run([tool("omni-ridge"), "--camera", d / "s/camera.json", d / "scan.jsonl"],
                             check=True, capture_output=True).stdout
    points = subprocess.run([tool("omni-triangulate"), "--camera", d / "s/camera.json", "--scanner",
                             d / "s/scanner.json"], input=stripes, check=True, capture_output=True).stdout
    records = [json.loads(line) for line in points.splitlines()]
    frames = [r for r in records if r["type"] == "frame"]
    (d / "a.jsonl").write_text(replay(frames, range(0, 3), records[0]))
    (d / "b.jsonl").write_text(replay(frames, range(3, 5), records[0]))
    (d / "base_link.json").write_text(json.dumps({
        "format": "omniscan.transform", "version": 1, "rotation": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
        "translation_mm": [10, 20, 300]}))
    script = ("ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && "
              f"exec {PYTHON} {PEER} {tool('omni-live')} {d / 'a.jsonl'},{d / 'b.jsonl'} "
              f"--camera {d / 's/camera.json'} --scanner {d / 's/scanner.json'} --extrinsics {d / 'base_link.json'} "
              "--domain-id 17 --prefix /robot/omniscan")
    p = subprocess.run(["unshare", "--net", "sh", "-c", script], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, f"unshare --net (needs root) or the peer failed: {p.stderr[-3000:]}"
    return {"dir": d, "frames": frames, "result": json.loads(p.stdout)}


def test_every_sweep_arrives_across_a_publisher_restart_and_a_killed_subscriber(run):
    r = run["result"]
    assert [x["returncode"] for x in r["runs"]] == [0, 0], r["runs"]
    assert r["victim_killed"], "the second subscriber was not killed mid-run"
    assert len(r["sweeps"]) == r["expected"] == 5, len(r["sweeps"])
    # The subscriber that never read holds the newest samples its history keeps (5), no more.
    assert r["stalled_unread"] == 5


def test_the_cloud_layout_is_the_documented_one(run):
    for s in run["result"]["sweeps"]:
        assert s["fields"] == FIELDS
        assert (s["height"], s["point_step"], s["row_step"]) == (1, 32, 32 * s["width"])
        assert (s["is_bigendian"], s["is_dense"], s["frame_id"]) == (False, True, "omniscan")


def test_the_points_equal_the_offline_pipelines(run):
    frames = run["frames"]
    offline = np.array([p[:3] for f in frames for p in f["points"]]) / 1000.0
    intensity = np.array([f["stripe"][int(p[5])][2] for f in frames for p in f["points"]])
    laser = np.array([p[3] for f in frames for p in f["points"]])
    assert len(offline) > 500
    for k, s in enumerate(run["result"]["sweeps"]):
        pts = np.frombuffer(bytes.fromhex(s["data"]), dtype=POINT)
        assert len(pts) == s["width"] == len(offline)
        got = np.stack([pts["x"], pts["y"], pts["z"]], axis=1)
        # float32 of the same metres: bit for bit.
        assert np.array_equal(got, offline.astype(np.float32)), np.abs(got - offline).max()
        assert np.array_equal(pts["intensity"], intensity.astype(np.float32))
        assert np.array_equal(pts["laser"], laser.astype(np.uint8))
        first_seq = k * len(frames)
        per_frame = np.repeat(np.arange(len(frames)), [len(f["points"]) for f in frames])
        assert np.array_equal(pts["frame"], first_seq + per_frame)
        assert np.array_equal(pts["ring"], per_frame)
        assert np.array_equal(pts["alpha"], np.array([frames[i]["alpha_deg"] for i in per_frame], np.float32))
        stamp_us = FIRST_STAMP_US + FRAME_PERIOD_US * first_seq
        assert s["stamp"] == [stamp_us // 1_000_000, stamp_us % 1_000_000 * 1000]


def test_t_is_the_time_after_the_sweeps_first_frame_and_never_decreases(run):
    for s in run["result"]["sweeps"]:
        t = np.frombuffer(bytes.fromhex(s["data"]), dtype=POINT)["t"]
        assert np.all(np.diff(t.astype(np.int64)) >= 0)
        assert np.array_equal(t, pts_frame_index(s) * FRAME_PERIOD_US * 1000)


def pts_frame_index(s: dict) -> np.ndarray:
    return np.frombuffer(bytes.fromhex(s["data"]), dtype=POINT)["ring"].astype(np.uint32)


def test_a_late_subscriber_gets_the_calibration_and_the_static_transform(run):
    latched, d = run["result"]["latched"], run["dir"]
    assert latched["calibration"]["camera"] == json.loads((d / "s/camera.json").read_text())
    assert latched["calibration"]["scanner"] == json.loads((d / "s/scanner.json").read_text())
    (tf,) = latched["tf_static"]
    assert (tf["parent"], tf["child"]) == ("base_link", "omniscan")
    assert tf["translation"] == pytest.approx([0.01, 0.02, 0.3], abs=1e-12)
    # 90° about z.
    assert tf["rotation_xyzw"] == pytest.approx([0, 0, 2 ** -0.5, 2 ** -0.5], abs=1e-12)


def test_each_run_reports_its_sweeps_and_a_final_status(run):
    for out, n in zip([x["stdout"] for x in run["result"]["runs"]], [3, 2]):
        lines = [json.loads(line) for line in out.splitlines()]
        sweeps, status = lines[:-1], lines[-1]
        assert [(s["sink"], s["complete"], s["frames"]) for s in sweeps] == [("dds", True, 5)] * n
        assert all(s["latency_ms"] >= 0 for s in sweeps)
        assert status == {"type": "status", "frames": 5 * n, "sweeps": n, "sweeps_incomplete": 0,
                          "sweeps_dropped": {"dds": 0}, "frames_deleted": 0, "input_complete": True,
                          "cut_short": False}


# --- Foxglove -------------------------------------------------------------------------------

SUBPROTOCOL = "foxglove.sdk.v1"


def message_class(channel: dict):
    """The protobuf class of an advertised channel, built from the schema the server sent."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


async def foxglove_session(port: int, feed, topics: list) -> dict:
    import websockets

    got: dict = {"messages": {t: [] for t in topics}}
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                                  max_size=1 << 26) as ws:
        got["subprotocol"] = ws.subprotocol
        got["server_info"] = json.loads(await ws.recv())
        channels: dict = {}
        while not all(t in channels for t in topics):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        got["channels"] = channels
        subs = [{"id": i, "channelId": channels[t]["id"]} for i, t in enumerate(topics)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        await asyncio.sleep(0.3)
        feeder = asyncio.get_running_loop().run_in_executor(None, feed)
        want = {"/omniscan/points": 3, "/omniscan/image": 3}
        while any(len(got["messages"].get(t, [])) < n for t, n in want.items()):
            data = await asyncio.wait_for(ws.recv(), 20)
            if isinstance(data, bytes) and data[0] == 0x01:
                sub, _log_time = struct.unpack_from("<IQ", data, 1)
                got["messages"][topics[sub]].append(data[13:])
        await feeder
    return got


@pytest.fixture(scope="module")
def foxglove(run):
    d, frames = run["dir"], run["frames"]
    (d / "fox.jsonl").write_text(replay(frames, range(0, 3), {**json.loads(
        (d / "a.jsonl").read_text().splitlines()[0]), "frames_dir": str(d / "f")}))
    # Every sweep is checked: the server's backlog (--queue sweeps per client) holds all of them
    # however late a loaded machine lets the client read.
    proc = subprocess.Popen([tool("omni-live"), "--foxglove", "127.0.0.1:0", "--queue", "8", "--camera", d / "s/camera.json",
                             "--scanner", d / "s/scanner.json", "--extrinsics", d / "base_link.json", "-"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = proc.stderr.readline().decode()
    assert "Foxglove server on port" in line, line + proc.stderr.read().decode()
    port = int(line.split("port")[1].split()[0])

    def feed():
        for rec in (d / "fox.jsonl").read_bytes().splitlines(keepends=True):
            proc.stdin.write(rec)
            proc.stdin.flush()
            if json.loads(rec).get("last_of_sweep"):
                time.sleep(0.1)

    topics = ["/omniscan/points", "/omniscan/image", "/omniscan/calibration", "/tf"]
    try:
        got = asyncio.run(asyncio.wait_for(foxglove_session(port, feed, topics), 60))
    finally:
        proc.stdin.close()
        out, err = proc.stdout.read(), proc.stderr.read()
        proc.wait(timeout=30)
    assert proc.returncode == 0, err.decode()
    got["stdout"] = out.decode()
    return got


def test_foxglove_advertises_the_live_channels(foxglove):
    assert foxglove["subprotocol"] == SUBPROTOCOL
    assert foxglove["server_info"]["op"] == "serverInfo"
    ch = foxglove["channels"]
    assert (ch["/omniscan/points"]["schemaName"], ch["/omniscan/points"]["encoding"]) == ("foxglove.PointCloud", "protobuf")
    assert ch["/omniscan/image"]["schemaName"] == "foxglove.RawImage"
    assert ch["/omniscan/calibration"]["encoding"] == "json"
    assert ch["/tf"]["schemaName"] == "foxglove.FrameTransforms"


def test_foxglove_clouds_carry_the_offline_points(foxglove, run):
    frames = run["frames"]
    offline = (np.array([p[:3] for f in frames for p in f["points"]]) / 1000.0).astype(np.float32)
    cls = message_class(foxglove["channels"]["/omniscan/points"])
    clouds = [cls.FromString(m) for m in foxglove["messages"]["/omniscan/points"]]
    assert len(clouds) == 3
    for k, c in enumerate(clouds):
        assert c.frame_id == "omniscan" and c.point_stride == 32
        assert [(f.name, f.offset) for f in c.fields] == [(f[0], f[1]) for f in FIELDS]
        pts = np.frombuffer(c.data, dtype=POINT)
        assert np.array_equal(np.stack([pts["x"], pts["y"], pts["z"]], axis=1), offline)
        stamp_us = FIRST_STAMP_US + FRAME_PERIOD_US * k * len(frames)
        assert (c.timestamp.seconds, c.timestamp.nanos) == (stamp_us // 1_000_000, stamp_us % 1_000_000 * 1000)


def test_foxglove_shows_each_sweeps_last_frame_the_calibration_and_the_transform(foxglove, run):
    d = run["dir"]
    cls = message_class(foxglove["channels"]["/omniscan/image"])
    images = [cls.FromString(m) for m in foxglove["messages"]["/omniscan/image"]]
    last = run["frames"][-1]["path"]
    import cv2  # an independent PNG reader

    truth = cv2.imread(str(d / "f" / last), cv2.IMREAD_UNCHANGED)
    for img in images[:3]:
        assert (img.width, img.height, img.encoding, img.step) == (1024, 1024, "mono8", 1024)
        assert np.array_equal(np.frombuffer(img.data, np.uint8).reshape(1024, 1024), truth)
    calib = json.loads(foxglove["messages"]["/omniscan/calibration"][0])
    assert calib["camera"] == json.loads((d / "s/camera.json").read_text())
    tf_cls = message_class(foxglove["channels"]["/tf"])
    (tf,) = tf_cls.FromString(foxglove["messages"]["/tf"][0]).transforms
    assert (tf.parent_frame_id, tf.child_frame_id) == ("base_link", "omniscan")
    assert [tf.translation.x, tf.translation.y, tf.translation.z] == pytest.approx([0.01, 0.02, 0.3])
    status = json.loads(foxglove["stdout"].splitlines()[-1])
    assert (status["sweeps"], status["sweeps_dropped"]) == (3, {"foxglove": 0})


def test_a_client_offering_only_the_old_subprotocol_is_refused(run):
    import websockets

    proc = subprocess.Popen([tool("omni-live"), "--foxglove", "127.0.0.1:0", "-"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        port = int(proc.stderr.readline().decode().split("port")[1].split()[0])

        async def connect():
            async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.websocket.v1"]) as ws:
                return await ws.recv()

        with pytest.raises(Exception):
            asyncio.run(asyncio.wait_for(connect(), 10))
    finally:
        proc.stdin.close()
        proc.stdout.read()
        proc.wait(timeout=30)
