"""The drones' wire format: one versioned packet per ZeroMQ message.

A packet is a fixed 40-byte little-endian header followed by the payload::

    offset  size  field
    0       4     magic  b"APZ\\x00"
    4       1     version (WIRE_VERSION)
    5       1     kind   (DATA = a stage message, HELLO = heartbeat, BYE = clean shutdown,
                         SKIP = "I will not process this slot": do not wait for me)
    6       1     drone id of the sender (1..255)
    7       1     stage  (1..3: the iteration after which the message was produced; 0 otherwise)
    8       1     dtype  (0 = float32, 1 = float16)
    9       1     rate divisor m (HELLO: the sender asks the swarm to process every m-th slot,
                         runtime.rate; 0 or 1 = every slot; 0 in other kinds)
    10      2     payload length in bytes
    12      4     frame index (the sender's camera frame counter; logging only)
    16      4     schedule slot (for SKIP and diagnostics; DATA is matched by the stamp)
    20      8     frame time stamp: the shutter time of the frame in the sender's clock (s, float64)
    28      8     send time in the sender's clock (s, float64; for link latency)
    36      4     CRC-32 of bytes 0..35 (with this field zeroed) and of the payload

A DATA payload is the paper's message (``model.message.MESSAGE_DIM``): 126 body-pose numbers
(21 joints x 6D) and 10 betas, 136 values = 544 bytes as float32 (the paper) or 272 bytes as float16. HELLO, BYE and SKIP have no
payload.
Anything that does not parse (short, wrong magic, other version, bad CRC, payload size not
matching kind and dtype, non-finite values) raises :class:`WireError`; the node logs and drops it.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from airpose_lib.model.message import MESSAGE_DIM  # torch-free: sizes the DATA payload

__all__ = [
    "MAGIC",
    "WIRE_VERSION",
    "HEADER",
    "HEADER_BYTES",
    "DATA",
    "HELLO",
    "BYE",
    "SKIP",
    "DTYPES",
    "WireError",
    "Packet",
    "encode_packet",
    "decode_packet",
    "packet_nbytes",
]

MAGIC = b"APZ\x00"
WIRE_VERSION = 1
HEADER = struct.Struct("<4sBBBBBBHIIddI")
HEADER_BYTES = HEADER.size  # 40

DATA, HELLO, BYE, SKIP = 1, 2, 3, 4
_KINDS = {DATA: "data", HELLO: "hello", BYE: "bye", SKIP: "skip"}
# dtype code <-> little-endian numpy dtype on the wire.
DTYPES: dict[int, np.dtype] = {0: np.dtype("<f4"), 1: np.dtype("<f2")}
_CODES = {dt.name: code for code, dt in DTYPES.items()}


class WireError(ValueError):
    """A packet that cannot be accepted: ``code`` (short, for counting) and the message (why)."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Packet:
    """A decoded packet. ``payload`` is ``(136,)`` in the wire dtype for DATA, else empty."""

    kind: int
    drone: int
    stage: int
    frame_index: int
    slot: int
    stamp: float
    sent: float
    payload: np.ndarray
    version: int = WIRE_VERSION
    rate_divisor: int = 1  # HELLO: the slot divisor the sender asks for

    @property
    def kind_name(self) -> str:
        return _KINDS.get(self.kind, str(self.kind))


def _dtype_code(dtype) -> int:
    name = np.dtype(dtype).name
    if name not in _CODES:
        raise ValueError(f"message dtype must be float32 or float16, got {name}")
    return _CODES[name]


def packet_nbytes(kind: int = DATA, dtype="float32") -> int:
    """Bytes of one packet: 40 + 544 (float32 DATA), 40 + 272 (float16 DATA), 40 otherwise."""
    if kind != DATA:
        return HEADER_BYTES
    return HEADER_BYTES + MESSAGE_DIM * DTYPES[_dtype_code(dtype)].itemsize


def encode_packet(kind: int, drone: int, *, stage: int = 0, frame_index: int = 0, slot: int = 0, stamp: float = 0.0,
                  sent: float = 0.0, payload: np.ndarray | None = None, dtype="float32",
                  version: int = WIRE_VERSION, rate_divisor: int = 1) -> bytes:
    """Build one packet.

    Args:
        kind: DATA, HELLO, BYE or SKIP.
        drone: sender id, 1..255.
        stage: iteration that produced the payload (DATA).
        frame_index: sender's camera frame counter.
        slot: schedule slot.
        stamp: the frame's shutter time stamp in the sender's clock (s).
        sent: send time in the sender's clock (s).
        payload: DATA only, ``(136,)`` values, cast to ``dtype``.
        dtype: ``"float32"`` (544-byte payload) or ``"float16"`` (272 bytes).
        version: header version (tests use other values to make a wrong-version packet).
        rate_divisor: HELLO only, 1..255: the slot divisor the sender asks for.
    """
    code = _dtype_code(dtype)
    if kind == DATA:
        if payload is None:
            raise ValueError("a DATA packet needs a payload")
        body = np.ascontiguousarray(np.asarray(payload).reshape(-1), dtype=DTYPES[code])
        if body.size != MESSAGE_DIM:
            raise ValueError(f"a message has {MESSAGE_DIM} values, got {body.size}")
        body = body.tobytes()
    elif kind in (HELLO, BYE, SKIP):
        body = b""
    else:
        raise ValueError(f"unknown packet kind {kind}")
    if not 1 <= drone <= 255:
        raise ValueError(f"drone id must be in 1..255, got {drone}")
    if not 1 <= rate_divisor <= 255:
        raise ValueError(f"rate divisor must be in 1..255, got {rate_divisor}")
    divisor_byte = rate_divisor if kind == HELLO else 0
    head = HEADER.pack(MAGIC, version, kind, drone, stage, code, divisor_byte, len(body), frame_index & 0xFFFFFFFF,
                       slot & 0xFFFFFFFF, float(stamp), float(sent), 0)
    crc = zlib.crc32(body, zlib.crc32(head))
    return head[:-4] + struct.pack("<I", crc) + body


def decode_packet(buf: bytes) -> Packet:
    """Parse and validate one packet; raises :class:`WireError` with the reason otherwise."""
    buf = bytes(buf)
    if len(buf) < HEADER_BYTES:
        raise WireError("short", f"short packet: {len(buf)} bytes < {HEADER_BYTES}-byte header")
    magic, version, kind, drone, stage, code, divisor, n, frame_index, slot, stamp, sent, crc = HEADER.unpack_from(buf)
    if magic != MAGIC:
        raise WireError("magic", f"bad magic {magic!r}")
    if version != WIRE_VERSION:
        raise WireError("version", f"wire version {version} not supported (this node speaks {WIRE_VERSION})")
    if kind not in _KINDS:
        raise WireError("kind", f"unknown packet kind {kind}")
    if code not in DTYPES:
        raise WireError("dtype", f"unknown dtype code {code}")
    if len(buf) != HEADER_BYTES + n:
        raise WireError("length", f"length mismatch: header says {n} payload bytes, got {len(buf) - HEADER_BYTES}")
    head0 = buf[:HEADER_BYTES - 4] + b"\x00\x00\x00\x00"
    if zlib.crc32(buf[HEADER_BYTES:], zlib.crc32(head0)) != crc:
        raise WireError("crc", "CRC mismatch")
    if kind == DATA:
        expected = MESSAGE_DIM * DTYPES[code].itemsize
        if n != expected:
            raise WireError("payload_size", f"DATA payload of {n} bytes, expected {expected} for {DTYPES[code].name}")
        if not 1 <= stage <= 255:
            raise WireError("stage", "DATA packet without a stage")
        payload = np.frombuffer(buf, dtype=DTYPES[code], offset=HEADER_BYTES, count=MESSAGE_DIM)
        if not np.isfinite(payload).all():
            raise WireError("non_finite", "non-finite values in the payload")
    else:
        if n != 0:
            raise WireError("payload_size", f"{_KINDS[kind]} packet with a {n}-byte payload")
        payload = np.zeros(0, DTYPES[code])
    if not (np.isfinite(stamp) and np.isfinite(sent)):
        raise WireError("non_finite", "non-finite time stamp")
    return Packet(kind=kind, drone=drone, stage=stage, frame_index=frame_index, slot=slot, stamp=stamp, sent=sent,
                  payload=payload, version=version, rate_divisor=max(1, divisor) if kind == HELLO else 1)
