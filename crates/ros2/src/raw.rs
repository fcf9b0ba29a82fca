//! Messages as bytes: the CDR a bag stores (4-byte encapsulation header, then the fields),
//! handed to and from RustDDS without a serde type, so the project's own decoders and encoders
//! (`rovlink_scans::ros`, fuzzed) serve live topics and bags alike.
//!
//! RustDDS gives a reader the representation identifier (the header's first two bytes) apart
//! from the body; [`RawAdapter`] puts the header back together (options bytes zero). A writer
//! is handed a whole message whose header must say little-endian plain CDR (`00 01`); the body
//! after the header goes on the wire.

use rustdds::RepresentationIdentifier;
use rustdds::bytes::Bytes;
use rustdds::no_key::{Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter};

/// A whole CDR message: encapsulation header and body, as a bag stores it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RawCdr(pub Vec<u8>);

/// A message that cannot go on the wire, or came off it in an encoding not understood.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RawError(pub String);

/// The header of little-endian plain CDR (XCDR1), what ROS 2 writes.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// RustDDS's adapter for [`RawCdr`], both directions.
pub struct RawAdapter;

/// The decoder [`RawAdapter`] uses.
#[derive(Clone, Copy)]
pub struct RawDecoder;

impl DeserializerAdapter<RawCdr> for RawAdapter {
    type Error = RawError;
    type Decoded = RawCdr;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }

    fn transform_decoded(decoded: RawCdr) -> RawCdr {
        decoded
    }
}

impl<'de> Decode<'de, RawCdr> for RawDecoder {
    type Error = RawError;

    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawCdr, RawError> {
        let id = encoding.to_bytes();
        let mut message = Vec::with_capacity(input_bytes.len() + 4);
        message.extend_from_slice(&[id[0], id[1], 0, 0]);
        message.extend_from_slice(input_bytes);
        Ok(RawCdr(message))
    }
}

impl DefaultDecoder<RawCdr> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl SerializerAdapter<RawCdr> for RawAdapter {
    type Error = RawError;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &RawCdr) -> Result<Bytes, RawError> {
        match value.0.get(..2) {
            Some(h) if h == &CDR_LE_HEADER[..2] => {
                Ok(Bytes::copy_from_slice(value.0.get(4..).unwrap_or_default()))
            }
            h => Err(RawError(format!(
                "expected a little-endian CDR message (header 00 01), found {h:02x?}"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_is_put_back_and_taken_off() {
        let body = [1u8, 2, 3, 4, 5];
        let m = RawAdapter::from_bytes(&body, RepresentationIdentifier::CDR_LE).unwrap();
        assert_eq!(m.0, [0, 1, 0, 0, 1, 2, 3, 4, 5]);
        assert_eq!(&RawAdapter::to_bytes(&m).unwrap()[..], &body);
        let be = RawAdapter::from_bytes(&body, RepresentationIdentifier::CDR_BE).unwrap();
        assert_eq!(be.0[..2], [0, 0]);
        let e = RawAdapter::to_bytes(&be).unwrap_err().to_string();
        assert!(e.contains("little-endian"), "{e}");
        assert!(RawAdapter::to_bytes(&RawCdr(vec![0])).is_err());
    }
}
