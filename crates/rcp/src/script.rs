//! What the operator plays in a session: joystick changes and GoTo orders, from CSV files or
//! the built-in 10-minute session.
//!
//! `--script` files have the columns `t_s,vx,vy,vz,vyaw` (joystick, percent of full thrust,
//! from `t_s` on), `--waypoints` files `t_s,x_m,y_m,z_m,heading_deg` (a GoTo order queued at
//! `t_s`; NED metres). Every row is checked ([`JoystickChange::check`], [`Waypoint::check`]) and
//! an error names the file and line; rows are returned sorted by time. `-` reads standard
//! input (for one of the two). A file that another user owns or that group or others may
//! write is refused before it is read, as the orders are
//! ([`rovlink_base::secret::open_command_source`]).

use std::path::{Path, PathBuf};

use rovlink_base::secret::SecretFileError;

use crate::config::{JoystickChange, Waypoint};
use crate::operator::Joystick;

/// The largest script or waypoint file read, bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 26;

/// What is wrong with a script or waypoint file.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// The file is owned by another user or writable by group or others: whoever can write
    /// to it could command the vehicle.
    #[error("{0}")]
    Refused(SecretFileError),
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error("{path}: more than {MAX_FILE_BYTES} bytes: not a script or waypoint file")]
    TooBig {
        /// The file.
        path: PathBuf,
    },
    /// A row is wrong: the file, then the line and what.
    #[error("{path}: {problem}")]
    Row {
        /// The file.
        path: PathBuf,
        /// `line N: ...`.
        problem: String,
    },
}

/// The rows of a CSV file with `columns`, with their line numbers.
fn table(path: &Path, columns: &[&str]) -> Result<Vec<(u64, Vec<f64>)>, ScriptError> {
    let read_error = |source| ScriptError::Read {
        path: path.to_path_buf(),
        source,
    };
    let read = match path.as_os_str() == "-" {
        true => read_stdin_at_most(MAX_FILE_BYTES),
        false => {
            let (file, _) =
                rovlink_base::secret::open_command_source(path, false).map_err(|e| match e {
                    SecretFileError::Read { source, .. } => read_error(source),
                    refused => ScriptError::Refused(refused),
                })?;
            rovlink_base::io::read_bounded(file, MAX_FILE_BYTES)
        }
    };
    let Some(text) = read.map_err(read_error)? else {
        return Err(ScriptError::TooBig {
            path: path.to_path_buf(),
        });
    };
    rovlink_base::io::read_number_table(&text, columns, f64::NEG_INFINITY).map_err(|e| {
        ScriptError::Row {
            path: path.to_path_buf(),
            problem: e.to_string(),
        }
    })
}

/// Standard input's bytes (`-` as a file name): `None` when it holds more than `max_bytes`.
fn read_stdin_at_most(max_bytes: u64) -> std::io::Result<Option<Vec<u8>>> {
    rovlink_base::io::read_bounded(std::io::stdin().lock(), max_bytes)
}

fn row_error(path: &Path, error: impl std::fmt::Display) -> ScriptError {
    ScriptError::Row {
        path: path.to_path_buf(),
        problem: error.to_string(),
    }
}

/// Reads a `--script` file: joystick changes, sorted by time.
pub fn read_script(path: &Path) -> Result<Vec<JoystickChange>, ScriptError> {
    let mut changes = Vec::new();
    for (line, r) in table(path, &["t_s", "vx", "vy", "vz", "vyaw"])? {
        let change = JoystickChange {
            t_s: r[0],
            joystick: Joystick {
                vx: r[1],
                vy: r[2],
                vz: r[3],
                vyaw: r[4],
            },
        };
        change
            .check(format!("line {line}"))
            .map_err(|e| row_error(path, e))?;
        changes.push(change);
    }
    changes.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(changes)
}

/// Reads a `--waypoints` file: GoTo orders, sorted by time.
pub fn read_waypoints(path: &Path) -> Result<Vec<Waypoint>, ScriptError> {
    let mut waypoints = Vec::new();
    for (line, r) in table(path, &["t_s", "x_m", "y_m", "z_m", "heading_deg"])? {
        let waypoint = Waypoint {
            t_s: r[0],
            position_m: [r[1], r[2], r[3]],
            heading_deg: r[4],
        };
        waypoint
            .check(format!("line {line}"))
            .map_err(|e| row_error(path, e))?;
        waypoints.push(waypoint);
    }
    waypoints.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(waypoints)
}

/// The built-in 10-minute session: some joystick driving, then three GoTo orders, all within
/// the S100's 5 m of the buoy.
pub fn builtin() -> (Vec<JoystickChange>, Vec<Waypoint>) {
    let js = |t_s, vx, vy, vz, vyaw| JoystickChange {
        t_s,
        joystick: Joystick { vx, vy, vz, vyaw },
    };
    let script = vec![
        js(5.0, 20.0, 0.0, 10.0, 0.0),
        js(15.0, 0.0, 0.0, 0.0, 0.0),
        js(30.0, 0.0, 0.0, 0.0, 30.0),
        js(36.0, 0.0, 0.0, 0.0, 0.0),
        js(60.0, -15.0, 10.0, 0.0, 0.0),
        js(75.0, 0.0, 0.0, 0.0, 0.0),
    ];
    let wp = |t_s, x, y, z, heading_deg| Waypoint {
        t_s,
        position_m: [x, y, z],
        heading_deg,
    };
    let waypoints = vec![
        wp(120.0, 3.0, 1.0, 0.5, 90.0),
        wp(300.0, 1.5, -1.0, 0.5, 180.0),
        wp(450.0, 1.0, 0.0, 0.0, 0.0),
    ];
    (script, waypoints)
}

/// The session's script and waypoints: the built-in ones unless a file is given; a file for
/// only one of them leaves the other empty.
pub fn load(
    script: Option<&Path>,
    waypoints: Option<&Path>,
) -> Result<(Vec<JoystickChange>, Vec<Waypoint>), ScriptError> {
    if script.is_none() && waypoints.is_none() {
        return Ok(builtin());
    }
    if let (Some(a), Some(b)) = (script, waypoints)
        && a.as_os_str() == "-"
        && b.as_os_str() == "-"
    {
        return Err(ScriptError::Row {
            path: a.to_path_buf(),
            problem: "--script and --waypoints cannot both read standard input".into(),
        });
    }
    Ok((
        script.map(read_script).transpose()?.unwrap_or_default(),
        waypoints
            .map(read_waypoints)
            .transpose()?
            .unwrap_or_default(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_out_of_range_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wp.csv");
        std::fs::write(
            &path,
            "t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n9,1e300,0,0,0\n",
        )
        .unwrap();
        let error = read_waypoints(&path).unwrap_err().to_string();
        assert!(
            error.ends_with(
                "wp.csv: line 3: expected X,Y,Z each in -327.67 m ..= 327.67 m, found 1e300,0,0 m"
            ),
            "{error}"
        );
        std::fs::write(&path, "t_s,vx,vy,vz,vyaw\n-1,0,0,0,0\n").unwrap();
        let error = read_script(&path).unwrap_err().to_string();
        assert!(error.contains("wp.csv: line 2: expected a time"), "{error}");
        std::fs::write(&path, "t_s,vx,vy,vz,vyaw\n3,0,0,0,0\n1,150,0,0,0\n").unwrap();
        let error = read_script(&path).unwrap_err().to_string();
        assert!(
            error.contains("line 3: expected vx,vy,vz,vyaw each in -100 % ..= 100 %"),
            "{error}"
        );
        std::fs::write(&path, "t_s,vx,vy,vz,vyaw\n3,0,0,0,0\n1,50,0,0,0\n").unwrap();
        let script = read_script(&path).unwrap();
        assert_eq!(script.iter().map(|c| c.t_s).collect::<Vec<_>>(), [1.0, 3.0]);
        // Whoever may write it could command the vehicle: refused before it is read.
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o664)).unwrap();
        let error = read_script(&path).unwrap_err().to_string();
        assert!(error.contains("permissions 0664 are too open"), "{error}");
        let error = read_waypoints(&path).unwrap_err().to_string();
        assert!(error.contains("permissions 0664 are too open"), "{error}");
    }
}
