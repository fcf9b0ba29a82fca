//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>): the key
//! file, signing what we send and checking what we hear.
//!
//! A signed frame carries 13 more bytes: the link id (1 byte), a timestamp (6 bytes, little
//! endian, in 10 µs units since 2015-01-01 00:00 UTC) and the first 6 bytes of
//! SHA-256(key, the frame from its magic byte to its checksum, link id, timestamp). The hash
//! is the `mavlink` crate's ([`MAVLinkV2MessageRaw::calculate_signature`]); the timestamps and
//! the checks are here, so that each refusal has its reason.
//!
//! Outgoing timestamps follow the wall clock, as ArduPilot's and MAVProxy's do, and never go
//! backwards within a run (each is at least the previous one plus one): nothing has to be
//! kept between runs. Incoming, per stream (link id, system, component): a timestamp must be
//! greater than the stream's last one, and a stream not heard before must not be more than
//! [`NEW_STREAM_SLACK_10US`] older than our own time, the wall clock's or the newest timestamp
//! accepted if later (a replay of a recorded session is refused that way, as the MAVLink
//! library and ArduPilot refuse it).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;
use std::time::{SystemTime, UNIX_EPOCH};

use mavlink::{MAVLinkMessageRaw, MAVLinkV2MessageRaw, MavHeader, Message};

use super::transport::lock;

/// The length of a signing key, bytes.
pub const KEY_BYTES: usize = 32;

/// The bytes a signature adds to a frame: link id 1, timestamp 6, signature 6.
pub const SIGNATURE_BYTES: usize = 13;

/// 2015-01-01 00:00:00 UTC, the signing timestamps' origin, in Unix seconds.
const EPOCH_2015_S: u64 = 1_420_070_400;

/// How much older than the newest accepted timestamp a new stream may start: one minute, in
/// 10 µs units (the MAVLink signing specification's bound).
pub const NEW_STREAM_SLACK_10US: u64 = 60 * 100_000;

/// The most streams remembered; past it a new stream is refused as a replay would be (a
/// link carries a handful: the autopilot's components).
pub const MAX_STREAMS: usize = 256;

/// Why a MAVLink key file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The file itself was refused (permissions, owner, size) or could not be read.
    #[error("{0}")]
    File(#[from] rovlink_base::secret::SecretFileError),
    /// Its contents are neither form.
    #[error(
        "{path}: expected 64 hex digits (and a newline) or exactly 32 raw bytes, found {found}"
    )]
    Format {
        /// The file.
        path: String,
        /// What it holds.
        found: String,
    },
}

/// A 32-byte MAVLink signing key. Its `Debug` shows no byte of it.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey(pub [u8; KEY_BYTES]);

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SigningKey(..)")
    }
}

impl SigningKey {
    /// Reads a key file: 64 hex digits with an optional trailing newline (what `xxd -p -c 64`
    /// writes), or exactly 32 raw bytes. The file is checked as ssh checks a private key
    /// ([`rovlink_base::secret::read_secret_file`]: a regular file of ours, mode 0600 or
    /// stricter).
    pub fn read(path: &Path) -> Result<SigningKey, KeyError> {
        let bytes = rovlink_base::secret::read_secret_file(path, 2 * KEY_BYTES as u64 + 2)?;
        SigningKey::parse(&bytes).map_err(|found| KeyError::Format {
            path: path.display().to_string(),
            found,
        })
    }

    /// A key file's contents (see [`SigningKey::read`]); the error says what was found.
    pub fn parse(bytes: &[u8]) -> Result<SigningKey, String> {
        if bytes.len() == KEY_BYTES {
            let mut key = [0u8; KEY_BYTES];
            key.copy_from_slice(bytes);
            return Ok(SigningKey(key));
        }
        let text = bytes
            .strip_suffix(b"\n")
            .map(|t| t.strip_suffix(b"\r").unwrap_or(t))
            .unwrap_or(bytes);
        if text.len() != 2 * KEY_BYTES {
            return Err(format!("{} bytes", bytes.len()));
        }
        let bytes = rovlink_base::hex::decode(text).map_err(|e| e.to_string())?;
        let mut key = [0u8; KEY_BYTES];
        key.copy_from_slice(&bytes);
        Ok(SigningKey(key))
    }
}

/// Now in signing timestamp units (10 µs since 2015), from the wall clock; 0 before 2015.
pub fn wall_timestamp() -> u64 {
    let micros = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros());
    (micros.saturating_sub(u128::from(EPOCH_2015_S) * 1_000_000) / 10) as u64 & 0xffff_ffff_ffff
}

/// Why a frame heard was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Refusal {
    /// No signature (MAVLink 1, or MAVLink 2 without the signed flag).
    Unsigned,
    /// A signature that this key did not make.
    BadSignature,
    /// A timestamp not after its stream's last one, or a new stream more than a minute older
    /// than the newest timestamp accepted.
    Replayed,
    /// UDP: a datagram from another address than the autopilot's.
    OtherAddress,
    /// UDP: a message from another system than the autopilot's, from its address.
    OtherSystem,
}

impl Refusal {
    /// Every reason, in the order of the metrics.
    pub const ALL: [Refusal; 5] = [
        Refusal::Unsigned,
        Refusal::BadSignature,
        Refusal::Replayed,
        Refusal::OtherAddress,
        Refusal::OtherSystem,
    ];

    /// The reason's name in `--metrics` (`mavlink_refused`) and on stderr.
    pub fn name(self) -> &'static str {
        match self {
            Refusal::Unsigned => "unsigned",
            Refusal::BadSignature => "bad_signature",
            Refusal::Replayed => "replayed",
            Refusal::OtherAddress => "other_address",
            Refusal::OtherSystem => "other_system",
        }
    }
}

/// A signature stream: link id, system, component.
type Stream = (u8, u32, u8);

/// What the streams heard so far: each one's last timestamp, and the newest of all.
#[derive(Default)]
struct Streams {
    last: HashMap<Stream, u64>,
    newest: u64,
}

/// Signs what we send and checks what we hear with one key.
pub struct Signing {
    key: SigningKey,
    link_id: u8,
    /// The last timestamp we sent.
    sent: Mutex<u64>,
    /// The last timestamp accepted per stream (link id, system, component), and the newest.
    streams: Mutex<Streams>,
}

impl Signing {
    /// Signing with `key`, our frames marked with `link_id`.
    pub fn new(key: SigningKey, link_id: u8) -> Signing {
        Signing {
            key,
            link_id,
            sent: Mutex::new(0),
            streams: Mutex::new(Streams::default()),
        }
    }

    /// The next outgoing timestamp: the wall clock's, or one more than the last one sent when
    /// the clock has not moved on (or went back).
    fn next_timestamp(&self) -> u64 {
        let mut sent = lock(&self.sent);
        *sent = wall_timestamp().max(*sent + 1);
        *sent
    }

    /// `message` with `header` as a signed MAVLink 2 frame stamped `timestamp`.
    pub fn frame_at<M: Message>(&self, header: MavHeader, message: &M, timestamp: u64) -> Vec<u8> {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message_for_signing(header, message);
        raw.signature_timestamp_bytes_mut()
            .copy_from_slice(&timestamp.to_le_bytes()[..6]);
        *raw.signature_link_id_mut() = self.link_id;
        let mut signature = [0u8; 6];
        raw.calculate_signature(&self.key.0, &mut signature);
        raw.signature_value_mut().copy_from_slice(&signature);
        raw.raw_bytes().to_vec()
    }

    /// `message` with `header` as a signed MAVLink 2 frame stamped now.
    pub fn frame<M: Message>(&self, header: MavHeader, message: &M) -> Vec<u8> {
        self.frame_at(header, message, self.next_timestamp())
    }

    /// Checks a frame heard: `Ok` when it is signed with our key and its timestamp is new for
    /// its stream (which then remembers it).
    pub fn check(&self, raw: &MAVLinkMessageRaw) -> Result<(), Refusal> {
        self.check_at(raw, wall_timestamp())
    }

    /// [`Signing::check`] with the wall clock at `now` (signing timestamp units).
    fn check_at(&self, raw: &MAVLinkMessageRaw, now: u64) -> Result<(), Refusal> {
        let MAVLinkMessageRaw::V2(frame) = raw else {
            return Err(Refusal::Unsigned);
        };
        if frame.incompatibility_flags() & mavlink::consts::v2::IFLAG_SIGNED == 0 {
            return Err(Refusal::Unsigned);
        }
        let mut signature = [0u8; 6];
        frame.calculate_signature(&self.key.0, &mut signature);
        if signature[..] != *frame.signature_value() {
            return Err(Refusal::BadSignature);
        }
        let timestamp = frame.signature_timestamp();
        let stream = (
            frame.signature_link_id(),
            frame.system_id(),
            frame.component_id(),
        );
        let mut streams = lock(&self.streams);
        match streams.last.get(&stream) {
            Some(&last) if timestamp <= last => return Err(Refusal::Replayed),
            Some(_) => {}
            None => {
                if timestamp.saturating_add(NEW_STREAM_SLACK_10US) < streams.newest.max(now)
                    || streams.last.len() >= MAX_STREAMS
                {
                    return Err(Refusal::Replayed);
                }
            }
        }
        streams.last.insert(stream, timestamp);
        streams.newest = streams.newest.max(timestamp);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::MavMessage;

    fn key() -> SigningKey {
        SigningKey(std::array::from_fn(|k| k as u8))
    }

    fn heartbeat() -> MavMessage {
        super::super::codec::gcs_heartbeat()
    }

    fn header(sequence: u8) -> MavHeader {
        MavHeader {
            system_id: 255,
            component_id: 190,
            sequence,
        }
    }

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    fn raw(bytes: &[u8]) -> MAVLinkMessageRaw {
        let mut reader = mavlink::MavlinkReader::new(bytes);
        reader.read_any_raw_message::<MavMessage>().unwrap()
    }

    /// The same frame pymavlink 2.4.50 writes (checked against it, see the test below).
    const PYMAVLINK_HEARTBEAT: &str =
        "fd09010007ffbe00000000000000060800040399020740e2010000000cd3e91f5e97";

    #[test]
    fn a_signed_heartbeat_is_the_frame_pymavlink_makes() {
        // pymavlink: MAVLink(file, srcSystem=255, srcComponent=190), signing.secret_key =
        // bytes(range(32)), link_id 7, timestamp 123456, sign_outgoing; seq 7; heartbeat_send(
        // MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE).
        let signing = Signing::new(key(), 7);
        let frame = signing.frame_at(header(7), &heartbeat(), 123_456);
        assert_eq!(hex(&frame), PYMAVLINK_HEARTBEAT);
        assert_eq!(frame.len(), 12 + 9 + SIGNATURE_BYTES);
        // And it is accepted once, then refused as a replay.
        // (At a clock of that time: it is 2015's first seconds.)
        let reader = Signing::new(key(), 0);
        assert_eq!(reader.check_at(&raw(&frame), 123_456), Ok(()));
        assert_eq!(
            reader.check_at(&raw(&frame), 123_456),
            Err(Refusal::Replayed)
        );
    }

    #[test]
    fn unsigned_badly_signed_and_old_frames_are_refused_each_for_its_reason() {
        let ours = Signing::new(key(), 1);
        let checker = Signing::new(key(), 0);
        // The wall clock of the checks: some time in 2026.
        let now = 3_600_000_000_000;
        let check = |frame: &[u8]| checker.check_at(&raw(frame), now);
        let mut unsigned = Vec::new();
        mavlink::write_versioned_msg(
            &mut unsigned,
            mavlink::MavlinkVersion::V2,
            header(0),
            &heartbeat(),
        )
        .unwrap();
        assert_eq!(check(&unsigned), Err(Refusal::Unsigned));
        let mut v1 = Vec::new();
        mavlink::write_versioned_msg(
            &mut v1,
            mavlink::MavlinkVersion::V1,
            header(0),
            &heartbeat(),
        )
        .unwrap();
        assert_eq!(check(&v1), Err(Refusal::Unsigned));
        let other_key = Signing::new(SigningKey([9; KEY_BYTES]), 1);
        assert_eq!(
            check(&other_key.frame_at(header(0), &heartbeat(), now)),
            Err(Refusal::BadSignature)
        );
        // A stream's timestamps must increase.
        let t = now + 500;
        assert_eq!(check(&ours.frame_at(header(0), &heartbeat(), t)), Ok(()));
        assert_eq!(
            check(&ours.frame_at(header(1), &heartbeat(), t)),
            Err(Refusal::Replayed)
        );
        assert_eq!(
            check(&ours.frame_at(header(1), &heartbeat(), t - 5)),
            Err(Refusal::Replayed)
        );
        assert_eq!(
            check(&ours.frame_at(header(2), &heartbeat(), t + 1)),
            Ok(())
        );
        // Another stream (link 2) may start up to a minute behind the newest, not more.
        let link2 = Signing::new(key(), 2);
        let old = t + 1 - NEW_STREAM_SLACK_10US - 1;
        assert_eq!(
            check(&link2.frame_at(header(0), &heartbeat(), old)),
            Err(Refusal::Replayed)
        );
        assert_eq!(
            check(&link2.frame_at(header(0), &heartbeat(), old + 1)),
            Ok(())
        );
        // Nor more than a minute behind our clock, the first stream too: a recorded session
        // replayed to a fresh checker is refused.
        let fresh = Signing::new(key(), 0);
        let recorded = ours.frame_at(header(4), &heartbeat(), now - NEW_STREAM_SLACK_10US - 1);
        assert_eq!(fresh.check_at(&raw(&recorded), now), Err(Refusal::Replayed));
        let recent = ours.frame_at(header(5), &heartbeat(), now - NEW_STREAM_SLACK_10US);
        assert_eq!(fresh.check_at(&raw(&recent), now), Ok(()));
        // A flipped signature byte is a bad signature.
        let mut flipped = ours.frame_at(header(3), &heartbeat(), t + 10);
        let last = flipped.len() - 1;
        flipped[last] ^= 1;
        assert_eq!(check(&flipped), Err(Refusal::BadSignature));
    }

    #[test]
    fn outgoing_timestamps_follow_the_wall_clock_and_never_repeat() {
        let signing = Signing::new(key(), 0);
        let now = wall_timestamp();
        // 2026 is about 3.5e13 units after 2015.
        assert!(now > 3_000_000_000_000, "{now}");
        let stamps: Vec<u64> = (0..1000).map(|_| signing.next_timestamp()).collect();
        assert!(stamps.windows(2).all(|w| w[1] > w[0]));
        assert!(stamps[0] >= now);
        // A clock behind the last stamp (set back) does not take it back.
        *lock(&signing.sent) = now + 1_000_000;
        assert_eq!(signing.next_timestamp(), now + 1_000_001);
    }

    #[test]
    fn key_files_hold_hex_or_raw_bytes() {
        let hex_key: String = (0..32).map(|k| format!("{k:02x}")).collect();
        assert_eq!(SigningKey::parse(hex_key.as_bytes()).unwrap(), key());
        assert_eq!(
            SigningKey::parse(format!("{}\n", hex_key.to_uppercase()).as_bytes()).unwrap(),
            key()
        );
        assert_eq!(SigningKey::parse(&key().0).unwrap(), key());
        assert_eq!(SigningKey::parse(b"abc").unwrap_err(), "3 bytes");
        let mut bad = hex_key.clone().into_bytes();
        bad[5] = b'g';
        assert_eq!(
            SigningKey::parse(&bad).unwrap_err(),
            "a character that is not a hex digit at byte 5"
        );
        assert_eq!(format!("{:?}", key()), "SigningKey(..)");
    }

    #[test]
    fn key_files_are_checked_as_private_keys() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("key");
        let hex_key: String = (0..32).map(|k| format!("{k:02x}")).collect();
        rovlink_base::secret::create_secret_file(&path, format!("{hex_key}\n").as_bytes()).unwrap();
        assert_eq!(SigningKey::read(&path).unwrap(), key());
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let error = SigningKey::read(&path).unwrap_err().to_string();
        assert!(error.contains("too open"), "{error}");
        let short = dir.path().join("short");
        rovlink_base::secret::create_secret_file(&short, b"0123").unwrap();
        let error = SigningKey::read(&short).unwrap_err().to_string();
        assert!(error.ends_with("found 4 bytes"), "{error}");
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_are_a_key_or_say_what_they_are(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..80)) {
            match SigningKey::parse(&bytes) {
                Ok(_) => proptest::prop_assert!(bytes.len() == 32 || bytes.len() >= 64),
                Err(found) => proptest::prop_assert!(!found.is_empty() && !found.contains('\n')),
            }
        }

        #[test]
        fn any_signed_looking_frame_is_checked_without_a_panic(
            tail in proptest::collection::vec(proptest::num::u8::ANY, 0..300),
        ) {
            // A signed frame's start, then anything: the reader keeps what checks out.
            let mut bytes = vec![0xfd, 9, 1, 0, 7, 1, 1, 0, 0, 0];
            bytes.extend(tail);
            let checker = Signing::new(key(), 0);
            let mut reader = mavlink::MavlinkReader::new(&bytes[..]);
            while let Ok(frame) = reader.read_any_raw_message::<MavMessage>() {
                let _ = checker.check(&frame);
            }
        }
    }
}
