#!/usr/bin/env python3
"""Writes testdata/noisy.bin: wire.md's five frames with the faults a serial line produces between
them (garbage with false preambles, a frame with one flipped bit, a CRC-valid frame whose payload
is not a valid message, a truncated tail). rcp-dump's golden files are made from it.

Usage: scripts/make-noisy-stream.py [testdata/wire-vectors.hex] [testdata/noisy.bin]
"""
import binascii
import sys


from wireframe import crc16_xmodem


def main() -> None:
    hex_path = sys.argv[1] if len(sys.argv) > 1 else "testdata/wire-vectors.hex"
    out_path = sys.argv[2] if len(sys.argv) > 2 else "testdata/noisy.bin"
    with open(hex_path) as f:
        frames = [binascii.unhexlify(line.strip()) for line in f if line.strip()]
    out = bytearray(b"\x00\x13\x55\x99\xff")  # garbage with a false preamble (LEN 255)
    out += frames[0]
    corrupt = bytearray(frames[1])
    corrupt[7] ^= 0x10  # one flipped bit: a CRC failure
    out += corrupt
    out += frames[1] + frames[2]
    out += b"\x55\x55\x01"  # preambles in garbage
    out += frames[3]
    body = bytes([0x01, 0x03, 0xAA, 0xBB, 0xCC])  # operator frame, 3-byte payload: invalid message
    out += b"\x55" + body + crc16_xmodem(body).to_bytes(2, "big")
    out += frames[4]
    out += frames[0][:9]  # truncated tail
    with open(out_path, "wb") as f:
        f.write(out)
    print(f"{out_path}: {len(out)} bytes")


if __name__ == "__main__":
    main()
