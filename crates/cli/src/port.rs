//! The port flags every tool that talks to a real modem shares (`rcp-dump`, `modem-bench`,
//! `tdma-run`, `link-sim`), flattened into each tool's arguments; the devices themselves are
//! named in the one grammar of [`rovlink_link::device`] (checked by [`crate::value::device`]).

use crate::value;
use rovlink_link::gll::{Dialect, Endpoint, PortError, PortOptions};

/// `--dialect`'s values: a [`Dialect`] as a flag (clap's traits live in this crate, the
/// dialects in `rovlink-link`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DialectFlag(pub Dialect);

impl DialectFlag {
    /// Transparent modems, the default.
    pub const TRANSPARENT: DialectFlag = DialectFlag(Dialect::Transparent);
}

impl clap::ValueEnum for DialectFlag {
    fn value_variants<'a>() -> &'a [Self] {
        const ALL: [DialectFlag; Dialect::ALL.len()] = {
            let mut all = [DialectFlag::TRANSPARENT; Dialect::ALL.len()];
            let mut i = 0;
            while i < all.len() {
                all[i] = DialectFlag(Dialect::ALL[i]);
                i += 1;
            }
            all
        };
        &ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.0.name()).help(self.0.help()))
    }
}

/// The modem flags, flattened into a tool's arguments.
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct PortArgs {
    /// How the modems are spoken to.
    #[arg(long, value_enum, default_value_t = DialectFlag::TRANSPARENT, help_heading = "Real modems")]
    pub dialect: DialectFlag,

    /// EvoLogics: send instant messages (AT*SENDIM, up to 64 bytes) instead of bursts.
    #[arg(long, help_heading = "Real modems")]
    pub instant: bool,

    /// EvoLogics: the destination address of the packets (0 ..= 254).
    #[arg(long, value_name = "ADDR", default_value_t = 2,
          value_parser = clap::value_parser!(u32).range(0..=254), help_heading = "Real modems")]
    pub address: u32,

    /// Baud rate of the serial ports (50 ..= 4000000).
    #[arg(long, default_value_t = 9600,
          value_parser = value::baud(), help_heading = "Real modems")]
    pub baud: u32,

    /// Transparent modems: write each packet in chunks of this many bytes, paced at
    /// --chunk-rate-bps (the S100 driver sends 45-byte chunks at the air rate, without flow
    /// control).
    #[arg(long, value_name = "BYTES", value_parser = value::bytes(1, 65_536), help_heading = "Real modems")]
    pub chunk_bytes: Option<u64>,

    /// The rate chunk pauses are computed from, bit/s.
    #[arg(long, value_name = "BPS", default_value_t = 1900.0,
          value_parser = value::real(1.0, 1e9, "bit/s"), help_heading = "Real modems")]
    pub chunk_rate_bps: f64,
}

impl Default for PortArgs {
    fn default() -> PortArgs {
        let o = PortOptions::default();
        PortArgs {
            dialect: DialectFlag(o.dialect),
            instant: o.instant,
            address: o.address,
            baud: o.baud,
            chunk_bytes: o.chunk_bytes,
            chunk_rate_bps: o.chunk_rate_bps,
        }
    }
}

impl PortArgs {
    /// The options the flags give.
    pub fn options(&self) -> PortOptions {
        PortOptions {
            dialect: self.dialect.0,
            instant: self.instant,
            address: self.address,
            baud: self.baud,
            chunk_bytes: self.chunk_bytes,
            chunk_rate_bps: self.chunk_rate_bps,
        }
    }

    /// True when any flag differs from its default (they only mean something with a device).
    pub fn any_set(&self) -> bool {
        self.options().any_set()
    }

    /// Opens `device` as these flags say.
    pub fn open(&self, device: &str) -> Result<Box<dyn Endpoint>, PortError> {
        self.options().open(device)
    }
}
