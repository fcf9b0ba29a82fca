#!/usr/bin/env python3
"""Independent check of rovlink's secured frames (docs/wire-extensions.md, "Secured frames").

Rebuilds a secured frame from the plain frame, the key and the counter with the Python
`cryptography` package alone (AES-CMAC, AES-CTR), as the construction is written down, and
compares it byte for byte with the frame rovlink made; then verifies that frame's tag and
decrypts it back to the plain frame. Shares no code with the Rust crates.

    secured-frame-check.py KEY_HEX COUNTER PLAIN_FRAME_HEX SECURED_FRAME_HEX [...]

Arguments come in groups of four, one frame each; `e:` before COUNTER means encrypted
(`e:16385`). Exit 0 when every frame matches, 1 when one does not (the difference is said),
2 on bad usage, 3 when the `cryptography` package is missing.

The construction:
- K_mac, K_enc: NIST SP 800-108 counter-mode KDF with AES-CMAC as the PRF over the frame key:
  block i = CMAC(K, [i] || label || 0x00 || L as 2 bytes big-endian), L the key length in
  bits, labels "rovlink frame mac v1" and "rovlink frame enc v1".
- payload = FLAGS (E:1 C13:1 S:1=1 C12..C8:5) || C7..C0 || message (AES-CTR under K_enc when E,
  first counter block V D A C48 || 7 zero bytes) || TAG.
- TAG = first 4 bytes of CMAC(K_mac, V D A C48 LEN payload-before-tag): V = 1, D = 0 from the
  operator (SRC 0) else 1, A = SRC:4 DST:4, C48 the counter in 6 bytes big-endian, LEN the
  payload length with the tag.
- The link frame: 0x55 A LEN payload CRC-16/XMODEM (big-endian) over A LEN payload.
"""

import sys

try:
    from cryptography.hazmat.primitives import cmac
    from cryptography.hazmat.primitives.ciphers import Cipher, algorithms, modes
except ImportError:
    print("secured-frame-check: the Python package `cryptography` is missing "
          "(pip install cryptography)", file=sys.stderr)
    sys.exit(3)

VERSION = 1
TAG_BYTES = 4
MAC_LABEL = b"rovlink frame mac v1"
ENC_LABEL = b"rovlink frame enc v1"


def aes_cmac(key, data):
    c = cmac.CMAC(algorithms.AES(key))
    c.update(data)
    return c.finalize()


def derive(key, label):
    bits = (len(key) * 8).to_bytes(2, "big")
    out = b""
    i = 1
    while len(out) < len(key):
        out += aes_cmac(key, bytes([i]) + label + b"\x00" + bits)
        i += 1
    return out[:len(key)]


def ctr_xor(key, iv, data):
    enc = Cipher(algorithms.AES(key), modes.CTR(iv)).encryptor()
    return enc.update(data) + enc.finalize()


def crc16_xmodem(data):
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def link_frame(address, payload):
    body = bytes([address, len(payload)]) + payload
    return b"\x55" + body + crc16_xmodem(body).to_bytes(2, "big")


def prefix(address, counter):
    src = address >> 4
    direction = 0 if src == 0 else 1
    return bytes([VERSION, direction, address]) + counter.to_bytes(6, "big")


def seal(key, plain, counter, encrypt):
    """The secured frame of the plain link frame `plain`."""
    if plain[0] != 0x55 or len(plain) != plain[2] + 5:
        raise ValueError("the plain frame is not a link frame")
    address, message = plain[1], plain[3:-2]
    k_mac, k_enc = derive(key, MAC_LABEL), derive(key, ENC_LABEL)
    low = counter & 0x3FFF
    flags = 0x20 | ((low >> 8) & 0x1F) | (0x40 if low & 0x2000 else 0) | (0x80 if encrypt else 0)
    if encrypt:
        message = ctr_xor(k_enc, prefix(address, counter) + bytes(7), message)
    covered = bytes([flags, low & 0xFF]) + message
    length = len(covered) + TAG_BYTES
    tag = aes_cmac(k_mac, prefix(address, counter) + bytes([length]) + covered)[:TAG_BYTES]
    return link_frame(address, covered + tag)


def open_frame(key, secured, counter):
    """The plain frame inside `secured`, or None when its tag is wrong for `counter`."""
    address, payload = secured[1], secured[3:-2]
    if crc16_xmodem(secured[1:-2]) != int.from_bytes(secured[-2:], "big"):
        return None
    k_mac, k_enc = derive(key, MAC_LABEL), derive(key, ENC_LABEL)
    covered, tag = payload[:-TAG_BYTES], payload[-TAG_BYTES:]
    expected = aes_cmac(k_mac, prefix(address, counter) + bytes([len(payload)]) + covered)
    if expected[:TAG_BYTES] != tag:
        return None
    message = covered[2:]
    if covered[0] & 0x80:
        message = ctr_xor(k_enc, prefix(address, counter) + bytes(7), message)
    return link_frame(address, message)


def main(argv):
    if not argv or len(argv) % 4:
        usage = [line for line in __doc__.splitlines() if "KEY_HEX COUNTER" in line]
        print("usage: " + usage[0].strip(), file=sys.stderr)
        print("secured-frame-check: expected groups of 4 arguments, found %d" % len(argv),
              file=sys.stderr)
        return 2
    bad = 0
    for i in range(0, len(argv), 4):
        key_hex, counter_text, plain_hex, secured_hex = argv[i:i + 4]
        try:
            key, plain, secured = (bytes.fromhex(key_hex), bytes.fromhex(plain_hex),
                                   bytes.fromhex(secured_hex))
            encrypt = counter_text.startswith("e:")
            counter = int(counter_text[2:] if encrypt else counter_text)
        except ValueError as e:
            print("secured-frame-check: group %d: %s" % (i // 4 + 1, e), file=sys.stderr)
            return 2
        if len(key) not in (16, 32) or not 1 <= counter < 1 << 48:
            print("secured-frame-check: group %d: key of 16 or 32 bytes and a counter "
                  "1..2^48-1 expected" % (i // 4 + 1), file=sys.stderr)
            return 2
        mine = seal(key, plain, counter, encrypt)
        if mine != secured:
            print("MISMATCH counter %s: rovlink %s, independent %s"
                  % (counter_text, secured.hex(), mine.hex()))
            bad += 1
            continue
        if open_frame(key, secured, counter) != plain:
            print("MISMATCH counter %s: %s does not open to %s"
                  % (counter_text, secured.hex(), plain.hex()))
            bad += 1
            continue
        if counter > 1 and open_frame(key, secured, counter - 1) is not None:
            print("MISMATCH counter %s: the tag also holds for counter %d"
                  % (counter_text, counter - 1))
            bad += 1
            continue
        print("ok %s %s" % (counter_text, secured.hex()))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
