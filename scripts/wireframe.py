"""Link frames as wire.md defines them, for the scripts: CRC-16/XMODEM and a frame builder."""


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM: polynomial 0x1021, init 0, not reflected (check value 0x31C3)."""
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def frame(src: int, dst: int, payload: bytes) -> bytes:
    """A link frame: 0x55, SRC:4|DST:4, LEN, payload, CRC over address..payload (big endian)."""
    body = bytes([(src << 4) | dst, len(payload)]) + payload
    crc = crc16_xmodem(body)
    return bytes([0x55]) + body + bytes([crc >> 8, crc & 0xFF])


assert crc16_xmodem(b"123456789") == 0x31C3
