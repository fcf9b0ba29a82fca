//! A binary adaptive range coder whose stream can be cut at any byte.
//!
//! The coder is LZMA's (32-bit range, carry propagation through a cached byte) with three
//! changes for an embedded image stream:
//! - the leading zero byte LZMA always writes is not written;
//! - the stream ends with the value of the final interval that has the most trailing zero bits,
//!   and trailing zero bytes are dropped: the decoder reads zeros past the end, so they carry
//!   nothing;
//! - both sides keep [`RangeEncoder::tell_bits`] / [`RangeDecoder::tell_bits`], the same count of
//!   bits spent so far. A decoder given `n` bytes decodes a symbol only while
//!   `tell_bits() + MARGIN_BITS <= 8 n`; the encoder for a budget of `n` bytes follows the same
//!   rule and then terminates, which provably fits in `n` bytes. Cut a longer stream at `n`
//!   bytes and the decoder stops at a symbol it still decodes correctly (the interval left is
//!   `2^MARGIN_BITS` times wider than what the cut removed).
//!
//! Probabilities are 15-bit, each context mixing a fast and a slow adaptive estimate, with fast
//! warm-up for the first symbols of a context (images of a few hundred bytes code only tens of
//! symbols per context).
//!
//! No-panic contract: the decoder reads any bytes, of any length, without panicking.

/// Bits a symbol may cost at most (probabilities are clamped to [32, 32736] / 32768).
pub const MAX_SYMBOL_BITS: u32 = 10;
/// Safety margin kept between the bits spent and the bits available.
pub const MARGIN_BITS: u32 = MAX_SYMBOL_BITS + 14;

const PROB_BITS: u32 = 15;
const PROB_ONE: u32 = 1 << PROB_BITS;
const PROB_MIN: u32 = 32;
const PROB_MAX: u32 = PROB_ONE - 32;
const TOP: u32 = 1 << 24;

/// One adaptive binary context.
#[derive(Debug, Clone, Copy)]
pub struct Context {
    fast: u16,
    slow: u16,
    count: u8,
}

impl Default for Context {
    fn default() -> Self {
        Context {
            fast: (PROB_ONE / 2) as u16,
            slow: (PROB_ONE / 2) as u16,
            count: 0,
        }
    }
}

impl Context {
    /// A context that starts at probability `p0` of a 0 (in 1/32768, clamped to the coder's
    /// range) as if it had already seen `count` symbols: the count sets how fast it adapts
    /// from there ([`Context::default`] is `with_prior(16384, 0)`).
    pub fn with_prior(p0: u16, count: u8) -> Context {
        let p = u32::from(p0).clamp(PROB_MIN, PROB_MAX) as u16;
        Context {
            fast: p,
            slow: p,
            count,
        }
    }

    /// Probability of a 0, in 1/32768.
    pub fn p0(&self) -> u32 {
        ((u32::from(self.fast) + u32::from(self.slow)) / 2).clamp(PROB_MIN, PROB_MAX)
    }

    /// Adapts to a coded `bit`, as the encoder and the decoder do after each symbol.
    pub fn update(&mut self, bit: bool) {
        let fast_shift = u32::from(self.count.min(2)) + 1;
        let slow_shift = u32::from(self.count.min(5)) + 1;
        let target: i32 = if bit { 0 } else { PROB_ONE as i32 - 1 };
        let step = |p: u16, shift: u32| -> u16 {
            let p = i32::from(p);
            (p + ((target - p) >> shift)) as u16
        };
        self.fast = step(self.fast, fast_shift);
        self.slow = step(self.slow, slow_shift);
        self.count = self.count.saturating_add(1);
    }
}

/// The encoder.
#[derive(Debug, Clone)]
pub struct RangeEncoder {
    low: u64,
    range: u32,
    cache: u8,
    cache_size: u64,
    shifts: u64,
    out: Vec<u8>,
    first: bool,
}

impl Default for RangeEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl RangeEncoder {
    /// An empty encoder.
    pub fn new() -> RangeEncoder {
        RangeEncoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            cache_size: 1,
            shifts: 0,
            out: Vec::new(),
            first: true,
        }
    }

    /// Bits spent so far; equal to the decoder's after the same symbols.
    pub fn tell_bits(&self) -> u64 {
        8 * self.shifts + u64::from(32 - self.range.ilog2())
    }

    fn push(&mut self, byte: u8) {
        // LZMA's first byte is always 0: it is not written, and the decoder does not read it.
        if self.first {
            self.first = false;
        } else {
            self.out.push(byte);
        }
    }

    fn shift_low(&mut self) {
        if self.low < 0xff00_0000 || self.low >= 1 << 32 {
            let carry = (self.low >> 32) as u8;
            let mut byte = self.cache;
            loop {
                self.push(byte.wrapping_add(carry));
                byte = 0xff;
                self.cache_size -= 1;
                if self.cache_size == 0 {
                    break;
                }
            }
            self.cache = ((self.low >> 24) & 0xff) as u8;
        }
        self.cache_size += 1;
        self.low = (self.low & 0x00ff_ffff) << 8;
    }

    fn normalize(&mut self) {
        while self.range < TOP {
            self.range <<= 8;
            self.shifts += 1;
            self.shift_low();
        }
    }

    /// Codes `bit` in context `ctx`.
    pub fn encode(&mut self, ctx: &mut Context, bit: bool) {
        let bound = (self.range >> PROB_BITS) * ctx.p0();
        if bit {
            self.low += u64::from(bound);
            self.range -= bound;
        } else {
            self.range = bound;
        }
        ctx.update(bit);
        self.normalize();
    }

    /// Codes `bits` low bits of `value`, most significant first, at probability one half.
    pub fn encode_raw(&mut self, value: u32, bits: u32) {
        for i in (0..bits).rev() {
            self.range >>= 1;
            if (value >> i) & 1 == 1 {
                self.low += u64::from(self.range);
            }
            self.normalize();
        }
    }

    /// Ends the stream: the value with the most trailing zeros in the final interval, trailing
    /// zero bytes dropped.
    pub fn finish(mut self) -> Vec<u8> {
        let high = self.low + u64::from(self.range) - 1;
        let mut value = self.low;
        for zeros in (0..=40).rev() {
            let mask = (1u64 << zeros) - 1;
            let candidate = (self.low + mask) & !mask;
            if candidate <= high {
                value = candidate;
                break;
            }
        }
        self.low = value;
        for _ in 0..5 {
            self.shift_low();
        }
        while self.out.last() == Some(&0) {
            self.out.pop();
        }
        self.out
    }
}

/// The decoder. Reads zeros past the end of its input.
#[derive(Debug, Clone)]
pub struct RangeDecoder<'a> {
    data: &'a [u8],
    pos: usize,
    code: u32,
    range: u32,
    shifts: u64,
}

impl<'a> RangeDecoder<'a> {
    /// Starts decoding `data`.
    pub fn new(data: &'a [u8]) -> RangeDecoder<'a> {
        let mut d = RangeDecoder {
            data,
            pos: 0,
            code: 0,
            range: u32::MAX,
            shifts: 0,
        };
        for _ in 0..4 {
            d.code = (d.code << 8) | u32::from(d.next_byte());
        }
        d
    }

    fn next_byte(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// Bits spent so far; equal to the encoder's after the same symbols.
    pub fn tell_bits(&self) -> u64 {
        8 * self.shifts + u64::from(32 - self.range.ilog2())
    }

    fn normalize(&mut self) {
        while self.range < TOP {
            self.range <<= 8;
            self.shifts += 1;
            self.code = (self.code << 8) | u32::from(self.next_byte());
        }
    }

    /// Decodes a bit in context `ctx`.
    pub fn decode(&mut self, ctx: &mut Context) -> bool {
        let bound = (self.range >> PROB_BITS) * ctx.p0();
        let bit = if self.code < bound {
            self.range = bound;
            false
        } else {
            self.code -= bound;
            self.range -= bound;
            true
        };
        ctx.update(bit);
        self.normalize();
        bit
    }

    /// Decodes `bits` raw bits, most significant first.
    pub fn decode_raw(&mut self, bits: u32) -> u32 {
        let mut value = 0;
        for _ in 0..bits {
            self.range >>= 1;
            let bit = self.code >= self.range;
            if bit {
                self.code -= self.range;
            }
            value = (value << 1) | u32::from(bit);
            self.normalize();
        }
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random symbols with skewed probabilities in a few contexts, plus raw bits.
    fn symbols(n: usize, seed: u64) -> Vec<(usize, bool, bool)> {
        let mut s = rovlink_base::rng::Rng::new(seed, 0);
        (0..n)
            .map(|i| {
                let ctx = (s.next_u32() % 4) as usize;
                let threshold = [50, 200, 600, 950][ctx];
                ((ctx), s.next_u32() % 1000 < threshold, i % 17 == 0)
            })
            .collect()
    }

    fn encode_all(syms: &[(usize, bool, bool)]) -> (Vec<u8>, Vec<u64>) {
        let mut e = RangeEncoder::new();
        let mut ctx = [Context::default(); 4];
        let mut tells = Vec::new();
        for &(c, bit, raw) in syms {
            tells.push(e.tell_bits());
            if raw {
                e.encode_raw(u32::from(bit), 1);
            } else {
                e.encode(&mut ctx[c], bit);
            }
        }
        (e.finish(), tells)
    }

    fn decode_some(data: &[u8], syms: &[(usize, bool, bool)], budget_bytes: usize) -> usize {
        let mut d = RangeDecoder::new(data);
        let mut ctx = [Context::default(); 4];
        for (i, &(c, bit, raw)) in syms.iter().enumerate() {
            if d.tell_bits() + u64::from(MARGIN_BITS) > 8 * budget_bytes as u64 {
                return i;
            }
            let got = if raw {
                d.decode_raw(1) == 1
            } else {
                d.decode(&mut ctx[c])
            };
            assert_eq!(
                got,
                bit,
                "symbol {i} of {} with {budget_bytes} bytes",
                syms.len()
            );
        }
        syms.len()
    }

    #[test]
    fn round_trip() {
        let syms = symbols(20_000, 7);
        let (data, tells) = encode_all(&syms);
        assert_eq!(decode_some(&data, &syms, data.len() + 8), syms.len());
        // The stream costs about what tell says.
        let last = *tells.last().unwrap();
        assert!(
            (data.len() as i64 * 8 - last as i64).abs() < 40,
            "{} bytes, tell {last}",
            data.len()
        );
    }

    #[test]
    fn every_prefix_decodes_what_it_covers() {
        let syms = symbols(3_000, 11);
        let (data, _) = encode_all(&syms);
        let mut last = 0;
        for cut in 0..=data.len() {
            let n = decode_some(&data[..cut], &syms, cut);
            assert!(n >= last, "more bytes decode no fewer symbols");
            last = n;
        }
        assert!(last > syms.len() * 9 / 10);
    }

    #[test]
    fn budgeted_encoding_fits_and_decodes() {
        let syms = symbols(5_000, 3);
        for budget in [0usize, 1, 2, 3, 4, 5, 8, 13, 40, 100, 250, 333] {
            let mut e = RangeEncoder::new();
            let mut ctx = [Context::default(); 4];
            let mut coded = 0;
            for &(c, bit, raw) in &syms {
                if e.tell_bits() + u64::from(MARGIN_BITS) > 8 * budget as u64 {
                    break;
                }
                if raw {
                    e.encode_raw(u32::from(bit), 1);
                } else {
                    e.encode(&mut ctx[c], bit);
                }
                coded += 1;
            }
            let data = e.finish();
            assert!(
                data.len() <= budget,
                "budget {budget}: {} bytes",
                data.len()
            );
            assert_eq!(decode_some(&data, &syms, budget), coded, "budget {budget}");
        }
    }

    #[test]
    fn decoder_survives_any_bytes() {
        let mut s = rovlink_base::rng::Rng::new(99, 0);
        let data: Vec<u8> = (0..500).map(|_| s.next_u32() as u8).collect();
        let mut d = RangeDecoder::new(&data);
        let mut ctx = Context::default();
        for _ in 0..10_000 {
            d.decode(&mut ctx);
            d.decode_raw(3);
        }
    }
}
