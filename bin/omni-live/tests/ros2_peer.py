#!/usr/bin/env python3
"""A ROS 2 peer without ROS: Cyclone DDS (PyPI `cyclonedds`) subscribing to omni-live.

Run inside a network namespace of its own (test_live.py does: `unshare --net`, `lo` only), so
that discovery and data never leave the machine. Starts omni-live on a stream that a feeder
writes into its stdin at a given pace, subscribes to `PREFIX/points` with ROS 2's sensor-data
QoS, and, after the calibration has been published, starts a second (late) reader of the
transient-local topics. Prints one JSON object with what arrived.

Usage: ros2_peer.py OMNI_LIVE STREAM [omni-live options...]
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
            got["calibration"] = json.loads(s.data)
        for s in tf.take(N=4):
            got["tf_static"] = [{"parent": t.header.frame_id, "child": t.child_frame_id,
                                 "translation": [t.transform.translation.x, t.transform.translation.y,
                                                 t.transform.translation.z],
                                 "rotation_xyzw": [t.transform.rotation.x, t.transform.rotation.y,
                                                   t.transform.rotation.z, t.transform.rotation.w]}
                                for t in s.transforms]
        time.sleep(0.02)
    return got


def main() -> int:
    omni_live, stream = sys.argv[1], sys.argv[2]
    opts = sys.argv[3:]
    prefix = opts[opts.index("--prefix") + 1] if "--prefix" in opts else "/omniscan"
    domain = int(opts[opts.index("--domain-id") + 1]) if "--domain-id" in opts else 0
    dp = DomainParticipant(domain)
    points = DataReader(dp, Topic(dp, f"rt{prefix}/points", PointCloud2), qos=SENSOR_DATA)
    proc = subprocess.Popen([omni_live, "--ros2", *opts, "-"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    lines = open(stream, "rb").read().splitlines(keepends=True)
    late_read = threading.Event()

    def feed() -> None:
        # Discovery first (best-effort samples sent before the match are lost), then one sweep's
        # frames at a time with a pause between sweeps.
        time.sleep(2.0)
        try:
            for line in lines:
                proc.stdin.write(line)
                proc.stdin.flush()
                rec = json.loads(line)
                if rec.get("type") == "frame" and rec.get("last_of_sweep"):
                    time.sleep(0.15)
            # Transient-local samples live in the running publisher: keep it running until the
            # late reader has had its chance.
            late_read.wait(30)
            proc.stdin.close()
        except BrokenPipeError:
            pass

    feeder = threading.Thread(target=feed)
    feeder.start()
    sweeps = []
    expected = sum(1 for line in lines if b'"last_of_sweep": true' in line or b'"last_of_sweep":true' in line)
    end = time.monotonic() + 30
    while time.monotonic() < end and len(sweeps) < expected:
        for msg in points.take(N=16):
            sweeps.append(sweep_of(msg))
        time.sleep(0.005)
    # A second participant, started after the publisher has sent its latched topics.
    latched = read_latched(DomainParticipant(domain), prefix, 5.0)
    late_read.set()
    feeder.join()
    out, err = proc.stdout.read(), proc.stderr.read()
    proc.wait(timeout=30)
    print(json.dumps({"returncode": proc.returncode, "stdout": out.decode(), "stderr": err.decode(),
                      "sweeps": sweeps, "latched": latched}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
