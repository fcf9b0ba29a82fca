//! Frame keys and the key file that holds them.
//!
//! A key file is text, one key per line, `ADDRESS KEY`:
//!
//! ```text
//! # rovlink frame keys
//! 1 2b7e151628aed2a6abf7158809cf4f3c
//! 2 603deb1015ca71be2b73aef0857d77811f352c073b6108d72d9810a30914dff4
//! broadcast 000102030405060708090a0b0c0d0e0f
//! ```
//!
//! ADDRESS is a vehicle (1..=14), `*` (every vehicle without a line of its own) or
//! `broadcast` (frames to address 15); KEY is 32 hex digits (AES-128) or 64 (AES-256). A line
//! holding a key alone is `* KEY`. `#` starts a comment. The operator holds every vehicle's
//! key; a vehicle holds its own (and the broadcast key, if the network uses broadcast).
//!
//! The file is read through [`rovlink_base::secret::read_secret_file`]: refused unless it is
//! a regular file owned by the user and private to them (0600 or 0400), as ssh refuses a
//! private key. A key never appears in `Debug` output, errors, logs or metrics: errors name
//! the line and the field, never the digits.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use rovlink_base::secret::{SecretFileError, create_secret_file, read_secret_file};
use rovlink_wire::frame::{ADDR_BROADCAST, ADDR_OPERATOR};

/// The largest key file read, bytes (16 vehicles' lines are about 1.5 KiB).
pub const MAX_KEY_FILE_BYTES: u64 = 64 * 1024;

/// A frame key: 16 bytes (AES-128) or 32 (AES-256).
#[derive(Clone, PartialEq, Eq)]
pub enum Key {
    /// A 128-bit key.
    Aes128([u8; 16]),
    /// A 256-bit key.
    Aes256([u8; 32]),
}

impl fmt::Debug for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Key({} bits, hidden)", self.bits())
    }
}

impl Key {
    /// The key from its bytes: 16 or 32 of them.
    pub fn from_bytes(bytes: &[u8]) -> Option<Key> {
        match bytes.len() {
            16 => bytes.try_into().ok().map(Key::Aes128),
            32 => bytes.try_into().ok().map(Key::Aes256),
            _ => None,
        }
    }

    /// Its bytes.
    pub fn bytes(&self) -> &[u8] {
        match self {
            Key::Aes128(k) => k,
            Key::Aes256(k) => k,
        }
    }

    /// Its length in bits.
    pub fn bits(&self) -> usize {
        self.bytes().len() * 8
    }

    /// A new key of `bits` (128 or 256) from the operating system's random source.
    pub fn generate(bits: usize) -> Result<Key, KeyError> {
        if bits != 128 && bits != 256 {
            return Err(KeyError::Bits(bits));
        }
        let bytes = rovlink_base::secret::random_bytes(bits / 8)
            .map_err(|e| KeyError::Random(e.to_string()))?;
        Key::from_bytes(&bytes).ok_or(KeyError::Bits(bits))
    }

    /// Lowercase hex, for writing a key file.
    fn hex(&self) -> String {
        rovlink_base::hex::encode(self.bytes())
    }
}

/// What is wrong with a key file or a key.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The file was refused or could not be read.
    #[error(transparent)]
    File(#[from] SecretFileError),
    /// A line is not `ADDRESS KEY`.
    #[error("{path}: line {line}: {problem}")]
    Line {
        /// The file.
        path: PathBuf,
        /// The line, from 1.
        line: usize,
        /// What is wrong (never the key's digits).
        problem: String,
    },
    /// The file holds no key.
    #[error("{path}: no key in the file (expected lines `ADDRESS KEY`)")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A key size other than 128 or 256 bits was asked for.
    #[error("key size {0} bits: expected 128 or 256")]
    Bits(usize),
    /// The random source failed.
    #[error("cannot draw a random key: {0}")]
    Random(String),
}

/// Every key a node holds, by the address it is for.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct KeyRing {
    vehicles: BTreeMap<u8, Key>,
    every_vehicle: Option<Key>,
    broadcast: Option<Key>,
}

impl fmt::Debug for KeyRing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("KeyRing")
            .field("vehicles", &self.vehicles.keys().collect::<Vec<_>>())
            .field("every_vehicle", &self.every_vehicle.is_some())
            .field("broadcast", &self.broadcast.is_some())
            .finish()
    }
}

/// Parses one hex key of 32 or 64 digits.
fn parse_hex_key(text: &str) -> Result<Key, String> {
    if text.len() != 32 && text.len() != 64 {
        return Err(format!(
            "key: expected 32 hex digits (128 bits) or 64 (256 bits), found {} characters",
            text.len()
        ));
    }
    let bytes = rovlink_base::hex::decode(text.as_bytes()).map_err(|e| match e {
        rovlink_base::hex::HexError::NotHex(at) => {
            format!("key: character {} is not a hex digit", at + 1)
        }
        odd => format!("key: {odd}"),
    })?;
    Key::from_bytes(&bytes).ok_or_else(|| "key: bad length".to_string())
}

impl KeyRing {
    /// A ring holding one key for every vehicle (a one-vehicle session, a test).
    pub fn single(key: Key) -> KeyRing {
        KeyRing {
            every_vehicle: Some(key),
            ..KeyRing::default()
        }
    }

    /// Adds the broadcast key.
    pub fn with_broadcast(mut self, key: Key) -> KeyRing {
        self.broadcast = Some(key);
        self
    }

    /// Reads and checks a key file (see the module doc).
    pub fn load(path: &Path) -> Result<KeyRing, KeyError> {
        let bytes = read_secret_file(path, MAX_KEY_FILE_BYTES)?;
        let line_err = |line, problem: String| KeyError::Line {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| line_err(1, format!("not UTF-8 text (byte {})", e.valid_up_to())))?;
        let ring = KeyRing::parse(text).map_err(|(line, problem)| line_err(line, problem))?;
        if ring.is_empty() {
            return Err(KeyError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(ring)
    }

    /// Parses key-file text; an error is the line (from 1) and what is wrong with it.
    pub fn parse(text: &str) -> Result<KeyRing, (usize, String)> {
        let mut ring = KeyRing::default();
        for (index, raw) in text.lines().enumerate() {
            let line = index + 1;
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let words: Vec<&str> = content.split_whitespace().collect();
            let (address, key_text) = match words.as_slice() {
                [key] => ("*", *key),
                [address, key] => (*address, *key),
                _ => {
                    return Err((
                        line,
                        format!(
                            "expected `ADDRESS KEY` (2 words), found {} words",
                            words.len()
                        ),
                    ));
                }
            };
            let key = parse_hex_key(key_text).map_err(|p| (line, p))?;
            let slot = match address {
                "*" => &mut ring.every_vehicle,
                "broadcast" => &mut ring.broadcast,
                number => {
                    let a: u8 = number
                        .parse()
                        .ok()
                        .filter(|a| (1..ADDR_BROADCAST).contains(a))
                        .ok_or_else(|| {
                            (
                                line,
                                format!(
                                    "address `{number}`: expected a vehicle 1..=14, `*` or `broadcast`"
                                ),
                            )
                        })?;
                    if ring.vehicles.contains_key(&a) {
                        return Err((line, format!("address {a}: a second key for it")));
                    }
                    ring.vehicles.insert(a, key);
                    continue;
                }
            };
            if slot.is_some() {
                return Err((line, format!("address `{address}`: a second key for it")));
            }
            *slot = Some(key);
        }
        Ok(ring)
    }

    /// True when the ring holds no key.
    pub fn is_empty(&self) -> bool {
        self.vehicles.is_empty() && self.every_vehicle.is_none() && self.broadcast.is_none()
    }

    /// The key of vehicle `address` (its own line, else `*`).
    pub fn vehicle(&self, address: u8) -> Option<&Key> {
        self.vehicles
            .get(&address)
            .or(self.every_vehicle.as_ref())
            .filter(|_| (1..ADDR_BROADCAST).contains(&address))
    }

    /// The key that protects a frame from `src` to `dst`: the broadcast key for DST 15,
    /// otherwise the key of the vehicle at the far end from the operator. Frames between two
    /// vehicles have none.
    pub fn for_frame(&self, src: u8, dst: u8) -> Option<&Key> {
        if dst == ADDR_BROADCAST {
            self.broadcast.as_ref()
        } else if src == ADDR_OPERATOR {
            self.vehicle(dst)
        } else if dst == ADDR_OPERATOR {
            self.vehicle(src)
        } else {
            None
        }
    }

    /// The same ring holding only what vehicle `address` needs: its own key and the broadcast
    /// key (a simulation gives each vehicle node only its own).
    pub fn for_vehicle(&self, address: u8) -> KeyRing {
        KeyRing {
            vehicles: self
                .vehicle(address)
                .map(|k| BTreeMap::from([(address, k.clone())]))
                .unwrap_or_default(),
            every_vehicle: None,
            broadcast: self.broadcast.clone(),
        }
    }
}

/// Writes a new key file at `path` holding one new key of `bits` for every vehicle (`* KEY`),
/// mode 0600; an existing file is refused, never replaced.
pub fn write_new_key_file(path: &Path, bits: usize) -> Result<(), KeyError> {
    let key = Key::generate(bits)?;
    let text = format!(
        "# rovlink frame key ({bits} bits): `ADDRESS KEY` per line; `*` is every vehicle.\n\
         # Copy it to the vehicle over a trusted path; keep it 0600.\n* {}\n",
        key.hex()
    );
    create_secret_file(path, text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    const K1: &str = "2b7e151628aed2a6abf7158809cf4f3c";
    const K2: &str = "603deb1015ca71be2b73aef0857d77811f352c073b6108d72d9810a30914dff4";

    #[test]
    fn a_file_maps_addresses_to_keys() {
        let ring = KeyRing::parse(&format!(
            "# keys\n1 {K1}\n\n2 {K2}  # the second\nbroadcast {K1}\n"
        ))
        .unwrap();
        assert_eq!(ring.vehicle(1).unwrap().bits(), 128);
        assert_eq!(ring.vehicle(2).unwrap().bits(), 256);
        assert!(ring.vehicle(3).is_none());
        assert_eq!(ring.for_frame(0, 2), ring.vehicle(2));
        assert_eq!(ring.for_frame(2, 0), ring.vehicle(2));
        assert_eq!(ring.for_frame(0, 15).unwrap().bits(), 128);
        assert!(ring.for_frame(1, 2).is_none());
        let only1 = ring.for_vehicle(1);
        assert!(only1.vehicle(2).is_none() && only1.vehicle(1).is_some());
    }

    #[test]
    fn a_bare_key_is_every_vehicle() {
        let ring = KeyRing::parse(&format!("{K1}\n")).unwrap();
        assert!(ring.vehicle(1).is_some() && ring.vehicle(14).is_some());
        assert!(ring.vehicle(0).is_none() && ring.vehicle(15).is_none());
        assert!(ring.for_frame(0, 15).is_none());
    }

    #[test]
    fn bad_lines_name_the_line_and_never_the_key() {
        for (text, expected) in [
            (format!("1 {}\n", &K1[..30]), "found 30 characters"),
            (format!("0 {K1}\n"), "address `0`"),
            (format!("15 {K1}\n"), "address `15`"),
            (format!("1 {K1}\n1 {K1}\n"), "a second key"),
            (format!("1 {K1} x\n"), "3 words"),
            (format!("1 {}zz\n", &K1[..30]), "character 31"),
        ] {
            let (line, problem) = KeyRing::parse(&text).unwrap_err();
            assert!(problem.contains(expected), "{problem}");
            assert!(!problem.contains(&K1[..16]), "{problem}");
            assert!(line >= 1);
        }
        assert!(!format!("{:?}", KeyRing::parse(K1).unwrap()).contains(&K1[..8]));
    }

    #[test]
    fn a_new_key_file_is_private_and_loads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("keys");
        write_new_key_file(&path, 256).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        let ring = KeyRing::load(&path).unwrap();
        assert_eq!(ring.vehicle(5).unwrap().bits(), 256);
        assert!(write_new_key_file(&path, 128).is_err());
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let err = KeyRing::load(&path).unwrap_err().to_string();
        assert!(err.contains("too open"), "{err}");
        let comments = dir.path().join("comments");
        create_secret_file(&comments, b"# nothing\n").unwrap();
        let err = KeyRing::load(&comments).unwrap_err().to_string();
        assert!(err.contains("no key"), "{err}");
    }
}
