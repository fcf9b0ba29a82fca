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

    /// Starts the program `exe` with `args`; its standard error is watched.
    pub fn spawn_exe(exe: &str, args: &[&str]) -> Watched {
        Watched::start(exe, args, false)
    }

    /// Starts the program `exe` with `args`; its standard output and error are watched.
    pub fn spawn_exe_both(exe: &str, args: &[&str]) -> Watched {
        Watched::start(exe, args, true)
    }

    fn start(exe: &str, args: &[&str], stdout: bool) -> Watched {
        let mut child = Command::new(exe)
            .args(args)
            .stdout(if stdout {
                Stdio::piped()
            } else {
                Stdio::null()
            })
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, lines) = mpsc::channel();
        let follow = |tx: mpsc::Sender<String>, r: Box<dyn std::io::Read + Send>| {
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(r).lines().map_while(Result::ok) {
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            });
        };
        if let Some(out) = child.stdout.take() {
            follow(tx.clone(), Box::new(out));
        }
        follow(tx, Box::new(child.stderr.take().unwrap()));
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
