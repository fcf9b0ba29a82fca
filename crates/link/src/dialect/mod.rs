//! Modem dialects `link-sim` can speak on its ports, so that programs written for a real modem's
//! command set run unchanged against a simulated link.
//!
//! A dialect is an [`Emulator`]: it reads what a side's host writes (commands carrying data),
//! answers that host as the modem would, hands the data to the link, and turns the link's
//! reports into what the modems would say (received-data notifications to the receiving host,
//! delivery reports to the sending one). [`emulator`] is the registry: the emulator of each
//! [`Dialect`] that has one. The one implementation now: [`evologics::EvoLogicsEmulator`].

pub mod evologics;

pub use evologics::EvoLogicsEmulator;

use super::channel::{Report, Side};
use super::model::Model;
use crate::gll::Dialect;

/// What an emulated modem says when the link decides a packet's fate.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Notifications {
    /// Bytes for the receiving side's host (a received-data notification), maybe none.
    pub to_receiver: Vec<u8>,
    /// Bytes for the sending side's host (a delivery report), maybe none.
    pub to_sender: Vec<u8>,
}

/// What a modem dialect must do to be emulated on a link's two sides.
///
/// Adding a dialect touches three source files: its own (`src/link/dialect/NAME.rs`, the
/// implementation of this trait), this module (`src/link/dialect/mod.rs`: its `mod` line and
/// its arm in [`emulator`]), and the enum where dialects are named ([`Dialect`] in
/// `src/gll/device.rs`: the variant, its name and its help; `--dialect`'s value list is made
/// from it; what the tools ask of a dialect, its broadcast address and whether it is emulated
/// between two sides only; and its arm in `PortOptions::open` says how the real-modem tools
/// speak it, or that they do not).
pub trait Emulator {
    /// Bytes `side`'s host wrote: every packet its commands carry goes on the air through
    /// `offer`, which returns the link's sequence number for it (reports carry it back); the
    /// result is the modem's replies to that host.
    fn host_wrote(
        &mut self,
        side: Side,
        bytes: &[u8],
        offer: &mut dyn FnMut(Vec<u8>) -> u64,
    ) -> Vec<u8>;

    /// A fate the link decided, with the sending direction's model: what each host hears.
    fn on_report(&mut self, report: &Report, model: &Model) -> Notifications;
}

/// A fresh emulator of `dialect`; none for bare packets ([`Dialect::Transparent`]).
pub fn emulator(dialect: Dialect) -> Option<Box<dyn Emulator>> {
    match dialect {
        Dialect::Transparent => None,
        Dialect::Evologics => Some(Box::new(EvoLogicsEmulator::new())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_dialect_but_bare_packets_has_an_emulator() {
        for dialect in Dialect::ALL {
            let has = emulator(dialect).is_some();
            assert_eq!(has, dialect != Dialect::Transparent, "{}", dialect.name());
            // An emulator works on a link's two sides (`Side`): a shared medium has none.
            assert_eq!(has, dialect.two_sides_only(), "{}", dialect.name());
        }
    }
}
