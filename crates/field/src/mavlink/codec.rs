//! The MAVLink side of the drive that is not state: ArduSub's custom modes and the status
//! block's NAV both ways, MANUAL_CONTROL's stick axes, and what the messages heard from the
//! autopilot say ([`keep`] turns each into the [`Inbox`] the drive reads).

use std::collections::VecDeque;

use mavlink::MavHeader;
use mavlink::dialects::ardupilotmega::{
    HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavSeverity,
    MavState, MavType,
};

use super::MAX_QUEUED;
use rovlink_wire::Nav;

/// ArduSub's custom modes that the status block's NAV has a value for, and back.
const MODE_TABLE: [(u32, Nav); 5] = [
    (19, Nav::Manual),
    (0, Nav::Stabilize),
    (2, Nav::DepthHold),
    (16, Nav::HoldPosition),
    (4, Nav::Guided),
];

/// The NAV reported while ArduSub is in a mode outside [`MODE_TABLE`] (ACRO, AUTO, CIRCLE,
/// SURFACE, ...): 5, the first value wire.md leaves reserved, so the operator sees "none of
/// ours" rather than a mode the vehicle is not in.
pub const OTHER_MODE_NAV: Nav = Nav::Unknown(5);

/// The NAV for an ArduSub custom mode (MANUAL 19, STABILIZE 0, ALT_HOLD 2, POSHOLD 16,
/// GUIDED 4); `None` for the others.
pub fn nav_of_custom_mode(custom_mode: u32) -> Option<Nav> {
    MODE_TABLE
        .iter()
        .find(|(mode, _)| *mode == custom_mode)
        .map(|(_, nav)| *nav)
}

/// The ArduSub custom mode a NAV reads back from ([`nav_of_custom_mode`]'s inverse; what is
/// asked for is [`demanded_mode`]); `None` for a reserved NAV value.
pub fn custom_mode_of(nav: Nav) -> Option<u32> {
    MODE_TABLE
        .iter()
        .find(|(_, n)| *n == nav)
        .map(|(mode, _)| *mode)
}

/// The ArduSub custom mode the ROV end asks for when the operator asks for `nav`: every stick
/// mode holds depth, since a BlueROV2 is positively buoyant and in MANUAL or STABILIZE with
/// neutral sticks floats up to the surface; HoldPosition is POSHOLD where the vehicle has a
/// position estimate (`position_known`), ALT_HOLD where it has none; Guided is GUIDED. `None`
/// for a reserved NAV value.
///
/// | NAV | ArduSub mode | what ArduSub holds with neutral sticks |
/// | --- | --- | --- |
/// | manual, stabilize, depth_hold | ALT_HOLD (2) | attitude and depth |
/// | hold_position | POSHOLD (16); ALT_HOLD (2) without a position | attitude, depth, position |
/// | guided | GUIDED (4) | the last setpoint (needs a position) |
pub fn demanded_mode(nav: Nav, position_known: bool) -> Option<u32> {
    match nav {
        Nav::Manual | Nav::Stabilize | Nav::DepthHold => Some(ALT_HOLD),
        Nav::HoldPosition if position_known => Some(POSHOLD),
        Nav::HoldPosition => Some(ALT_HOLD),
        Nav::Guided => Some(GUIDED),
        Nav::Unknown(_) => None,
    }
}

/// ArduSub's ALT_HOLD: attitude and depth held.
pub const ALT_HOLD: u32 = 2;
/// ArduSub's POSHOLD: attitude, depth and position held (needs a position estimate).
pub const POSHOLD: u32 = 16;
/// ArduSub's GUIDED: goes to and holds the last setpoint (needs a position estimate).
pub const GUIDED: u32 = 4;

/// ArduSub's name for a custom mode (`mode 12` for a number it does not define).
pub fn ardusub_mode_name(custom_mode: u32) -> String {
    let name = match custom_mode {
        0 => "STABILIZE",
        1 => "ACRO",
        2 => "ALT_HOLD",
        3 => "AUTO",
        4 => "GUIDED",
        7 => "CIRCLE",
        9 => "SURFACE",
        16 => "POSHOLD",
        19 => "MANUAL",
        20 => "MOTOR_DETECT",
        21 => "SURFTRAK",
        other => return format!("mode {other}"),
    };
    name.to_string()
}

/// MANUAL_CONTROL's x, y, z, r for thrust in percent (surge, sway, heave down, yaw clockwise,
/// each -100..=100), as ArduSub's `transform_manual_control_to_rc_override` reads them: x
/// forward, y starboard and r clockwise in -1000..=1000; z is its throttle, 0..=1000 with 500
/// neutral, where a larger z raises the vehicle, so heave down `h` gives `500 - 5 h`.
/// Out-of-range or non-finite input is clamped (not-a-number gives neutral).
pub fn manual_control_axes(thrust_percent: [f64; 4]) -> [i16; 4] {
    let axis = |value: f64, scale: f64, centre: f64, low: f64, high: f64| -> i16 {
        let raw = centre + value * scale;
        if raw.is_nan() {
            centre as i16
        } else {
            raw.round().clamp(low, high) as i16
        }
    };
    let [surge, sway, heave, yaw] = thrust_percent;
    [
        axis(surge, 10.0, 0.0, -1000.0, 1000.0),
        axis(sway, 10.0, 0.0, -1000.0, 1000.0),
        axis(heave, -5.0, 500.0, 0.0, 1000.0),
        axis(yaw, 10.0, 0.0, -1000.0, 1000.0),
    ]
}

/// MANUAL_CONTROL with the sticks centred.
pub const NEUTRAL_AXES: [i16; 4] = [0, 0, 500, 0];

/// Our HEARTBEAT: a ground station (MAV_TYPE_GCS, no autopilot), active.
pub(super) fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// The autopilot the link settled on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Autopilot {
    pub(super) system: u8,
    pub(super) component: u8,
    pub(super) submarine: bool,
}

/// What the receiving thread learnt, handed to `step`.
#[derive(Debug, Default)]
pub(super) struct Inbox {
    pub(super) autopilot: Option<Autopilot>,
    /// Messages heard from the autopilot.
    pub(super) heard: u64,
    /// Armed and custom mode from its last HEARTBEAT.
    pub(super) heartbeat: Option<(bool, u32)>,
    /// LOCAL_POSITION_NED: x, y, z (m), vx, vy, vz (m/s); and how many.
    pub(super) position: Option<[f64; 6]>,
    pub(super) positions: u64,
    /// ATTITUDE: roll, pitch, yaw (rad), yaw speed (rad/s); and how many.
    pub(super) attitude: Option<[f64; 4]>,
    pub(super) attitudes: u64,
    /// Whether the one warning for a dropped position / attitude was given.
    pub(super) position_warned: bool,
    pub(super) attitude_warned: bool,
    pub(super) acks: VecDeque<(MavCmd, MavResult)>,
    pub(super) notes: VecDeque<String>,
    /// Frames refused, by [`super::Refusal`] (its order).
    pub(super) refused: [u64; 5],
}

/// The fields of LOCAL_POSITION_NED kept, with the largest magnitude each may have: x, y, z
/// within the toolkit's 100 km site ([`rovlink_rcp::config::MAX_POSITION_M`]); vx, vy, vz within
/// 100 m/s (no underwater vehicle comes near it).
const POSITION_BOUNDS: [(&str, f64); 6] = [
    ("x", rovlink_rcp::config::MAX_POSITION_M),
    ("y", rovlink_rcp::config::MAX_POSITION_M),
    ("z", rovlink_rcp::config::MAX_POSITION_M),
    ("vx", 100.0),
    ("vy", 100.0),
    ("vz", 100.0),
];

/// The fields of ATTITUDE kept, with the largest magnitude each may have: angles within 2π
/// rad, the yaw rate within 100 rad/s.
const ATTITUDE_BOUNDS: [(&str, f64); 4] = [
    ("roll", std::f64::consts::TAU),
    ("pitch", std::f64::consts::TAU),
    ("yaw", std::f64::consts::TAU),
    ("yawspeed", 100.0),
];

/// True if every value is finite and within its bound: an autopilot's pose that is not (NaN,
/// ±1e38) is dropped rather than becoming the vehicle's.
pub(super) fn plausible(values: &[f64], bounds: &[(&str, f64)]) -> bool {
    values
        .iter()
        .zip(bounds)
        .all(|(v, (_, bound))| v.is_finite() && v.abs() <= *bound)
}

/// The one warning for a dropped message: its first implausible field, the bound and the value.
pub(super) fn dropped_note(message: &str, values: &[f64], bounds: &[(&str, f64)]) -> String {
    let bad = values
        .iter()
        .zip(bounds)
        .find(|(v, (_, bound))| !(v.is_finite() && v.abs() <= *bound));
    let what = bad.map_or_else(String::new, |(v, (field, bound))| {
        format!(": field {field}: expected within ±{bound}, found {v}")
    });
    format!("warning: autopilot's {message} dropped{what} (later ones dropped without a word)")
}

pub(super) fn push_bounded<T>(queue: &mut VecDeque<T>, item: T) {
    if queue.len() >= MAX_QUEUED {
        queue.pop_front();
    }
    queue.push_back(item);
}

/// Keeps one message in the inbox if it comes from the autopilot.
pub(super) fn keep(inbox: &mut Inbox, header: &MavHeader, message: MavMessage, our_system: u8) {
    let (Ok(system), component) = (u8::try_from(header.system_id), header.component_id) else {
        return;
    };
    if system == our_system {
        return; // Another ground station speaking as us, or our own echo.
    }
    if let MavMessage::HEARTBEAT(heartbeat) = &message {
        let autopilot = heartbeat.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
            && heartbeat.mavtype != MavType::MAV_TYPE_GCS;
        let submarine = heartbeat.mavtype == MavType::MAV_TYPE_SUBMARINE;
        let better = match inbox.autopilot {
            None => autopilot,
            Some(known) => autopilot && submarine && !known.submarine,
        };
        if better {
            inbox.autopilot = Some(Autopilot {
                system,
                component,
                submarine,
            });
            let text = format!(
                "mavlink: autopilot found: system {system} component {component}, {:?}, {:?}{}",
                heartbeat.mavtype,
                heartbeat.autopilot,
                if submarine {
                    ""
                } else {
                    " (not a submarine: its modes are read as ArduSub's)"
                }
            );
            push_bounded(&mut inbox.notes, text);
        }
    }
    let from_autopilot = inbox
        .autopilot
        .is_some_and(|a| a.system == system && a.component == component);
    if !from_autopilot {
        return;
    }
    inbox.heard += 1;
    match message {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            base_mode,
            custom_mode,
            ..
        }) => {
            let armed = base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
            inbox.heartbeat = Some((armed, custom_mode));
        }
        MavMessage::LOCAL_POSITION_NED(p) => {
            let values = [p.x, p.y, p.z, p.vx, p.vy, p.vz].map(f64::from);
            let kept = (&mut inbox.position, &mut inbox.positions);
            let (warned, notes) = (&mut inbox.position_warned, &mut inbox.notes);
            keep_values(
                values,
                &POSITION_BOUNDS,
                "LOCAL_POSITION_NED",
                kept,
                warned,
                notes,
            );
        }
        MavMessage::ATTITUDE(a) => {
            let values = [a.roll, a.pitch, a.yaw, a.yawspeed].map(f64::from);
            let kept = (&mut inbox.attitude, &mut inbox.attitudes);
            let (warned, notes) = (&mut inbox.attitude_warned, &mut inbox.notes);
            keep_values(values, &ATTITUDE_BOUNDS, "ATTITUDE", kept, warned, notes);
        }
        MavMessage::COMMAND_ACK(ack) => push_bounded(&mut inbox.acks, (ack.command, ack.result)),
        MavMessage::STATUSTEXT(status) => {
            let warning = matches!(
                status.severity,
                MavSeverity::MAV_SEVERITY_EMERGENCY
                    | MavSeverity::MAV_SEVERITY_ALERT
                    | MavSeverity::MAV_SEVERITY_CRITICAL
                    | MavSeverity::MAV_SEVERITY_ERROR
                    | MavSeverity::MAV_SEVERITY_WARNING
            );
            if warning {
                let bytes: Vec<u8> = status
                    .text
                    .iter()
                    .copied()
                    .take_while(|&b| b != 0)
                    .collect();
                let text = format!("autopilot: {}", String::from_utf8_lossy(&bytes).trim());
                push_bounded(&mut inbox.notes, text);
            }
        }
        _ => {}
    }
}

/// Keeps a message's `values` (and counts them) when they are plausible; otherwise the one
/// warning for `name`, the first time (`warned`).
fn keep_values<const N: usize>(
    values: [f64; N],
    bounds: &[(&str, f64); N],
    name: &str,
    (last, count): (&mut Option<[f64; N]>, &mut u64),
    warned: &mut bool,
    notes: &mut VecDeque<String>,
) {
    if plausible(&values, bounds) {
        *last = Some(values);
        *count += 1;
    } else if !*warned {
        *warned = true;
        push_bounded(notes, dropped_note(name, &values, bounds));
    }
}
