//! Hex text, as the toolkit writes and reads it (frame dumps, key and token files): lowercase
//! out, either case in, and the position of the first character that is not a hex digit.

/// What is wrong with hex text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum HexError {
    /// An odd number of digits.
    #[error("an odd number of hex digits ({0})")]
    OddLength(usize),
    /// The character at this offset (from 0) is not a hex digit.
    #[error("a character that is not a hex digit at byte {0}")]
    NotHex(usize),
}

/// Decodes hex digits of either case into bytes.
pub fn decode(text: &[u8]) -> Result<Vec<u8>, HexError> {
    if !text.len().is_multiple_of(2) {
        return Err(HexError::OddLength(text.len()));
    }
    let nibble = |k: usize| {
        (text[k] as char)
            .to_digit(16)
            .map(|d| d as u8)
            .ok_or(HexError::NotHex(k))
    };
    (0..text.len() / 2)
        .map(|i| Ok(nibble(2 * i)? << 4 | nibble(2 * i + 1)?))
        .collect()
}

/// Encodes bytes as lowercase hex.
pub fn encode(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(bytes.len() * 2);
    for &b in bytes {
        out.push(DIGITS[usize::from(b >> 4)] as char);
        out.push(DIGITS[usize::from(b & 0x0f)] as char);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trips_and_names_the_first_bad_character() {
        assert_eq!(decode(b"00ffA0").unwrap(), [0x00, 0xff, 0xa0]);
        assert_eq!(encode(&[0x00, 0xff, 0xa0]), "00ffa0");
        assert_eq!(decode(b""), Ok(Vec::new()));
        assert_eq!(decode(b"abc"), Err(HexError::OddLength(3)));
        assert_eq!(decode(b"0g"), Err(HexError::NotHex(1)));
        assert_eq!(decode(b"x0zz"), Err(HexError::NotHex(0)));
    }
}
