//! What a single-vehicle session is made of, and the ranges every session's settings are
//! checked against: the vocabulary the order sources, the scenario reader, the console and the
//! drivers share ([`SessionConfig`], [`Waypoint`], [`JoystickChange`], the limits). A leaf: it
//! uses the engines' types and the rules, never a driver or an output.

use crate::ImageSettings;
use crate::operator::Joystick;
use crate::rules;
use rovlink_debt as debt;
use rovlink_link::Model;

/// A GoTo order sent at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// When the operator queues it, s.
    pub t_s: f64,
    /// Target, NED m.
    pub position_m: [f64; 3],
    /// Heading, degrees.
    pub heading_deg: f64,
}

/// A joystick change at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoystickChange {
    /// When, s.
    pub t_s: f64,
    /// The new state.
    pub joystick: Joystick,
}

/// Everything a simulated session needs.
#[derive(Debug, Clone)]
pub struct SessionConfig {
    /// The link model (both directions).
    pub model: Model,
    /// Seed of the link's random streams.
    pub seed: u64,
    /// Inter-packet gap, s.
    pub ipg_s: f64,
    /// Length of the session, s.
    pub duration_s: f64,
    /// The operator modem's position, NED m.
    pub buoy_m: [f64; 3],
    /// The ROV's initial position, NED m.
    pub start_m: [f64; 3],
    /// Joystick changes, sorted by time.
    pub script: Vec<JoystickChange>,
    /// GoTo orders, sorted by time.
    pub waypoints: Vec<Waypoint>,
    /// Image settings at the start.
    pub settings: ImageSettings,
    /// The camera's pictures, cycled.
    pub images: Vec<debt::Image>,
}

/// The shortest inter-packet gap, s (a slot shorter than a millisecond carries no frame).
pub const MIN_IPG_S: f64 = 1e-3;
/// The longest inter-packet gap, s (10 minutes).
pub const MAX_IPG_S: f64 = 600.0;
/// The longest session, s (a week).
pub const MAX_DURATION_S: f64 = 7.0 * 86_400.0;
/// The farthest a buoy or a start position may be from the site's origin along any axis, m: no
/// real site is 100 km across.
pub const MAX_POSITION_M: f64 = 100_000.0;
/// The farthest a waypoint may be along any axis, m: what a GoTo order carries (i16 cm).
pub const MAX_WAYPOINT_M: f64 = 327.67;
/// The smallest encoded image, bytes.
pub const MIN_IMAGE_BYTES: u16 = 16;

/// An IPG held to [`MIN_IPG_S`] ..= [`MAX_IPG_S`] by [`bound_ipg`], and whether it had to be.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundedIpg {
    /// The IPG within the bounds, s: the one given when it was within them, else the nearer
    /// bound (`f64::clamp`'s value: not a number stays not a number).
    pub ipg_s: f64,
    /// True when the IPG given was not within the bounds (or not finite), so `ipg_s` is not it.
    pub clamped: bool,
}

/// The one rule for the bounds of an IPG (a TDMA slot: an exchange and its guard),
/// [`MIN_IPG_S`] ..= [`MAX_IPG_S`]. It says where `ipg_s` falls; each caller decides what a
/// value outside means, as its source calls for:
///
/// - [`SessionConfig::validate`] refuses it (`IPG: expected 1 ms ..= 10 min, found ...`): a
///   session's IPG is a setting (`--ipg`, or a library caller's), and a setting is never
///   changed behind its owner's back.
/// - `Scenario::auto_slot_s` takes the clamped value: an `auto` slot is derived from the
///   models (the exchange's air times, delays and guards), and a derived slot beyond a bound
///   (a model of a very slow or very fast link) is still a slot to run, at the bound.
/// - tdma-run's network node (`--routes`) takes the clamped value for its session's IPG:
///   that IPG is the network's cycle, which only its validation looks at (the node's ends run
///   at the scenario's slots), and a cycle of many slots may be longer than one IPG may be.
///
/// The values a user gives are refused before any of these, in their own words, against the
/// same bounds: `--ipg` by tdma-run's parser, a scenario's `slot_s` by the scenario reader.
pub fn bound_ipg(ipg_s: f64) -> BoundedIpg {
    BoundedIpg {
        ipg_s: ipg_s.clamp(MIN_IPG_S, MAX_IPG_S),
        clamped: !(ipg_s.is_finite() && (MIN_IPG_S..=MAX_IPG_S).contains(&ipg_s)),
    }
}

/// A session setting out of its range: `what`, what it must be, what it is.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what}: expected {expected}, found {found}")]
pub struct ConfigError {
    /// The setting, e.g. `IPG` or `waypoint 3`.
    pub what: String,
    /// Its range, with units.
    pub expected: String,
    /// The value given, with units.
    pub found: String,
}

fn out_of_range(
    what: impl Into<String>,
    expected: impl Into<String>,
    found: String,
) -> ConfigError {
    ConfigError {
        what: what.into(),
        expected: expected.into(),
        found,
    }
}

/// A number as a user would write it: `1e300`, not 301 digits.
fn number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e15).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Checks a position: finite, at most `limit_m` from the origin along each axis.
fn check_position(
    what: impl Into<String>,
    position_m: [f64; 3],
    limit_m: f64,
) -> Result<(), ConfigError> {
    if position_m
        .iter()
        .all(|v| v.is_finite() && v.abs() <= limit_m)
    {
        return Ok(());
    }
    let [x, y, z] = position_m;
    Err(out_of_range(
        what,
        format!("X,Y,Z each in -{limit_m} m ..= {limit_m} m"),
        format!("{},{},{} m", number(x), number(y), number(z)),
    ))
}

/// Checks a scripted time: finite, 0 ..= [`MAX_DURATION_S`], not before the previous one.
fn check_time(what: impl Into<String>, t_s: f64, previous_s: f64) -> Result<(), ConfigError> {
    if t_s.is_finite() && (0.0..=MAX_DURATION_S).contains(&t_s) && t_s >= previous_s {
        return Ok(());
    }
    Err(out_of_range(
        what,
        format!("a time in {previous_s} s ..= {MAX_DURATION_S} s (sorted)"),
        format!("{} s", number(t_s)),
    ))
}

impl JoystickChange {
    /// Checks the time (0 ..= a week) and each axis (-100 % ..= 100 %); `what` names it.
    pub fn check(&self, what: impl Into<String>) -> Result<(), ConfigError> {
        let what = what.into();
        check_time(what.clone(), self.t_s, 0.0)?;
        let j = self.joystick;
        for v in [j.vx, j.vy, j.vz, j.vyaw] {
            if !(v.is_finite() && v.abs() <= 100.0) {
                return Err(out_of_range(
                    what,
                    "vx,vy,vz,vyaw each in -100 % ..= 100 % of full thrust",
                    format!("{} %", number(v)),
                ));
            }
        }
        Ok(())
    }
}

impl Waypoint {
    /// Checks the time (0 ..= a week), the target (within a GoTo order's
    /// ±[`MAX_WAYPOINT_M`]) and the heading (finite); `what` names it.
    pub fn check(&self, what: impl Into<String>) -> Result<(), ConfigError> {
        let what = what.into();
        check_time(what.clone(), self.t_s, 0.0)?;
        check_position(what.clone(), self.position_m, MAX_WAYPOINT_M)?;
        if !self.heading_deg.is_finite() {
            return Err(out_of_range(
                what,
                "a finite heading in degrees",
                format!("{} degrees", self.heading_deg),
            ));
        }
        Ok(())
    }
}

impl SessionConfig {
    /// Checks every setting against its range; the first one out of range is the error. The
    /// model is checked when the link is built.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.duration_s.is_finite()
            && self.duration_s > 0.0
            && self.duration_s <= MAX_DURATION_S)
        {
            return Err(out_of_range(
                "duration",
                format!("more than 0 s, at most {MAX_DURATION_S} s (a week)"),
                format!("{} s", number(self.duration_s)),
            ));
        }
        check_position("buoy position", self.buoy_m, MAX_POSITION_M)?;
        check_position("start position", self.start_m, MAX_POSITION_M)?;
        if bound_ipg(self.ipg_s).clamped {
            return Err(out_of_range(
                "IPG",
                "1 ms ..= 10 min",
                format!("{} ms", number(self.ipg_s * 1e3)),
            ));
        }
        let mut previous_s = 0.0;
        for (k, change) in self.script.iter().enumerate() {
            let what = format!("joystick change {}", k + 1);
            check_time(what.clone(), change.t_s, previous_s)?;
            previous_s = change.t_s;
            change.check(what)?;
        }
        let mut previous_s = 0.0;
        for (k, waypoint) in self.waypoints.iter().enumerate() {
            let what = format!("waypoint {}", k + 1);
            check_time(what.clone(), waypoint.t_s, previous_s)?;
            previous_s = waypoint.t_s;
            waypoint.check(what)?;
        }
        let settings = &self.settings;
        let max_trunk = rovlink_wire::rov::MAX_TRUNK_BYTES;
        if settings.trunk_bytes == 0 || usize::from(settings.trunk_bytes) > max_trunk {
            return Err(out_of_range(
                "trunk size",
                format!("1 ..= {max_trunk} bytes (what a ROV frame carries)"),
                format!("{} bytes", settings.trunk_bytes),
            ));
        }
        if settings.size_bytes < MIN_IMAGE_BYTES {
            return Err(out_of_range(
                "image size",
                format!("{MIN_IMAGE_BYTES} ..= 65535 bytes"),
                format!("{} bytes", settings.size_bytes),
            ));
        }
        for (k, image) in self.images.iter().enumerate() {
            let side = debt::MAX_SIDE;
            if image.width == 0
                || image.height == 0
                || image.width > side
                || image.height > side
                || image.data.len() != image.width * image.height * image.channels
            {
                return Err(out_of_range(
                    format!("camera picture {}", k + 1),
                    format!("1x1 ..= {side}x{side} pixels (what DEBT holds)"),
                    format!("{}x{} pixels", image.width, image.height),
                ));
            }
        }
        Ok(())
    }
}

/// The IPG wire.md derives from a model for a session, the one-hop case of a network's slot
/// ([`rules::slot_s`] of one hop out and one back): the operator's frame, the ROV's frame with a
/// trunk of `settings.trunk_bytes`, at the distance between `start_m` and `buoy_m`, each frame
/// `overhead_bytes` longer when secured.
pub fn auto_ipg_for(
    model: &Model,
    settings: &ImageSettings,
    start_m: [f64; 3],
    buoy_m: [f64; 3],
    overhead_bytes: usize,
) -> f64 {
    let hop = rules::Hop {
        model,
        distance_m: rovlink_base::geometry::distance_m(start_m, buoy_m),
    };
    rules::slot_s(&[hop], &[hop], settings.trunk_bytes, overhead_bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ipg_is_held_to_its_bounds_and_says_when_it_was() {
        let held = |ipg_s: f64| {
            let b = bound_ipg(ipg_s);
            (b.ipg_s, b.clamped)
        };
        assert_eq!(held(0.64), (0.64, false));
        assert_eq!(held(MIN_IPG_S), (MIN_IPG_S, false));
        assert_eq!(held(MAX_IPG_S), (MAX_IPG_S, false));
        assert_eq!(held(1e-12), (MIN_IPG_S, true));
        assert_eq!(held(8400.0), (MAX_IPG_S, true));
        assert_eq!(held(f64::INFINITY), (MAX_IPG_S, true));
        let nan = bound_ipg(f64::NAN);
        assert!(nan.ipg_s.is_nan() && nan.clamped);
    }
}
