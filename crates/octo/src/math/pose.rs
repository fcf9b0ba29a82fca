//! Poses in OctoMap's `f32` arithmetic: quaternion products and rotations in its order of
//! operations, and a scan's points and origin in the map frame as `graph2tree` computes them.

use crate::{Pose, Scan};

/// Quaternion product in `f32`, in OctoMap's order of operations.
fn qmul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [au, ax, ay, az] = a;
    let [bu, bx, by, bz] = b;
    [
        au * bu - ax * bx - ay * by - az * bz,
        ay * bz - by * az + au * bx + bu * ax,
        az * bx - bz * ax + au * by + bu * ay,
        ax * by - bx * ay + au * bz + bu * az,
    ]
}

/// `q * v * q^-1` as OctoMap's `Quaternion::rotate` computes it (no normalisation).
fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let inv = [q[0], -q[1], -q[2], -q[3]];
    let r = qmul(qmul(q, [0.0, v[0], v[1], v[2]]), inv);
    [r[1], r[2], r[3]]
}

fn normalized(q: [f32; 4]) -> [f32; 4] {
    let mut n = 0.0f64;
    for c in q {
        n += (c * c) as f64;
    }
    let len = n.sqrt() as f32;
    if len > 0.0 {
        [q[0] / len, q[1] / len, q[2] / len, q[3] / len]
    } else {
        q
    }
}

fn transform(pose: &Pose, v: [f32; 3]) -> [f32; 3] {
    let r = rotate(pose.rotation, v);
    let t = pose.translation_m;
    [r[0] + t[0], r[1] + t[1], r[2] + t[2]]
}

fn inverse(pose: &Pose) -> Pose {
    let q = normalized([
        pose.rotation[0],
        -pose.rotation[1],
        -pose.rotation[2],
        -pose.rotation[3],
    ]);
    let t = pose.translation_m;
    Pose {
        translation_m: rotate(q, [-t[0], -t[1], -t[2]]),
        rotation: q,
    }
}

/// The points of a scan in the map frame and the sensor origin, computed exactly as
/// `graph2tree` does (the origin goes through the inverse pose and back, in `f32`).
pub fn world_points(scan: &Scan) -> (Vec<[f32; 3]>, [f32; 3]) {
    let pose = &scan.pose;
    let sensor = transform(&inverse(pose), pose.translation_m);
    let origin = transform(pose, sensor);
    let pts = scan.points.iter().map(|&p| transform(pose, p)).collect();
    (pts, origin)
}
