#!/usr/bin/env python3
"""A ROS 2 peer on Eclipse Cyclone DDS (PyPI `cyclonedds`, the real C library in the wheel),
standing in for the vehicle's sensors and for the operator's RViz in the process tests.

Subcommands (each prints one JSON line when it ends; progress lines go to stderr):

  play BAG        publishes the messages of an MCAP bag (PointCloud2, TFMessage, PoseStamped,
                  Odometry topics) live under their own topic names: /tf_static first
                  (transient-local), then every message in log-time order, one cloud every
                  --period seconds. Waits until every writer has --wait-readers readers first.
  session         listens to a tdma-run session on the graph (pose, tf, velocity, image,
                  status, /rosout) for --seconds, publishing a Twist (--twist) and a goal pose
                  (--goal) on the way, and reports what it heard.
  probe           round trips through crates/ros2/examples/ros2_echo.rs (scripts/ros2-measure.sh):
                  discovery time and the round trip of clouds of --sizes bytes, or poses.
  camera          publishes camera frames (raw rgb8, or PNG on a /compressed topic) at 2 Hz.
  vehicle         a stand-in vehicle whose stack speaks ROS 2 (cmd_vel, goal_pose, arm in; odom
                  out), for tdma-run --vehicle ros2.
  flood           hostile: many topics, a cmd_vel flood (NaN with --nan), a huge cloud.
  latched TOPIC   joins late and takes the last octomap_msgs/msg/Octomap (or PointCloud2 with
                  --type cloud) of TOPIC (reliable, transient-local, keep-last 1), writes its
                  fields to --out (JSON) and its data to --out + ".data"; with --expect-bytes
                  N, the first message whose data has N bytes.

The domain is --domain; discovery is unicast on loopback (../shared/design/facts.md, "ROS 2
without a ROS installation"): the configuration is written next to --out or in a temporary
directory and given as CYCLONEDDS_URI before the library starts.
"""
import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass

CONFIG = (
    '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any"><General><Interfaces>'
    '<NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast></General>'
    "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32"
    '</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery><Internal>'
    '<SocketReceiveBufferSize max="16MB"/></Internal></Domain></CycloneDDS>'
)


def configure():
    d = tempfile.mkdtemp(prefix="cyclone-")
    path = os.path.join(d, "cyclonedds.xml")
    with open(path, "w") as f:
        f.write(CONFIG)
    os.environ["CYCLONEDDS_URI"] = "file://" + path


configure()

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.annotations import final  # noqa: E402
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402


def dds(pkg, name):
    return f"{pkg}::msg::dds_::{name}_"


@final
@dataclass
class Time(IdlStruct, typename=dds("builtin_interfaces", "Time")):
    sec: t.int32
    nanosec: t.uint32


@final
@dataclass
class Header(IdlStruct, typename=dds("std_msgs", "Header")):
    stamp: Time
    frame_id: str


@final
@dataclass
class PointField(IdlStruct, typename=dds("sensor_msgs", "PointField")):
    name: str
    offset: t.uint32
    datatype: t.uint8
    count: t.uint32


@final
@dataclass
class PointCloud2(IdlStruct, typename=dds("sensor_msgs", "PointCloud2")):
    header: Header
    height: t.uint32
    width: t.uint32
    fields: t.sequence[PointField]
    is_bigendian: bool
    point_step: t.uint32
    row_step: t.uint32
    data: t.sequence[t.uint8]
    is_dense: bool


@final
@dataclass
class Vector3(IdlStruct, typename=dds("geometry_msgs", "Vector3")):
    x: t.float64
    y: t.float64
    z: t.float64


@final
@dataclass
class Point(IdlStruct, typename=dds("geometry_msgs", "Point")):
    x: t.float64
    y: t.float64
    z: t.float64


@final
@dataclass
class Quaternion(IdlStruct, typename=dds("geometry_msgs", "Quaternion")):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@final
@dataclass
class Transform(IdlStruct, typename=dds("geometry_msgs", "Transform")):
    translation: Vector3
    rotation: Quaternion


@final
@dataclass
class TransformStamped(IdlStruct, typename=dds("geometry_msgs", "TransformStamped")):
    header: Header
    child_frame_id: str
    transform: Transform


@final
@dataclass
class TFMessage(IdlStruct, typename=dds("tf2_msgs", "TFMessage")):
    transforms: t.sequence[TransformStamped]


@final
@dataclass
class Pose(IdlStruct, typename=dds("geometry_msgs", "Pose")):
    position: Point
    orientation: Quaternion


@final
@dataclass
class PoseStamped(IdlStruct, typename=dds("geometry_msgs", "PoseStamped")):
    header: Header
    pose: Pose


@final
@dataclass
class Octomap(IdlStruct, typename=dds("octomap_msgs", "Octomap")):
    header: Header
    binary: bool
    id: str
    resolution: t.float64
    data: t.sequence[t.int8]


@final
@dataclass
class Twist(IdlStruct, typename=dds("geometry_msgs", "Twist")):
    linear: Vector3
    angular: Vector3


@final
@dataclass
class TwistStamped(IdlStruct, typename=dds("geometry_msgs", "TwistStamped")):
    header: Header
    twist: Twist


@final
@dataclass
class CompressedImage(IdlStruct, typename=dds("sensor_msgs", "CompressedImage")):
    header: Header
    format: str
    data: t.sequence[t.uint8]


@final
@dataclass
class String(IdlStruct, typename=dds("std_msgs", "String")):
    data: str


@final
@dataclass
class Log(IdlStruct, typename=dds("rcl_interfaces", "Log")):
    stamp: Time
    level: t.uint8
    name: str
    msg: str
    file: str
    function: str
    line: t.uint32


@final
@dataclass
class Image(IdlStruct, typename=dds("sensor_msgs", "Image")):
    header: Header
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@final
@dataclass
class Bool(IdlStruct, typename=dds("std_msgs", "Bool")):
    data: bool


@final
@dataclass
class PoseWithCovariance(IdlStruct, typename=dds("geometry_msgs", "PoseWithCovariance")):
    pose: Pose
    covariance: t.array[t.float64, 36]


@final
@dataclass
class TwistWithCovariance(IdlStruct, typename=dds("geometry_msgs", "TwistWithCovariance")):
    twist: Twist
    covariance: t.array[t.float64, 36]


@final
@dataclass
class Odometry(IdlStruct, typename=dds("nav_msgs", "Odometry")):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


TYPES = {
    "sensor_msgs/msg/PointCloud2": PointCloud2,
    "tf2_msgs/msg/TFMessage": TFMessage,
    "geometry_msgs/msg/PoseStamped": PoseStamped,
    "geometry_msgs/msg/TransformStamped": TransformStamped,
}


def reliable(transient=False, depth=None):
    policies = [Policy.Reliability.Reliable(max_blocking_time=1_000_000_000)]
    if transient:
        policies.append(Policy.Durability.TransientLocal)
    policies.append(Policy.History.KeepLast(depth) if depth else Policy.History.KeepAll)
    if transient and not depth:
        policies.append(Policy.DurabilityService(0, Policy.History.KeepAll, -1, -1, -1))
    return Qos(*policies)


def say(**fields):
    print(json.dumps(fields), flush=True)


def play(args):
    from mcap.reader import make_reader

    with open(args.bag, "rb") as f:
        reader = make_reader(f)
        messages = []
        topics = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if schema.name not in TYPES:
                continue
            topics[channel.topic] = schema.name
            messages.append((channel.topic, message.data))
    dp = DomainParticipant(args.domain)
    writers = {}
    for name, schema in topics.items():
        latched = name.endswith("tf_static")
        qos = reliable(transient=latched, depth=100 if "tf" in name else None)
        topic = Topic(dp, "rt" + name, TYPES[schema], qos=qos)
        writers[name] = DataWriter(dp, topic, qos=qos)
    deadline = time.monotonic() + args.timeout
    while any(
        len(w.get_matched_subscriptions()) < args.wait_readers for w in writers.values()
    ):
        if time.monotonic() > deadline:
            say(ok=False, why="no readers", topics=sorted(topics))
            return 1
        time.sleep(0.05)
    print(f"peer: {len(writers)} topics matched", file=sys.stderr, flush=True)
    clouds = 0
    statics = [m for m in messages if m[0].endswith("tf_static")]
    for name, data in statics:
        writers[name].write(TYPES[topics[name]].deserialize(data))
    next_cloud = time.monotonic()
    for name, data in messages:
        if name.endswith("tf_static"):
            continue
        schema = topics[name]
        if schema == "sensor_msgs/msg/PointCloud2":
            now = time.monotonic()
            if next_cloud > now:
                time.sleep(next_cloud - now)
            next_cloud = max(now, next_cloud) + args.period
            clouds += 1
        writers[name].write(TYPES[schema].deserialize(data))
    # Reliable delivery of the last samples before the participant goes.
    time.sleep(args.linger)
    say(ok=True, clouds=clouds, messages=len(messages))
    return 0


def latched(args):
    dp = DomainParticipant(args.domain)
    kind = Octomap if args.type == "octomap" else PointCloud2
    qos = reliable(transient=True, depth=1)
    topic = Topic(dp, "rt" + args.topic, kind, qos=qos)
    reader = DataReader(dp, topic, qos=qos)
    deadline = time.monotonic() + args.timeout
    seen = []
    while time.monotonic() < deadline:
        samples = reader.take(N=16)
        seen.extend(len(m.data) for m in samples)
        if args.expect_bytes is not None:
            samples = [m for m in samples if len(m.data) == args.expect_bytes]
        if samples:
            m = samples[-1]
            data = bytes(x & 0xFF for x in m.data) if kind is Octomap else bytes(m.data)
            with open(args.out + ".data", "wb") as f:
                f.write(data)
            fields = {"frame_id": m.header.frame_id, "bytes": len(data)}
            if kind is Octomap:
                fields.update(id=m.id, binary=m.binary, resolution=m.resolution)
            else:
                fields.update(width=m.width, height=m.height, point_step=m.point_step,
                              fields=[f.name for f in m.fields])
            with open(args.out, "w") as f:
                json.dump(fields, f)
            say(ok=True, **fields)
            return 0
        time.sleep(0.05)
    say(ok=False, why="not the message expected", data_bytes_seen=seen)
    return 1


def session(args):
    """Listens to a tdma-run session until --until-goal or --poses-after-goal is met (at most
    --seconds); with --twist, publishes that Twist on NS/cmd_vel at 5 Hz from 1 s to
    1 + --twist-seconds; with --goal, a goal pose at --goal-at s. Reports what it heard."""
    import io
    dp = DomainParticipant(args.domain)
    ns = args.namespace
    q = reliable(depth=10)
    latched_q = reliable(transient=True, depth=1)
    subs = {
        "pose": (ns + "/pose", PoseStamped, q),
        "tf": ("/tf", TFMessage, reliable(depth=100)),
        "velocity": (ns + "/velocity", TwistStamped, q),
        "image": (ns + "/image/compressed", CompressedImage, latched_q),
        "status": (ns + "/status", String, latched_q),
        "rosout": ("/rosout", Log, q),
    }
    readers = {k: DataReader(dp, Topic(dp, "rt" + n, ty, qos=qq), qos=qq) for k, (n, ty, qq) in subs.items()}
    twist_w = DataWriter(dp, Topic(dp, "rt" + ns + "/cmd_vel", Twist, qos=q), qos=q)
    goal_w = DataWriter(dp, Topic(dp, "rt" + ns + "/goal_pose", PoseStamped, qos=q), qos=q)
    counts = {k: 0 for k in readers}
    first = {}
    poses = []
    images_ok = 0
    logs = []
    status = None
    t0 = time.monotonic()
    next_twist = 1.0
    goal_sent = False
    done = False
    poses_after_goal = 0
    while not done:
        now = time.monotonic() - t0
        if now > args.seconds:
            break
        if args.twist and 1.0 <= now <= 1.0 + args.twist_seconds and now >= next_twist:
            x, y, z, yaw = args.twist
            twist_w.write(Twist(Vector3(x, y, z), Vector3(0.0, 0.0, yaw)))
            next_twist = now + 0.2
        if args.goal and not goal_sent and now >= args.goal_at:
            gx, gy, gz = args.goal
            goal_w.write(PoseStamped(Header(Time(0, 0), "ned"),
                                     Pose(Point(gx, gy, gz), Quaternion(0.0, 0.0, 0.0, 1.0))))
            goal_sent = True
        for k, r in readers.items():
            for m in r.take(N=64):
                counts[k] += 1
                first.setdefault(k, round(now, 3))
                if k == "pose":
                    p = m.pose.position
                    poses.append([round(now, 2), p.x, p.y, p.z])
                    if goal_sent:
                        poses_after_goal += 1
                        gx, gy, gz = args.goal
                        near = ((p.x - gx) ** 2 + (p.y - gy) ** 2 + (p.z - gz) ** 2) ** 0.5
                        if args.until_goal is not None and near <= args.until_goal:
                            done = True
                        if args.poses_after_goal and poses_after_goal >= args.poses_after_goal:
                            done = True
                elif k == "image":
                    try:
                        from PIL import Image
                        Image.open(io.BytesIO(bytes(m.data))).load()
                        images_ok += 1
                    except Exception as e:  # noqa: BLE001  reported, not raised
                        logs.append("image does not decode: %s" % e)
                elif k == "rosout":
                    logs.append(m.msg)
                elif k == "status":
                    status = json.loads(m.data)
        time.sleep(0.02)
    waited = args.until_goal is not None or args.poses_after_goal
    say(ok=done or not waited, seconds=round(time.monotonic() - t0, 2), counts=counts, first_s=first, images_decoded=images_ok,
        start=poses[0][1:] if poses else None, last=poses[-1][1:] if poses else None,
        max_x=max((p[1] for p in poses), default=None), logs=logs[-40:], status=status)
    return 0


def probe(args):
    """Round trips through an echo (crates/ros2/examples/ros2_echo.rs) on /probe/in ->
    /probe/out: when both our endpoints had matched the echo's (wall clock, for the discovery
    time of an echo started after this), then
    --count messages of each size, one at a time; reports the round trips' median and max."""
    import statistics
    dp = DomainParticipant(args.domain)
    q = reliable(depth=4)
    kind = PointCloud2 if args.type == "cloud" else PoseStamped
    w = DataWriter(dp, Topic(dp, "rt/probe/in", kind, qos=q), qos=q)
    r = DataReader(dp, Topic(dp, "rt/probe/out", kind, qos=q), qos=q)
    t0 = time.monotonic()
    print("peer: waiting for the echo", file=sys.stderr, flush=True)
    while not (w.get_matched_subscriptions() and r.get_matched_publications()):
        if time.monotonic() - t0 > args.timeout:
            say(ok=False, why="the echo was not discovered")
            return 1
        time.sleep(0.002)
    matched_unix_s = time.time()
    results = {}
    for size in args.sizes:
        rtts = []
        for k in range(args.count):
            if kind is PointCloud2:
                msg = PointCloud2(Header(Time(k, 0), "probe"), 1, size // 16,
                                  [PointField("x", 0, 7, 1)], False, 16, size, bytes(size), True)
            else:
                msg = PoseStamped(Header(Time(k, 0), "probe"),
                                  Pose(Point(1.0, 2.0, 3.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
            t = time.monotonic()
            w.write(msg)
            got = None
            while got is None and time.monotonic() - t < 60:
                for m in r.take(N=4):
                    if m.header.stamp.sec == k:
                        got = time.monotonic() - t
                if got is None:
                    time.sleep(0.0005)
            if got is None:
                say(ok=False, why="message %d of %d B not echoed" % (k, size))
                return 1
            rtts.append(got)
        results[str(size)] = {"rtt_median_s": statistics.median(rtts), "rtt_max_s": max(rtts)}
    say(ok=True, matched_unix_s=matched_unix_s, results=results)
    return 0


def camera(args):
    """Publishes camera frames on --topic at 2 Hz for --seconds (sensor-data QoS: best effort,
    keep-last 1): a --width x --height picture, dark on the left half and bright on the
    right, as rgb8 (Image) or PNG (CompressedImage, for a topic ending in /compressed)."""
    import io
    from PIL import Image as PilImage
    dp = DomainParticipant(args.domain)
    q = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1))
    w, h = args.width, args.height
    rgb = bytearray()
    for _y in range(h):
        for x in range(w):
            rgb += bytes([40, 40, 40]) if x < w // 2 else bytes([220, 200, 180])
    compressed = args.topic.endswith("/compressed")
    kind = CompressedImage if compressed else Image
    writer = DataWriter(dp, Topic(dp, "rt" + args.topic, kind, qos=q), qos=q)
    if compressed:
        buf = io.BytesIO()
        PilImage.frombytes("RGB", (w, h), bytes(rgb)).save(buf, format="PNG")
        png = buf.getvalue()
    t0 = time.monotonic()
    frames = 0
    while time.monotonic() - t0 < args.seconds:
        stamp = Header(Time(frames, 0), "camera")
        if compressed:
            writer.write(CompressedImage(stamp, "png", png))
        else:
            writer.write(Image(stamp, h, w, "rgb8", 0, 3 * w, bytes(rgb)))
        frames += 1
        time.sleep(0.5)
    say(ok=True, frames=frames)
    return 0


def vehicle(args):
    """A stand-in for a vehicle whose stack speaks ROS 2 (REP 103: odom east-north-up, body
    forward-left-up): armed by NS/arm, it moves at NS/cmd_vel x 0.5 m/s (and 0.5 rad/s) or
    straight to NS/goal_pose at 0.5 m/s, and publishes NS/odom at 20 Hz. Ends once it has held
    a goal for 1 s (or at --seconds) and reports what it was told and where it ended."""
    import math
    dp = DomainParticipant(args.domain)
    ns = args.namespace
    q = reliable(depth=10)
    latched_q = reliable(transient=True, depth=1)
    twist_r = DataReader(dp, Topic(dp, "rt" + ns + "/cmd_vel", Twist, qos=q), qos=q)
    goal_r = DataReader(dp, Topic(dp, "rt" + ns + "/goal_pose", PoseStamped, qos=latched_q), qos=latched_q)
    arm_r = DataReader(dp, Topic(dp, "rt" + ns + "/arm", Bool, qos=latched_q), qos=latched_q)
    odom_w = DataWriter(dp, Topic(dp, "rt" + ns + "/odom", Odometry, qos=q), qos=q)
    pos = [0.0, 0.0, 0.0]
    yaw = math.pi / 2  # facing north
    armed = False
    armed_seen = False
    twist = (0.0, 0.0, 0.0, 0.0)
    max_twist_x = 0.0
    goals = []
    goal = None
    held = 0.0
    dt = 0.05
    t0 = time.monotonic()
    while time.monotonic() - t0 < args.seconds:
        for m in arm_r.take(N=16):
            armed = bool(m.data)
            armed_seen = armed_seen or armed
        for m in twist_r.take(N=64):
            twist = (m.linear.x, m.linear.y, m.linear.z, m.angular.z)
            max_twist_x = max(max_twist_x, m.linear.x)
            if any(abs(v) > 0 for v in twist):
                goal = None
        for m in goal_r.take(N=16):
            p, o = m.pose.position, m.pose.orientation
            goal = (p.x, p.y, p.z, 2 * math.atan2(o.z, o.w))
            goals.append([round(v, 3) for v in goal])
        vel = [0.0, 0.0, 0.0]
        wz = 0.0
        if armed and goal is not None:
            d = [goal[k] - pos[k] for k in range(3)]
            dist = math.sqrt(sum(v * v for v in d))
            step = min(dist, 0.5 * dt)
            if dist > 1e-9:
                pos = [pos[k] + d[k] / dist * step for k in range(3)]
            yaw = goal[3]
            if dist < 0.05:
                held += dt
                if held >= 1.0:
                    break
        elif armed:
            fx, fy, fz, fw = twist
            c, sn = math.cos(yaw), math.sin(yaw)
            vel = [0.5 * (fx * c - fy * sn), 0.5 * (fx * sn + fy * c), 0.5 * fz]
            wz = 0.5 * fw
            pos = [pos[k] + vel[k] * dt for k in range(3)]
            yaw += wz * dt
        odom_w.write(Odometry(
            Header(Time(int(time.time()), 0), "odom"), "base_link",
            PoseWithCovariance(Pose(Point(*pos), Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))), [0.0] * 36),
            TwistWithCovariance(Twist(Vector3(0.5 * twist[0] if armed else 0.0, 0.0, 0.0), Vector3(0.0, 0.0, wz)), [0.0] * 36)))
        time.sleep(dt)
    say(ok=held >= 1.0, armed_seen=armed_seen, max_twist_x=max_twist_x, goals=goals,
        final=[round(v, 3) for v in pos], yaw=round(yaw, 3))
    return 0


def flood(args):
    """Hostile: --topics extra topics advertised on the domain (each a writer), then Twists on
    NS/cmd_vel as fast as they go for --seconds (with --nan, every other one NaN), and, with
    --cloud-mb, one PointCloud2 of that many MB on --cloud-topic. Reports what was sent."""
    dp = DomainParticipant(args.domain)
    q = reliable(depth=10)
    extra = [DataWriter(dp, Topic(dp, "rt/hostile/t%d" % k, String, qos=q), qos=q)
             for k in range(args.topics)]
    for k, w in enumerate(extra):
        w.write(String("x%d" % k))
    sent = 0
    if args.cloud_mb:
        cw = DataWriter(dp, Topic(dp, "rt" + args.cloud_topic, PointCloud2, qos=q), qos=q)
        size = int(args.cloud_mb * 1e6) // 16 * 16
        cw.write(PointCloud2(Header(Time(0, 0), "base_link"), 1, size // 16,
                             [PointField("x", 0, 7, 1), PointField("y", 4, 7, 1),
                              PointField("z", 8, 7, 1)], False, 16, size, bytes(size), True))
        try:  # every fragment acknowledged before the participant goes
            cw.wait_for_acks(120 * 10**9)
        except Exception:  # noqa: BLE001  an older binding: the reader's own wait covers it
            time.sleep(10)
    tw = DataWriter(dp, Topic(dp, "rt" + args.namespace + "/cmd_vel", Twist, qos=q), qos=q)
    t0 = time.monotonic()
    while time.monotonic() - t0 < args.seconds:
        x = float("nan") if args.nan and sent % 2 else 0.2
        tw.write(Twist(Vector3(x, 0.0, 0.0), Vector3(0.0, 0.0, 0.0)))
        sent += 1
    time.sleep(1.0)
    say(ok=True, twists=sent, topics=args.topics, cloud_mb=args.cloud_mb)
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--timeout", type=float, default=120)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("play")
    a.add_argument("bag")
    a.add_argument("--period", type=float, default=0.5)
    a.add_argument("--wait-readers", type=int, default=1)
    a.add_argument("--linger", type=float, default=2.0)
    b = sub.add_parser("latched")
    b.add_argument("topic")
    b.add_argument("--type", choices=["octomap", "cloud"], default="octomap")
    b.add_argument("--out", required=True)
    b.add_argument("--expect-bytes", type=int,
                   help="wait for a message whose data has this many bytes (a late joiner may "
                        "get older samples first)")
    c = sub.add_parser("session")
    c.add_argument("--namespace", default="/rov")
    c.add_argument("--seconds", type=float, default=20)
    c.add_argument("--twist", type=lambda v: [float(x) for x in v.split(",")])
    c.add_argument("--twist-seconds", type=float, default=3)
    c.add_argument("--goal", type=lambda v: [float(x) for x in v.split(",")])
    c.add_argument("--goal-at", type=float, default=6)
    c.add_argument("--until-goal", type=float, metavar="M",
                   help="end once a pose within M metres of --goal comes (else at --seconds)")
    c.add_argument("--poses-after-goal", type=int, metavar="N",
                   help="end once N poses came after the goal was sent")
    d = sub.add_parser("probe")
    d.add_argument("--type", choices=["cloud", "pose"], default="cloud")
    d.add_argument("--sizes", type=lambda v: [int(x) for x in v.split(",")], default=[0])
    d.add_argument("--count", type=int, default=5)
    e = sub.add_parser("camera")
    e.add_argument("--topic", required=True)
    e.add_argument("--width", type=int, default=64)
    e.add_argument("--height", type=int, default=48)
    e.add_argument("--seconds", type=float, default=60)
    f = sub.add_parser("vehicle")
    f.add_argument("--namespace", default="/rov")
    f.add_argument("--seconds", type=float, default=120)
    g = sub.add_parser("flood")
    g.add_argument("--namespace", default="/rov")
    g.add_argument("--seconds", type=float, default=10)
    g.add_argument("--topics", type=int, default=0)
    g.add_argument("--nan", action="store_true")
    g.add_argument("--cloud-mb", type=float, default=0)
    g.add_argument("--cloud-topic", default="/points")
    args = p.parse_args()
    commands = {"play": play, "latched": latched, "session": session, "probe": probe,
                "camera": camera, "vehicle": vehicle, "flood": flood}
    return commands[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
