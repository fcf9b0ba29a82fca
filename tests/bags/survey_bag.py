#!/usr/bin/env python3
"""Writes the scans of an OctoMap .graph as a ROS 2 bag with the real writers.

The bag holds one sensor_msgs/msg/PointCloud2 per graph node (points in the sensor frame,
float32, optionally coloured and organised with NaN holes) and the node's pose as:

  tf      /tf (odom -> base_link, at every cloud's stamp and between them) and /tf_static
          (map -> odom and base_link -> sensor, identities): the cloud's pose in `map` is the
          node's pose exactly
  pose    /pose geometry_msgs/msg/PoseStamped at every cloud's stamp
  odom    /odom nav_msgs/msg/Odometry at every cloud's stamp
  transform  /sensor_pose geometry_msgs/msg/TransformStamped at every cloud's stamp
  none    no pose at all

Kinds (the container and its writer):
  db3            rosbags' rosbag2 writer, sqlite3 storage (a directory)
  rosbag2-mcap   rosbags' rosbag2 writer, mcap storage (a directory)
  db3-file-zstd / db3-message-zstd
                 rosbags' writer, sqlite3 storage, compression_mode FILE / MESSAGE (zstd)
  mcap-zstd / mcap-lz4 / mcap-none
                 the official `mcap` writer, chunks compressed so
  mcap-ros2      the official `mcap_ros2` writer (zstd chunks, its default), messages as dicts

With --tf-fault the TF is malformed: `cycle` (also sensor -> map), `two-parents` (sensor also
under odom), `nan` (a NaN rotation in the first /tf sample).

With --late one more cloud is written whose stamp lies after every pose (it must be skipped).
With --late-root X (tf only) map -> odom is X m along x and is logged just after the first
cloud: a reader that poses clouds as it goes would have built in odom (the root it saw then).
Prints one JSON line: the kind, the clouds written, the path.
"""
import argparse
import json
import struct
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from write_bag import TYPESTORE, msgdef, write_mcap, write_rosbag2  # noqa: E402  the same writers

STAMP0_NS = 1_700_000_000 * 10**9
PERIOD_NS = 500_000_000

TS = TYPESTORE
T = TS.types


def read_graph(path):
    b = Path(path).read_bytes()
    pos = 0

    def take(fmt):
        nonlocal pos
        v = struct.unpack_from("<" + fmt, b, pos)
        pos += struct.calcsize("<" + fmt)
        return v

    (nodes,) = take("I")
    scans = []
    for _ in range(nodes):
        (n,) = take("I")
        pts = np.frombuffer(b, dtype=np.dtype([("tag", "<i4"), ("xyz", "<f8", 3)]), count=n, offset=pos)
        pos += 28 * n
        _, tx, ty, tz = take("iddd")
        _, qw, qx, qy, qz = take("idddd")
        take("I")
        scans.append((pts["xyz"].astype(np.float32), (tx, ty, tz), (qw, qx, qy, qz)))
    return scans


def stamp(ns):
    return T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def header(ns, frame):
    return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def colours_of(xyz):
    r = (np.abs(xyz[:, 0]) * 40).astype(np.uint32) % 256
    g = (np.abs(xyz[:, 1]) * 40).astype(np.uint32) % 256
    b = (np.abs(xyz[:, 2]) * 40).astype(np.uint32) % 256
    return (r << 16) | (g << 8) | b


def cloud(xyz, ns, color, organised):
    n = len(xyz)
    names = ["x", "y", "z"] + (["rgb"] if color else [])
    step = 4 * len(names)
    rows = np.zeros((n, len(names)), dtype=np.float32)
    rows[:, :3] = xyz
    if color:
        rows[:, 3] = colours_of(xyz).view(np.float32)
    height, width = 1, n
    if organised:
        # Two rows; a NaN hole after every 7th point.
        holes = np.full((1, len(names)), np.nan, dtype=np.float32)
        parts = []
        for i in range(0, n, 7):
            parts.append(rows[i:i + 7])
            parts.append(holes)
        rows = np.concatenate(parts) if parts else rows
        if len(rows) % 2:
            rows = np.concatenate([rows, holes])
        height, width = 2, len(rows) // 2
    fields = [T["sensor_msgs/msg/PointField"](name=f, offset=4 * i, datatype=7, count=1) for i, f in enumerate(names)]
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(ns, "sensor"), height=height, width=width, fields=fields,
        is_bigendian=False, point_step=step, row_step=step * width,
        data=np.frombuffer(rows.tobytes(), dtype=np.uint8), is_dense=not organised)


def transform(t, q):
    return T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
        rotation=T["geometry_msgs/msg/Quaternion"](x=q[1], y=q[2], z=q[3], w=q[0]))


def tf_stamped(ns, parent, child, t, q):
    return T["geometry_msgs/msg/TransformStamped"](header=header(ns, parent), child_frame_id=child, transform=transform(t, q))


def pose(t, q):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=t[0], y=t[1], z=t[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=q[1], y=q[2], z=q[3], w=q[0]))


IDENTITY = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))


def messages(scans, pose_kind, color, organised, late, fault=None, late_root=None):
    """(topic, type, log_time_ns, message) in log-time order."""
    out = []
    if pose_kind == "tf":
        statics = [tf_stamped(STAMP0_NS, "base_link", "sensor", *IDENTITY)]
        root = tf_stamped(STAMP0_NS, "map", "odom", *IDENTITY)
        if late_root is None:
            statics.insert(0, root)
        else:
            root = tf_stamped(STAMP0_NS, "map", "odom", (late_root, 0.0, 0.0), IDENTITY[1])
            out.append(("/tf_static", "tf2_msgs/msg/TFMessage", STAMP0_NS + 2_000_000,
                        T["tf2_msgs/msg/TFMessage"](transforms=[root])))
        if fault == "cycle":
            statics.append(tf_stamped(STAMP0_NS, "sensor", "map", *IDENTITY))
        if fault == "two-parents":
            statics.append(tf_stamped(STAMP0_NS, "odom", "sensor", *IDENTITY))
        static = T["tf2_msgs/msg/TFMessage"](transforms=statics)
        out.append(("/tf_static", "tf2_msgs/msg/TFMessage", STAMP0_NS, static))
    clouds = list(scans)
    if late and clouds:
        clouds.append(clouds[-1])
    for k, (xyz, t, q) in enumerate(clouds):
        ns = STAMP0_NS + k * PERIOD_NS
        is_late = late and k == len(clouds) - 1
        if not is_late:
            if pose_kind == "tf":
                if fault == "nan" and k == 0:
                    q = (float("nan"), q[1], q[2], q[3])
                out.append(("/tf", "tf2_msgs/msg/TFMessage", ns, T["tf2_msgs/msg/TFMessage"](
                    transforms=[tf_stamped(ns, "odom", "base_link", t, q)])))
                # A sample between this cloud and the next one, elsewhere: never used exactly.
                mid = ns + PERIOD_NS // 2
                out.append(("/tf", "tf2_msgs/msg/TFMessage", mid, T["tf2_msgs/msg/TFMessage"](
                    transforms=[tf_stamped(mid, "odom", "base_link", (t[0] + 0.5, t[1], t[2]), q)])))
            elif pose_kind == "pose":
                out.append(("/pose", "geometry_msgs/msg/PoseStamped", ns, T["geometry_msgs/msg/PoseStamped"](
                    header=header(ns, "map"), pose=pose(t, q))))
            elif pose_kind == "transform":
                out.append(("/sensor_pose", "geometry_msgs/msg/TransformStamped", ns,
                            tf_stamped(ns, "map", "sensor", t, q)))
            elif pose_kind == "odom":
                cov = np.zeros(36, dtype=np.float64)
                out.append(("/odom", "nav_msgs/msg/Odometry", ns, T["nav_msgs/msg/Odometry"](
                    header=header(ns, "odom"), child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(t, q), covariance=cov),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](
                        twist=T["geometry_msgs/msg/Twist"](
                            linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                            angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                        covariance=cov))))
        # Clouds are logged a little after their stamp, as a recorder sees them.
        out.append(("/points", "sensor_msgs/msg/PointCloud2", ns + 1_000_000, cloud(xyz, ns, color, organised)))
    out.sort(key=lambda m: m[2])
    return out, len(clouds)


def raw(msgs):
    """The messages as (topic, type, log_time_ns, CDR bytes), as write_bag.py's writers take them."""
    return [(topic, typ, ns, TS.serialize_cdr(msg, typ)) for topic, typ, ns, msg in msgs]


def as_dict(msg):
    if hasattr(msg, "__dataclass_fields__"):
        return {k: as_dict(getattr(msg, k)) for k in msg.__dataclass_fields__ if k != "__msgtype__"}
    if isinstance(msg, list):
        return [as_dict(m) for m in msg]
    if isinstance(msg, np.ndarray):
        return msg.tobytes() if msg.dtype == np.uint8 else msg.tolist()
    return msg


def write_mcap_ros2(path, msgs):
    from mcap_ros2.writer import Writer
    with open(path, "wb") as f:
        w = Writer(f)
        schemas = {}
        for topic, typ, ns, msg in msgs:
            if typ not in schemas:
                schemas[typ] = w.register_msgdef(typ, msgdef(typ))
            w.write_message(topic=topic, schema=schemas[typ], message=as_dict(msg), log_time=ns, publish_time=ns)
        w.finish()


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--graph", required=True)
    p.add_argument("--kind", required=True, choices=["db3", "db3-file-zstd", "db3-message-zstd", "rosbag2-mcap", "mcap-zstd", "mcap-lz4", "mcap-none", "mcap-ros2"])
    p.add_argument("--pose", default="tf", choices=["tf", "pose", "odom", "transform", "none"])
    p.add_argument("--color", action="store_true")
    p.add_argument("--organised", action="store_true")
    p.add_argument("--late", action="store_true")
    p.add_argument("--tf-fault", choices=["cycle", "two-parents", "nan"])
    p.add_argument("--late-root", type=float)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    msgs, clouds = messages(read_graph(a.graph), a.pose, a.color, a.organised, a.late, a.tf_fault, a.late_root)
    from mcap.writer import CompressionType
    from rosbags.rosbag2 import StoragePlugin
    # MCAP files in the writer's default 1 MiB chunks, as recorders make them.
    mcap = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
    if a.kind == "db3":
        write_rosbag2(a.out, raw(msgs), StoragePlugin.SQLITE3)
    elif a.kind == "db3-file-zstd":
        write_rosbag2(a.out, raw(msgs), StoragePlugin.SQLITE3, "file")
    elif a.kind == "db3-message-zstd":
        write_rosbag2(a.out, raw(msgs), StoragePlugin.SQLITE3, "message")
    elif a.kind == "rosbag2-mcap":
        write_rosbag2(a.out, raw(msgs), StoragePlugin.MCAP)
    elif a.kind == "mcap-ros2":
        write_mcap_ros2(a.out, msgs)
    else:
        write_mcap(a.out, raw(msgs), mcap[a.kind.split("-")[1]], True, chunk_size=1 << 20)
    print(json.dumps({"kind": a.kind, "clouds": clouds, "path": a.out}))


if __name__ == "__main__":
    sys.exit(main())
