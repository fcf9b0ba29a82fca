//! The EvoLogics dialect, emulated: [`EvoLogicsEmulator`] answers the EvoLogics AT dialect ([`crate::gll::evologics`]): a host
//! writes `AT*SEND` (burst) or `AT*SENDIM` (instant message) commands; the data goes through the
//! link model; the other side's host receives `RECV` or `RECVIM` notifications; an instant
//! message sent with `ack` is answered `DELIVEREDIM` or `FAILEDIM` when its fate is known.
//! Side A is modem address 1, side B address 2. Other `AT` commands are answered `OK` (`AT?T`
//! with the last propagation time in microseconds); anything else `ERROR WRONG FORMAT`.

use std::collections::HashMap;

use super::{Emulator, Notifications};
use crate::channel::{Fate, Report, Side};
use crate::gll::evologics::{Command, CommandReader, Notification, format_notification};
use crate::model::Model;

/// How a packet was sent, to answer in kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// `AT*SEND`.
    Burst,
    /// `AT*SENDIM`, with or without an acknowledgement.
    Instant {
        /// The sender asked for `DELIVEREDIM` / `FAILEDIM`.
        ack: bool,
    },
}

/// The EvoLogics AT dialect on both sides of a link.
#[derive(Debug, Default)]
pub struct EvoLogicsEmulator {
    readers: [CommandReader; 2],
    sent: HashMap<(Side, u64), Kind>,
    last_propagation_us: u64,
}

/// The modem address of a side.
pub fn address(side: Side) -> u32 {
    side.index() as u32 + 1
}

impl EvoLogicsEmulator {
    /// A fresh emulator.
    pub fn new() -> EvoLogicsEmulator {
        EvoLogicsEmulator::default()
    }
}

impl Emulator for EvoLogicsEmulator {
    /// `AT*SEND` and `AT*SENDIM` put their data on the air (answered `OK`); `AT?T` is answered
    /// with the last propagation time in microseconds, other `AT` commands `OK`, anything else
    /// `ERROR WRONG FORMAT`.
    fn host_wrote(
        &mut self,
        side: Side,
        bytes: &[u8],
        offer: &mut dyn FnMut(Vec<u8>) -> u64,
    ) -> Vec<u8> {
        let reader = &mut self.readers[side.index()];
        reader.push(bytes);
        let mut replies = Vec::new();
        while let Some(command) = reader.next_command() {
            let reply = match command {
                Command::Send { data, .. } => {
                    self.sent.insert((side, offer(data)), Kind::Burst);
                    Notification::Ok
                }
                Command::SendIm { ack, data, .. } => {
                    self.sent.insert((side, offer(data)), Kind::Instant { ack });
                    Notification::Ok
                }
                Command::Other(line) if line == "AT?T" => {
                    Notification::Other(self.last_propagation_us.to_string())
                }
                Command::Other(line) if line.starts_with("AT") => Notification::Ok,
                Command::Other(_) => Notification::Error("WRONG FORMAT".into()),
            };
            replies.extend(format_notification(&reply));
        }
        replies
    }

    /// `RECV` (a burst) or `RECVIM` (an instant message) to the receiver when the data
    /// arrived (integrity 40 when corrupted); `DELIVEREDIM` or `FAILEDIM` to the sender of an
    /// instant message that asked for it.
    fn on_report(&mut self, report: &Report, model: &Model) -> Notifications {
        let key = (report.from, report.seq);
        let kind = if report.duplicate {
            self.sent.get(&key).copied()
        } else {
            self.sent.remove(&key)
        }
        .unwrap_or(Kind::Burst);
        let (src, dst) = (address(report.from), address(report.from.other()));
        let mut to_receiver = Vec::new();
        let mut to_sender = Vec::new();
        let air_us = (model.air_time_s(report.len) * 1e6) as u64;
        if let (Some(t_rx), Some(t_tx)) = (report.t_rx, report.t_tx_start) {
            let on_air_us = (t_rx.0.saturating_sub(t_tx.0)) / 1000;
            self.last_propagation_us = on_air_us.saturating_sub(air_us);
        }
        if report.fate.arrived() {
            let integrity = if report.fate == Fate::Corrupted {
                40
            } else {
                100
            };
            let data = report.bytes.clone();
            let notification = match kind {
                Kind::Burst => Notification::Recv {
                    src,
                    dst,
                    bitrate: model.effective_rate_bps().round() as u32,
                    rssi: -50,
                    integrity,
                    ptime_us: self.last_propagation_us,
                    velocity: 0.0,
                    data,
                },
                Kind::Instant { ack } => Notification::RecvIm {
                    src,
                    dst,
                    ack,
                    duration_us: air_us,
                    rssi: -50,
                    integrity,
                    velocity: 0.0,
                    data,
                },
            };
            to_receiver = format_notification(&notification);
        }
        if let (Kind::Instant { ack: true }, false) = (kind, report.duplicate) {
            let note = if report.fate == Fate::Delivered {
                Notification::DeliveredIm(dst)
            } else {
                Notification::FailedIm(dst)
            };
            to_sender = format_notification(&note);
        }
        Notifications {
            to_receiver,
            to_sender,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gll::evologics::{NotificationReader, format_command};
    use crate::{Distance, Link};

    #[test]
    fn a_burst_and_an_acknowledged_instant_message_cross_the_link() {
        let mut model = Model::preset("s2cr-burst").unwrap();
        model.jitter_ms = 0.0;
        let mut link = Link::symmetric(model.clone(), 1, Distance::Fixed(1500.0)).unwrap();
        let mut emulator = EvoLogicsEmulator::new();
        let mut stream = format_command(&Command::Send {
            dst: 2,
            data: b"burst\r\n".to_vec(),
        });
        stream.extend(format_command(&Command::SendIm {
            dst: 2,
            ack: true,
            data: b"im".to_vec(),
        }));
        stream.extend(b"AT?T\r\nhello\r\n");
        let replies = emulator.host_wrote(Side::A, &stream, &mut |data| link.offer(Side::A, data));
        assert_eq!(replies, b"OK\r\nOK\r\n0\r\nERROR WRONG FORMAT\r\n");
        while link.step() {}
        let mut at_b = NotificationReader::new();
        let mut at_a = NotificationReader::new();
        while let Some(report) = link.pop_report() {
            let notes = emulator.on_report(&report, &model);
            at_b.push(&notes.to_receiver);
            at_a.push(&notes.to_sender);
        }
        match at_b.next_notification() {
            Some(Notification::Recv {
                src: 1,
                dst: 2,
                ptime_us,
                data,
                ..
            }) => {
                assert_eq!(data, b"burst\r\n");
                assert_eq!(ptime_us, 1_005_000); // 0.67 ms/m x 1500 m
            }
            other => panic!("{other:?}"),
        }
        assert!(
            matches!(at_b.next_notification(), Some(Notification::RecvIm { ack: true, ref data, .. }) if data == b"im")
        );
        assert_eq!(at_a.next_notification(), Some(Notification::DeliveredIm(2)));
        assert_eq!(at_a.next_notification(), None);
    }
}
