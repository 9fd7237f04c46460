#!/usr/bin/env python3
"""A ROS 2 peer without ROS: Cyclone DDS (PyPI `cyclonedds`) subscribing to omni-live.

Run inside a network namespace of its own (test_live.py does: `unshare --net`, `lo` only), so
that discovery and data never leave the machine. Runs omni-live once per stream (a restart of
the publisher between them), feeding each at a sweep's pace into its stdin; subscribes to
`PREFIX/points` with ROS 2's sensor-data QoS, beside a subscriber that never reads and one that
is killed after the first sweep; after the first run's calibration has been published, a
second (late) participant reads the transient-local topics. Prints one JSON object with what
arrived.

Usage: ros2_peer.py OMNI_LIVE STREAM[,STREAM...] [omni-live options...]
"""


import json
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

import cyclonedds.idl.annotations as annotate
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint8, uint32
from cyclonedds.internal import InvalidSample
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class PointField(IdlStruct, typename="sensor_msgs::msg::dds_::PointField_"):
    name: str
    offset: uint32
    datatype: uint8
    count: uint32


@dataclass
@annotate.final
class PointCloud2(IdlStruct, typename="sensor_msgs::msg::dds_::PointCloud2_"):
    header: Header
    height: uint32
    width: uint32
    fields: sequence[PointField]
    is_bigendian: bool
    point_step: uint32
    row_step: uint32
    data: sequence[uint8]
    is_dense: bool


@dataclass
@annotate.final
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


@dataclass
@annotate.final
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
@annotate.final
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
@annotate.final
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
@annotate.final
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


# ROS 2's rmw_qos_profile_sensor_data, and the latched profile of /tf_static.
SENSOR_DATA = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5))
LATCHED = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
              Policy.History.KeepLast(1))


def sweep_of(msg: PointCloud2) -> dict:
    return {"stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec], "frame_id": msg.header.frame_id,
            "height": msg.height, "width": msg.width, "point_step": msg.point_step, "row_step": msg.row_step,
            "is_bigendian": msg.is_bigendian, "is_dense": msg.is_dense,
            "fields": [[f.name, f.offset, f.datatype, f.count] for f in msg.fields],
            "data": bytes(msg.data).hex()}


def read_latched(dp: DomainParticipant, prefix: str, wait_s: float) -> dict:
    calib = DataReader(dp, Topic(dp, f"rt{prefix}/calibration", String), qos=LATCHED)
    tf = DataReader(dp, Topic(dp, "rt/tf_static", TFMessage), qos=LATCHED)
    got: dict = {}
    end = time.monotonic() + wait_s
    while time.monotonic() < end and len(got) < 2:
        for s in calib.take(N=4):
            if isinstance(s, InvalidSample):
                continue
            got["calibration"] = json.loads(s.data)
        for s in tf.take(N=4):
            if isinstance(s, InvalidSample):
                continue
            got["tf_static"] = [{"parent": t.header.frame_id, "child": t.child_frame_id,
                                 "translation": [t.transform.translation.x, t.transform.translation.y,
                                                 t.transform.translation.z],
                                 "rotation_xyzw": [t.transform.rotation.x, t.transform.rotation.y,
                                                   t.transform.rotation.z, t.transform.rotation.w]}
                                for t in s.transforms]
        time.sleep(0.02)
    return got


def subscribe_only(prefix: str, domain: int) -> int:
    """A second subscriber that the test kills while omni-live publishes."""
    dp = DomainParticipant(domain)
    reader = DataReader(dp, Topic(dp, f"rt{prefix}/points", PointCloud2), qos=SENSOR_DATA)
    print("ready", flush=True)
    while True:
        reader.take(N=16)
        time.sleep(0.01)


def publish_run(omni_live: str, stream: str, opts: list, hold: threading.Event) -> dict:
    """One omni-live process fed `stream` at a sweep's pace; stdin stays open until `hold`."""
    proc = subprocess.Popen([omni_live, "--ros2", *opts, "-"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    # Discovery first: best-effort samples sent before the subscriber is matched are lost.
    time.sleep(2.0)
    try:
        for line in open(stream, "rb"):
            proc.stdin.write(line)
            proc.stdin.flush()
            if json.loads(line).get("last_of_sweep"):
                time.sleep(0.15)
        # Transient-local samples live in the running publisher: keep it running until the late
        # reader has had its chance.
        hold.wait(30)
        proc.stdin.close()
    except BrokenPipeError:
        pass
    out, err = proc.stdout.read(), proc.stderr.read()
    proc.wait(timeout=30)
    return {"returncode": proc.returncode, "stdout": out.decode(), "stderr": err.decode()}


def main() -> int:
    args = sys.argv[1:]
    if args[0] == "--subscribe-only":
        return subscribe_only(args[1], int(args[2]))
    omni_live, streams = args[0], args[1].split(",")
    opts = args[2:]
    prefix = opts[opts.index("--prefix") + 1] if "--prefix" in opts else "/omniscan"
    domain = int(opts[opts.index("--domain-id") + 1]) if "--domain-id" in opts else 0
    dp = DomainParticipant(domain)
    points = DataReader(dp, Topic(dp, f"rt{prefix}/points", PointCloud2), qos=SENSOR_DATA)
    # A subscriber that never reads, and one that is killed mid-run: neither may cost the
    # others a sweep.
    stalled = DataReader(dp, Topic(dp, f"rt{prefix}/points", PointCloud2), qos=SENSOR_DATA)
    victim = subprocess.Popen([sys.executable, __file__, "--subscribe-only", prefix, str(domain)],
                              stdout=subprocess.PIPE)
    victim.stdout.readline()
    expected = sum(1 for path in streams for line in open(path, "rb") if json.loads(line).get("last_of_sweep"))
    sweeps, runs, latched = [], [], {}
    for i, stream in enumerate(streams):
        hold = threading.Event()
        result: dict = {}
        run = threading.Thread(target=lambda: result.update(publish_run(omni_live, stream, opts, hold)))
        run.start()
        goal = sum(1 for line in open(stream, "rb") if json.loads(line).get("last_of_sweep")) + len(sweeps)
        end = time.monotonic() + 30
        while time.monotonic() < end and len(sweeps) < goal:
            for msg in points.take(N=16):
                if isinstance(msg, InvalidSample):
                    continue  # the writer of a finished run going away
                sweeps.append(sweep_of(msg))
                if victim.poll() is None and len(sweeps) == 1:
                    victim.kill()
                    victim.wait()
            time.sleep(0.005)
        if i == 0:
            # A second participant, started after the publisher has sent its latched topics.
            latched = read_latched(DomainParticipant(domain), prefix, 5.0)
        hold.set()
        run.join()
        runs.append(result)
    print(json.dumps({"runs": runs, "expected": expected, "sweeps": sweeps, "latched": latched,
                      "victim_killed": victim.returncode is not None and victim.returncode < 0,
                      "stalled_unread": len(stalled.take(N=100))}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
