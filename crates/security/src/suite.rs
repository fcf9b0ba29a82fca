//! The cryptography, in one place: AES-CMAC (RFC 4493) truncated to [`TAG_BYTES`] for
//! authenticity, AES-CTR for secrecy, each under its own key derived from the frame key with
//! the NIST SP 800-108 counter-mode KDF (CMAC as the PRF).
//!
//! Why this construction: it is LoRaWAN's (a 4-byte AES-CMAC MIC over the addresses, the
//! direction and a frame counter; AES-CTR for the payload), proven on links as narrow as ours;
//! one block cipher serves both (AES, in hardware on every CPU we run on); CMAC needs no nonce,
//! so a frame's tag depends only on the key and the bytes, and encrypt-then-MAC means a forged
//! frame is refused before anything is decrypted. The RustCrypto crates (`aes`, `cmac`, `ctr`)
//! are maintained, constant-time on CPUs with AES instructions, and used by LoRaWAN stacks.

use aes::{Aes128, Aes256};
use cmac::{Cmac, Mac};
use ctr::cipher::{KeyIvInit, StreamCipher};

use crate::key::Key;

/// Bytes of the truncated tag a frame carries: a forger's odds are 2^-32 per frame tried.
pub const TAG_BYTES: usize = 4;

/// The label of the MAC key's derivation.
const MAC_LABEL: &[u8] = b"rovlink frame mac v1";
/// The label of the encryption key's derivation.
const ENC_LABEL: &[u8] = b"rovlink frame enc v1";

/// A keyed CMAC, ready to clone per message (the key schedule is expanded once).
#[derive(Clone)]
enum Prf {
    A128(Box<Cmac<Aes128>>),
    A256(Box<Cmac<Aes256>>),
}

impl Prf {
    fn new(key: &Key) -> Prf {
        match key {
            // Key lengths are the cipher's by construction: `new_from_slice` cannot fail.
            Key::Aes128(k) => Prf::A128(Box::new(
                <Cmac<Aes128> as Mac>::new_from_slice(k).expect("16-byte key"),
            )),
            Key::Aes256(k) => Prf::A256(Box::new(
                <Cmac<Aes256> as Mac>::new_from_slice(k).expect("32-byte key"),
            )),
        }
    }

    /// The full 16-byte CMAC of the concatenation of `parts`.
    fn cmac(&self, parts: &[&[u8]]) -> [u8; 16] {
        fn run<M: Mac + Clone>(m: &M, parts: &[&[u8]]) -> [u8; 16] {
            let mut m = m.clone();
            for p in parts {
                m.update(p);
            }
            let out = m.finalize().into_bytes();
            let mut tag = [0u8; 16];
            tag.copy_from_slice(&out[..16]);
            tag
        }
        match self {
            Prf::A128(m) => run(m.as_ref(), parts),
            Prf::A256(m) => run(m.as_ref(), parts),
        }
    }

    /// SP 800-108 counter mode: `out_len` bytes (16 or 32) for `label`.
    fn derive(&self, label: &[u8], out_len: usize) -> Vec<u8> {
        let bits = u16::try_from(out_len * 8).unwrap_or(u16::MAX).to_be_bytes();
        let mut out = Vec::with_capacity(out_len);
        let mut i = 1u8;
        while out.len() < out_len {
            out.extend_from_slice(&self.cmac(&[&[i], label, &[0], &bits]));
            i = i.wrapping_add(1);
        }
        out.truncate(out_len);
        out
    }
}

/// One frame key's working keys: the tag's and the keystream's.
#[derive(Clone)]
pub struct Suite {
    mac: Prf,
    enc: Key,
}

impl std::fmt::Debug for Suite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Suite(AES-{}, hidden)", self.enc.bits())
    }
}

impl Suite {
    /// Derives the working keys from `key` (same size as it).
    pub fn new(key: &Key) -> Suite {
        let master = Prf::new(key);
        let len = key.bytes().len();
        // Derived keys have the master's length: `from_bytes` takes 16 or 32.
        let mac_key = Key::from_bytes(&master.derive(MAC_LABEL, len)).expect("16 or 32 bytes");
        let enc = Key::from_bytes(&master.derive(ENC_LABEL, len)).expect("16 or 32 bytes");
        Suite {
            mac: Prf::new(&mac_key),
            enc,
        }
    }

    /// The truncated tag of the concatenation of `parts`.
    pub fn tag(&self, parts: &[&[u8]]) -> [u8; TAG_BYTES] {
        let full = self.mac.cmac(parts);
        let mut tag = [0u8; TAG_BYTES];
        tag.copy_from_slice(&full[..TAG_BYTES]);
        tag
    }

    /// XORs `data` with the AES-CTR keystream starting at counter block `iv` (encrypts and
    /// decrypts alike).
    pub fn apply_keystream(&self, iv: [u8; 16], data: &mut [u8]) {
        match &self.enc {
            Key::Aes128(k) => {
                ctr::Ctr128BE::<Aes128>::new(k.into(), &iv.into()).apply_keystream(data)
            }
            Key::Aes256(k) => {
                ctr::Ctr128BE::<Aes256>::new(k.into(), &iv.into()).apply_keystream(data)
            }
        }
    }
}

/// Working keys per (SRC, DST), each derived from its frame key once, when first needed: a
/// node's guard and a stream's sealer keep one.
#[derive(Debug, Default)]
pub(crate) struct Suites(std::collections::HashMap<(u8, u8), Suite>);

impl Suites {
    /// The working keys for frames from `src` to `dst` under `ring`'s key for them.
    pub(crate) fn get(&mut self, ring: &crate::key::KeyRing, src: u8, dst: u8) -> Option<&Suite> {
        use std::collections::hash_map::Entry;
        match self.0.entry((src, dst)) {
            Entry::Occupied(known) => Some(known.into_mut()),
            Entry::Vacant(new) => Some(new.insert(Suite::new(ring.for_frame(src, dst)?))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    #[test]
    fn cmac_matches_rfc_4493() {
        // RFC 4493 section 4, example 2 (16-byte message) and example 3 (40 bytes).
        let key = Key::from_bytes(&hex("2b7e151628aed2a6abf7158809cf4f3c")).unwrap();
        let prf = Prf::new(&key);
        let m =
            hex("6bc1bee22e409f96e93d7e117393172aae2d8a571e03ac9c9eb76fac45af8e5130c81c46a35ce411");
        assert_eq!(
            prf.cmac(&[&m[..16]]).to_vec(),
            hex("070a16b46b4d4144f79bdd9dd04a287c")
        );
        assert_eq!(
            prf.cmac(&[&m[..20], &m[20..]]).to_vec(),
            hex("dfa66747de9ae63030ca32611497c827")
        );
    }

    #[test]
    fn ctr_matches_sp_800_38a() {
        // NIST SP 800-38A F.5.1, CTR-AES128, first block; F.5.5, CTR-AES256, first block. The
        // encryption key is used directly here (no derivation) to check the mode.
        let cases = [
            (
                "2b7e151628aed2a6abf7158809cf4f3c",
                "874d6191b620e3261bef6864990db6ce",
            ),
            (
                "603deb1015ca71be2b73aef0857d77811f352c073b6108d72d9810a30914dff4",
                "601ec313775789a5b7a7f504bbf3d228",
            ),
        ];
        for (key, expected) in cases {
            let key = Key::from_bytes(&hex(key)).unwrap();
            let suite = Suite {
                mac: Prf::new(&key),
                enc: key,
            };
            let mut block = hex("6bc1bee22e409f96e93d7e117393172a");
            let iv: [u8; 16] = hex("f0f1f2f3f4f5f6f7f8f9fafbfcfdfeff").try_into().unwrap();
            suite.apply_keystream(iv, &mut block);
            assert_eq!(block, hex(expected));
        }
    }

    #[test]
    fn derived_keys_differ_from_the_key_and_each_other() {
        let key = Key::from_bytes(&[7u8; 16]).unwrap();
        let suite = Suite::new(&key);
        assert_ne!(suite.enc, key);
        assert_ne!(
            suite.tag(&[b"x"]),
            Suite::new(&Key::from_bytes(&[8u8; 16]).unwrap()).tag(&[b"x"])
        );
        assert_eq!(suite.tag(&[b"a", b"b"]), suite.tag(&[b"ab"]));
        assert_ne!(suite.tag(&[b"a"]), suite.tag(&[b"b"]));
    }
}
