//! A tool run in the background whose standard error is read line by line aside, so a test
//! waits for a sign (a line it says), never for a time.

use std::io::BufRead;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use super::Reaped;

const OCTO: &str = env!("TOOL_EXE_octo-delta");
/// The longest any sign is waited for.
pub const DEADLINE: Duration = Duration::from_secs(240);

/// A running tool whose standard error is read line by line aside.
pub struct Watched {
    child: Reaped,
    lines: mpsc::Receiver<String>,
    said: Vec<String>,
}

impl Watched {
    /// Starts octo-delta with `args`.
    pub fn spawn(args: &[&str]) -> Watched {
        Watched::spawn_exe(OCTO, args)
    }

    /// Starts the program `exe` with `args`.
    pub fn spawn_exe(exe: &str, args: &[&str]) -> Watched {
        let mut child = Command::new(exe)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let err = child.stderr.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Watched {
            child: Reaped(child),
            lines,
            said: Vec::new(),
        }
    }

    /// Waits until `n` lines said so far contain `sign`.
    pub fn wait_count(&mut self, sign: &str, n: usize) {
        while self.said.iter().filter(|l| l.contains(sign)).count() < n {
            match self.lines.recv_timeout(DEADLINE) {
                Ok(line) => self.said.push(line),
                Err(_) => panic!("not {n} of {sign:?} in {DEADLINE:?}: {:#?}", self.said),
            }
        }
    }

    /// Waits for a line containing `sign`.
    pub fn wait_for(&mut self, sign: &str) {
        loop {
            match self.lines.recv_timeout(DEADLINE) {
                Ok(line) => {
                    let hit = line.contains(sign);
                    self.said.push(line);
                    if hit {
                        return;
                    }
                }
                Err(_) => panic!("no {sign:?} in {DEADLINE:?}: {:#?}", self.said),
            }
        }
    }

    /// Waits for the process to end; its exit code and everything it said.
    pub fn finish(mut self) -> (Option<i32>, String) {
        let status = self.child.wait().unwrap();
        self.said.extend(self.lines.iter());
        (status.code(), self.said.join("\n"))
    }

    pub fn signal(&self, sig: nix::sys::signal::Signal) {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        nix::sys::signal::kill(pid, sig).unwrap();
    }
}
