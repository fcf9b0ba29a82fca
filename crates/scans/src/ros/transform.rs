//! Rigid transforms in `f64` as ROS holds them ([`Transform`]): applied to points, composed,
//! inverted and interpolated (slerp), and checked as tf2 checks a transform's numbers
//! ([`TransformProblem`]).

use rovlink_octo::Pose;

/// A rigid transform: a point `p` in the child frame is `rotation * p + translation_m` in the
/// parent frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Translation x, y, z in metres.
    pub translation_m: [f64; 3],
    /// Rotation quaternion (w, x, y, z), of unit length (within tf2's tolerance).
    pub rotation: [f64; 4],
}

/// What is wrong with a transform's numbers, for error messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TransformProblem {
    /// A value is NaN or infinite: which (as in the message: translation x, y, z, then rotation
    /// x, y, z, w) and the value.
    NotFinite {
        /// `translation.x` ... `rotation.w`.
        field: &'static str,
        /// The value found.
        value: f64,
    },
    /// The quaternion's squared norm is more than 0.01 from 1 (tf2's rule).
    NotUnit {
        /// The squared norm found.
        norm2: f64,
    },
}

impl std::fmt::Display for TransformProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TransformProblem::NotFinite { field, value } => {
                write!(f, "{field}: expected a finite number, found {value:?}")
            }
            TransformProblem::NotUnit { norm2 } => write!(
                f,
                "rotation: expected a unit quaternion (squared norm within 0.01 of 1), found \
                 squared norm {norm2}"
            ),
        }
    }
}

/// Field names of a transform's seven numbers, in message order.
pub(super) const TRANSFORM_FIELDS: [&str; 7] = [
    "translation.x",
    "translation.y",
    "translation.z",
    "rotation.x",
    "rotation.y",
    "rotation.z",
    "rotation.w",
];

/// The squared norm of `q` if it is out of tf2's tolerance.
pub(super) fn not_unit(q: [f64; 4]) -> Option<f64> {
    let norm2 = q.iter().map(|v| v * v).sum::<f64>();
    ((norm2 - 1.0).abs() > 0.01).then_some(norm2)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a ⊗ b`, Hamilton's product of quaternions (w, x, y, z).
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

impl Transform {
    /// No motion: zero translation, rotation (1, 0, 0, 0).
    pub const IDENTITY: Transform = Transform {
        translation_m: [0.0; 3],
        rotation: [1.0, 0.0, 0.0, 0.0],
    };

    /// The transform of an OctoMap pose (`f32` widened exactly to `f64`).
    pub fn from_pose(pose: &Pose) -> Transform {
        Transform {
            translation_m: pose.translation_m.map(f64::from),
            rotation: pose.rotation.map(f64::from),
        }
    }

    /// The pose OctoMap would read from these numbers: each rounded to `f32`, the quaternion not
    /// renormalised. `None` when a value is not finite as `f32` (NaN, infinite, or beyond
    /// `f32`'s range).
    pub fn to_pose(&self) -> Option<Pose> {
        let f = |v: f64| Some(v as f32).filter(|x| x.is_finite());
        let [x, y, z] = self.translation_m;
        let [qw, qx, qy, qz] = self.rotation;
        Some(Pose {
            translation_m: [f(x)?, f(y)?, f(z)?],
            rotation: [f(qw)?, f(qx)?, f(qy)?, f(qz)?],
        })
    }

    /// Whether every number is finite and the quaternion is of unit length within tf2's
    /// tolerance (`|norm² - 1| <= 0.01`).
    pub fn check(&self) -> Result<(), TransformProblem> {
        let [qw, qx, qy, qz] = self.rotation;
        let values = [
            self.translation_m[0],
            self.translation_m[1],
            self.translation_m[2],
            qx,
            qy,
            qz,
            qw,
        ];
        for (value, field) in values.into_iter().zip(TRANSFORM_FIELDS) {
            if !value.is_finite() {
                return Err(TransformProblem::NotFinite { field, value });
            }
        }
        match not_unit(self.rotation) {
            Some(norm2) => Err(TransformProblem::NotUnit { norm2 }),
            None => Ok(()),
        }
    }

    /// `p` rotated by the quaternion (taken as unit) and translated.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let [w, x, y, z] = self.rotation;
        let u = [x, y, z];
        let c = cross(u, p);
        let t = [2.0 * c[0], 2.0 * c[1], 2.0 * c[2]];
        let ut = cross(u, t);
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = p[i] + w * t[i] + ut[i] + self.translation_m[i];
        }
        out
    }

    /// `self * other`: the transform that takes a point `p` in `other`'s child frame to
    /// `self.apply(other.apply(p))` (for `other` from frame A to B and `self` from B to C, the
    /// transform from A to C). Composing with an exact [`Transform::IDENTITY`] on either side
    /// gives the other transform bit for bit.
    pub fn compose(&self, other: &Transform) -> Transform {
        if *self == Transform::IDENTITY {
            return *other;
        }
        if *other == Transform::IDENTITY {
            return *self;
        }
        Transform {
            translation_m: self.apply(other.translation_m),
            rotation: quat_mul(self.rotation, other.rotation),
        }
    }

    /// The inverse motion (the quaternion conjugated, as tf2 does for unit quaternions).
    pub fn inverse(&self) -> Transform {
        let [w, x, y, z] = self.rotation;
        let rotation = [w, -x, -y, -z];
        let back = Transform {
            translation_m: [0.0; 3],
            rotation,
        }
        .apply(self.translation_m);
        Transform {
            translation_m: back.map(|v| -v),
            rotation,
        }
    }

    /// The transform a fraction `t` of the way from `self` to `other`: translation linear,
    /// rotation by spherical linear interpolation along the shortest arc (`q` and `-q` are the
    /// same rotation). `t = 0` gives `self` and `t = 1` gives `other`, bit for bit.
    pub fn interpolate(&self, other: &Transform, t: f64) -> Transform {
        if t == 0.0 {
            return *self;
        }
        if t == 1.0 {
            return *other;
        }
        let mut translation_m = [0.0; 3];
        for (i, v) in translation_m.iter_mut().enumerate() {
            let (a, b) = (self.translation_m[i], other.translation_m[i]);
            *v = a + (b - a) * t;
        }
        Transform {
            translation_m,
            rotation: slerp(self.rotation, other.rotation, t),
        }
    }
}

/// Spherical linear interpolation from `a` to `b` (or `-b`, whichever is nearer), fraction `t`.
fn slerp(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let mut b = b;
    if dot < 0.0 {
        b = b.map(|v| -v);
        dot = -dot;
    }
    let (wa, wb) = if dot > 0.9995 {
        // Nearly the same rotation: linear, then normalised below.
        (1.0 - t, t)
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        (((1.0 - t) * theta).sin() / s, (t * theta).sin() / s)
    };
    let mut q = [0.0; 4];
    for (i, v) in q.iter_mut().enumerate() {
        *v = wa * a[i] + wb * b[i];
    }
    if dot > 0.9995 {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if n > 0.0 {
            q = q.map(|v| v / n);
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;

    #[test]
    fn transform_algebra() {
        let a = Transform {
            translation_m: [1.0, 2.0, 3.0],
            rotation: [H, 0.0, 0.0, H], // 90 degrees about z
        };
        let p = a.apply([1.0, 0.0, 0.0]);
        for (g, w) in p.iter().zip([1.0, 3.0, 3.0]) {
            assert!((g - w).abs() < 1e-12, "{p:?}");
        }
        let b = Transform {
            translation_m: [-0.5, 0.25, 4.0],
            rotation: [0.5, 0.5, -0.5, 0.5],
        };
        let q = [0.3, -0.7, 2.0];
        let ab = a.compose(&b).apply(q);
        let seq = a.apply(b.apply(q));
        for (x, y) in ab.iter().zip(seq) {
            assert!((x - y).abs() < 1e-12);
        }
        let back = a.inverse().apply(a.apply(q));
        for (x, y) in back.iter().zip(q) {
            assert!((x - y).abs() < 1e-12);
        }
        // Identity on either side, bit for bit.
        assert_eq!(Transform::IDENTITY.compose(&b), b);
        assert_eq!(b.compose(&Transform::IDENTITY), b);
        assert_eq!(Transform::from_pose(&Pose::IDENTITY), Transform::IDENTITY);
        assert_eq!(Transform::IDENTITY.to_pose(), Some(Pose::IDENTITY));
        let far = Transform {
            translation_m: [1e39, 0.0, 0.0],
            ..Transform::IDENTITY
        };
        assert_eq!(far.to_pose(), None);
        assert_eq!(a.check(), Ok(()));
        assert_eq!(
            Transform {
                rotation: [2.0, 0.0, 0.0, 0.0],
                ..a
            }
            .check(),
            Err(TransformProblem::NotUnit { norm2: 4.0 })
        );
        assert!(matches!(
            Transform {
                rotation: [1.0, 0.0, f64::NAN, 0.0],
                ..a
            }
            .check(),
            Err(TransformProblem::NotFinite {
                field: "rotation.y",
                ..
            })
        ));
    }

    #[test]
    fn interpolation() {
        let a = Transform::IDENTITY;
        let b = Transform {
            translation_m: [2.0, -4.0, 6.0],
            rotation: [H, 0.0, 0.0, H],
        };
        let m = a.interpolate(&b, 0.5);
        assert_eq!(m.translation_m, [1.0, -2.0, 3.0]);
        // 90 degrees -> 45 degrees about z.
        let (c, s) = (
            std::f64::consts::FRAC_PI_8.cos(),
            std::f64::consts::FRAC_PI_8.sin(),
        );
        for (g, w) in m.rotation.iter().zip([c, 0.0, 0.0, s]) {
            assert!((g - w).abs() < 1e-12, "{:?}", m.rotation);
        }
        // -q is the same rotation: the shortest arc gives the same midpoint.
        let neg = Transform {
            rotation: b.rotation.map(|v| -v),
            ..b
        };
        let m2 = a.interpolate(&neg, 0.5);
        for (g, w) in m2.rotation.iter().zip([c, 0.0, 0.0, s]) {
            assert!((g - w).abs() < 1e-12, "{:?}", m2.rotation);
        }
        // Endpoints exactly.
        assert_eq!(a.interpolate(&b, 0.0), a);
        assert_eq!(a.interpolate(&b, 1.0), b);
        assert_eq!(a.interpolate(&neg, 1.0), neg);
        // Nearly equal rotations: normalised linear.
        let tiny = Transform {
            rotation: [1.0, 1e-6, 0.0, 0.0],
            ..a
        };
        let n = a.interpolate(&tiny, 0.25).rotation;
        assert!((n.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
