"""The drones' packet format: layout checked byte by byte with struct/zlib, sizes of the paper's
message (544 / 272 payload bytes), agreement with the model's message encoding, and that every
kind of malformed packet is rejected with a reason."""
from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from airpose_lib.runtime.wire import (
    BYE,
    DATA,
    HEADER_BYTES,
    HELLO,
    MAGIC,
    SKIP,
    WIRE_VERSION,
    WireError,
    decode_packet,
    encode_packet,
    packet_nbytes,
)


def _message(seed=0):
    return np.random.default_rng(seed).normal(size=136).astype(np.float32)


def _recrc(buf: bytes) -> bytes:
    """Fix the CRC of a hand-modified packet (so that only the intended defect remains)."""
    head = bytearray(buf[:HEADER_BYTES])
    head[36:40] = b"\x00\x00\x00\x00"
    crc = zlib.crc32(bytes(buf[HEADER_BYTES:]), zlib.crc32(bytes(head)))
    head[36:40] = struct.pack("<I", crc)
    return bytes(head) + bytes(buf[HEADER_BYTES:])


def test_layout_by_hand():
    msg = _message()
    buf = encode_packet(DATA, 7, stage=2, frame_index=123456, slot=42, stamp=1234.5678, sent=1234.6,
                        payload=msg)
    assert HEADER_BYTES == 40 and len(buf) == 40 + 544 == packet_nbytes(DATA, "float32")
    assert buf[:4] == MAGIC and buf[4] == WIRE_VERSION and buf[5] == DATA
    assert buf[6] == 7 and buf[7] == 2 and buf[8] == 0  # drone, stage, dtype float32
    assert struct.unpack_from("<H", buf, 10)[0] == 544
    assert struct.unpack_from("<II", buf, 12) == (123456, 42)
    assert struct.unpack_from("<dd", buf, 20) == (1234.5678, 1234.6)
    head0 = buf[:36] + b"\x00" * 4
    assert struct.unpack_from("<I", buf, 36)[0] == zlib.crc32(buf[40:], zlib.crc32(head0))
    assert buf[40:] == msg.astype("<f4").tobytes()


def test_roundtrip_float32_and_float16():
    msg = _message(1)
    p = decode_packet(encode_packet(DATA, 3, stage=1, frame_index=9, slot=4, stamp=10.25, sent=10.5, payload=msg))
    assert (p.kind, p.drone, p.stage, p.frame_index, p.slot, p.stamp, p.sent) == (DATA, 3, 1, 9, 4, 10.25, 10.5)
    np.testing.assert_array_equal(p.payload, msg)
    buf16 = encode_packet(DATA, 3, stage=1, payload=msg, dtype="float16")
    assert len(buf16) == 40 + 272 == packet_nbytes(DATA, np.float16)
    p16 = decode_packet(buf16)
    assert p16.payload.dtype == np.float16
    np.testing.assert_array_equal(p16.payload, msg.astype(np.float16))
    for kind in (HELLO, BYE, SKIP):
        q = decode_packet(encode_packet(kind, 200, slot=5, stamp=1.0))
        assert q.kind == kind and q.drone == 200 and q.slot == 5 and q.payload.size == 0
        assert packet_nbytes(kind) == 40


def test_payload_is_the_models_message():
    """The DATA payload is byte for byte the model's wire message (model.staged.encode_message)."""
    from airpose_lib.model import decode_message, encode_message

    theta = np.random.default_rng(2).normal(size=(21, 6)).astype(np.float32)
    beta = np.random.default_rng(3).normal(size=10).astype(np.float32)
    for dtype in ("float32", "float16"):
        msg = encode_message(theta, beta, dtype=dtype)
        buf = encode_packet(DATA, 1, stage=1, payload=msg, dtype=dtype)
        assert buf[HEADER_BYTES:] == msg.tobytes()
        t2, b2 = decode_message(decode_packet(buf).payload)
        np.testing.assert_array_equal(t2, theta.astype(dtype).astype(np.float32))
        np.testing.assert_array_equal(b2, beta.astype(dtype).astype(np.float32))


def _bad_packets():
    good = encode_packet(DATA, 2, stage=1, stamp=5.0, payload=_message())
    flipped = bytearray(good)
    flipped[100] ^= 0xFF
    nan = _message()
    nan[7] = np.nan
    nan_buf = bytearray(good)
    nan_buf[40:] = nan.astype("<f4").tobytes()
    wrong_size = bytearray(encode_packet(DATA, 2, stage=1, payload=_message(), dtype="float16"))
    wrong_size[8] = 0  # says float32, carries 272 bytes
    no_stage = bytearray(good)
    no_stage[7] = 0
    hello_with_payload = bytearray(encode_packet(HELLO, 2)) + b"\x00" * 4
    struct.pack_into("<H", hello_with_payload, 10, 4)
    nan_stamp = bytearray(good)
    struct.pack_into("<d", nan_stamp, 20, float("nan"))
    return {
        "short": (good[:20], "short packet"),
        "empty": (b"", "short packet"),
        "garbage": (bytes(range(200)), "bad magic"),
        "magic": (_recrc(b"XXXX" + good[4:]), "bad magic"),
        "version": (_recrc(good[:4] + bytes([WIRE_VERSION + 1]) + good[5:]), "version"),
        "kind": (_recrc(good[:5] + bytes([9]) + good[6:]), "unknown packet kind"),
        "dtype": (_recrc(good[:8] + bytes([5]) + good[9:]), "unknown dtype"),
        "truncated": (good[:-8], "length mismatch"),
        "crc": (bytes(flipped), "CRC"),
        "nan": (_recrc(bytes(nan_buf)), "non-finite"),
        "wrong_size": (_recrc(bytes(wrong_size)), "DATA payload"),
        "no_stage": (_recrc(bytes(no_stage)), "without a stage"),
        "hello_payload": (_recrc(bytes(hello_with_payload)), "payload"),
        "nan_stamp": (_recrc(bytes(nan_stamp)), "time stamp"),
    }


@pytest.mark.parametrize("name", sorted(_bad_packets()))
def test_malformed_packets_are_rejected(name):
    buf, reason = _bad_packets()[name]
    with pytest.raises(WireError, match=reason) as info:
        decode_packet(buf)
    assert info.value.code in {"short", "magic", "version", "kind", "dtype", "length", "crc", "payload_size",
                               "stage", "non_finite"}


def test_encode_checks_its_arguments():
    with pytest.raises(ValueError):
        encode_packet(DATA, 1, payload=_message()[:100])
    with pytest.raises(ValueError):
        encode_packet(DATA, 1)
    with pytest.raises(ValueError):
        encode_packet(DATA, 0, payload=_message())
    with pytest.raises(ValueError):
        encode_packet(DATA, 1, payload=_message(), dtype="float64")
    with pytest.raises(ValueError):
        encode_packet(42, 1)
