"""Scene state snapshots as compact binary frames, streamed from a server to its clients
(one WebSocket binary message per frame).

The scheme follows Glenn Fiedler's "Snapshot Compression": positions quantized to a
fixed resolution, orientations as "smallest three" quaternions, and each frame
delta-coded against the last snapshot the client acknowledged (its *baseline*), so a
scene at rest costs a few dozen bytes per frame. A second mode, ``"full"``, carries
float64 positions, orientations and both velocities, reproduced bit for bit, for
research clients.

Roles: the server keeps one :class:`SnapshotEncoder` per mode (or per client) and calls
``encode(snapshot, baseline_seq)`` with the newest seq that client acknowledged; the
client keeps one :class:`SnapshotDecoder` and calls ``decode(frame)``. Both keep a
bounded history of snapshots keyed by seq; a baseline the encoder no longer holds gives
a key frame (no baseline), which every client can decode.

Units: metres, radians, seconds. Positions are body origins in the world frame;
orientations are unit quaternions (x, y, z, w) rotating body frame to world frame;
velocities are in the world frame.

Frame layout
============

All integers are unsigned and little-endian unless stated. A frame is a 56-byte header
followed by a zlib stream (RFC 1950, any compression level) of the *payload*.

Header::

    offset size type     field
    0      2    bytes    magic, b"WS"
    2      1    uint8    version, VERSION (2; a decoder also reads 1, which has no
                         RANGE_CODED flag)
    3      1    uint8    mode: 0 = compressed, 1 = full
    4      1    uint8    flags: bit 0 BASELINE (delta-coded against snapshot `baseline`),
                         bit 1 SAME_IDS (the body ids are the baseline's; only with
                         BASELINE), bit 2 RANGE_CODED (the body state is one
                         range-coded table, see "Range-coded body state"; compressed
                         mode, version 2 only); bits 3-7 reserved, 0
    5      1    uint8    orientation bits b: 6..16 in compressed mode, 0 in full mode
    6      2    uint16   predictor distance D: 0, or 1..65535 when the body state is
                         coded against a linear extrapolation (see "Prediction"); only
                         in compressed mode with BASELINE
    8      4    uint32   seq: this snapshot's sequence number
    12     4    uint32   baseline: seq of the baseline snapshot; 0 without BASELINE
    16     8    uint64   step: the world's step count
    24     8    float64  time: simulated time, s
    32     8    float64  position resolution r, m: finite and > 0 in compressed mode,
                         0.0 in full mode
    40     4    uint32   N: number of bodies (at most 10,000,000)
    44     4    uint32   payload length: bytes of the payload once decompressed
    48     8    float64  wall time: the server's clock (Unix time, s) when it captured
                         the state; end-to-end delay = receipt time - wall time on one
                         machine (0.0 when unknown)
    56     ...  bytes    zlib stream of the payload (the rest of the frame)

Payload building blocks:

- *stream* of n values (n known from context): one uint8 P (0..8, the number of bytes
  each value needs), then P *byte planes* of n bytes each: plane k holds byte k (bits
  8k..8k+7) of every value, in body order; the bytes above P are 0. A stream of zeros
  is the single byte 0. Planes group alike bytes, which zlib compresses well.
- *zigzag*: a signed residual d is stored as the unsigned (d << 1) XOR (d >> 63)
  (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...), so small magnitudes need few bytes.
- *id gaps*: ascending ids i_0 < i_1 < ... are stored as a stream (P <= 4) of
  g_0 = i_0 and g_k = i_k - i_(k-1) - 1; consecutive ids give zeros.

Payload, in order:

1. Body ids (uint32, strictly ascending):

   - no BASELINE (key frame): id gaps of the N ids;
   - BASELINE and SAME_IDS: nothing (N equals the baseline's count);
   - BASELINE without SAME_IDS: a keep mask of ceil(Nb / 8) bytes (Nb: the baseline's
     count; bit i, least significant bit first, is 1 when the baseline's i-th body is
     still present; padding bits 0), a uint32 A (bodies added), and the id gaps of the
     A added ids (none of them in the baseline). The ids are the kept and the added
     ones, merged in ascending order, N in all.

2. Body state, in id order. Each body present in the baseline (same id) is coded
   against the baseline's value of that body, any other body against zero.

   Compressed mode, 7 streams of N values (the baseline's values below are its
   predicted values when D > 0, see "Prediction"):

   - 3 streams x, y, z: zigzag of p - p_base, where p = round(position / r) (round
     half to even) is an int64 with |p| < 2**40, and p_base the baseline's;
   - 1 stream: (i - i_base) mod 4, where i (0..3) is the index of the quaternion's
     largest-magnitude component (the encoder takes the first on a tie);
   - 3 streams: zigzag of u - u_base for the three other components, in their
     (x, y, z, w) order after the quaternion's sign is chosen to make component i
     positive: u = round((c * sqrt(2) + 1) / 2 * (2**b - 1)), in 0 .. 2**b - 1.

   With RANGE_CODED, the same 7 residuals per body (the index one as (i - i_base)
   mod 4, the others signed, not zigzagged) are instead one range-coded table that
   fills the rest of the payload (see below).

   The decoder rebuilds position = p * r, the three components
   c = (u * 2 / (2**b - 1) - 1) / sqrt(2), the largest as sqrt(max(0, 1 - sum c**2)),
   and normalises the quaternion. Velocities are not sent.

   Full mode, 13 streams of N values: the IEEE-754 float64 bit patterns (as uint64) of
   position x, y, z, orientation x, y, z, w, linear velocity x, y, z and angular
   velocity x, y, z, each XOR the baseline's bit pattern of the same quantity. The
   decoder reproduces the float64 values exactly.

Prediction (D > 0): let F be the baseline and B the snapshot that F's own frame was
delta-coded against, whose seq must be F's seq - D (a decoder that decoded F against
another snapshot, or as a key frame, refuses the frame). With den = F.step - B.step and
num = step - F.step, both in 1..65535 and num <= 16 den, each body of F gets an int64
motion m per column: F - B for its 3 position integers, and for its 3 orientation
integers when the largest-component index is the same in F and B; 0 for the index, and
0 throughout for a body absent from B. The body's reference is then
F + floor(m * num / den) (floor: rounds toward negative infinity; the product fits in
int64), with F's index. A body moving at constant velocity then has residuals near 0:
over the first 15 s of the boxes3000 scene at 60 Hz this makes frames 38 % smaller when
the baseline is the previous snapshot, 22 % when it is 4 snapshots old. An encoder
predicts only from a baseline it has coded against a single basis (a seq encoded for
several clients against different baselines is never a predicting baseline), so the
decoder's basis always matches.

Range-coded body state (RANGE_CODED): a table of N rows (bodies, in id order) by 7
columns (the residuals above, in that order) coded column by column, rows in order,
with the adaptive binary range coder of ``cpp/src/codec/residual_coder.cpp``:

- Decoder state: range = 2**32 - 1, code = the first 4 bytes, big-endian. To decode a
  bit with probability p0 (of a 0, in 1/65536): bound = (range >> 16) * p0; if code <
  bound the bit is 0 and range = bound, else it is 1, code -= bound and range -=
  bound. Then the probability adapts: with s = min(1 + u, 4) where u (0..3) counts its
  earlier updates (saturating at 3), p0 -= p0 >> s after a 1 and p0 += (65536 - p0) >>
  s after a 0, then p0 is clamped to 32 .. 65504. A *plain* bit: range >>= 1; the bit
  is 1 if code >= range (then code -= range). After either, while range < 2**24:
  range = (range << 8) mod 2**32 and code = ((code << 8) | the next byte) mod 2**32.
  The table must consume the stream exactly: reading past its end, or leaving bytes
  after it, refuses the frame. Every probability starts at p0 = 32768, u = 0, in every
  frame.
- A value v: its class k = bit length of |v| (0..62) in unary, "k > j" for j = 0,
  1, ... until a 0 or 20 ones, each bit with probability classes[column][ctx][j];
  after 20 ones, k = 20 + 6 plain bits (most significant first; k > 62 refuses the
  frame). For k > 0: the sign (1 = negative) with probability
  signs[column][sp][sn][sf], then the bits of |v| below its leading one, most
  significant first: the first two (those that exist) with probabilities
  tops[column][k][0] and [1], the others plain.
- ctx = (min((a + 2 b + n + 1) // 2, 23), min(f, 3)) with a the bit length of the
  body's motion m in this column (module text above; 0 without prediction), b that of
  this body's value in the previous column (0 for columns 0 and 4, which start a
  group), n that of the previous body's value in this column (0 for the first body),
  all three capped at 15, and f that of the body's *previous residual*: the residual
  the baseline's own frame carried for this body in this column (its frame had a
  baseline whenever this one predicts), clipped to -8..8; 0 without prediction, for a
  body absent from the baseline, or for a baseline key frame. sp, sn and sf are the
  signs (0 zero, 1 positive, 2 negative) of the previous column's value, the previous
  body's value and the previous residual.

Deltas are always taken against the *quantized* values (and predictions made from
them), which client and server hold identically, so quantization errors never
accumulate along a chain of deltas: every decoded snapshot equals the quantization of
the original.

Checks a decoder makes (any failure refuses the whole frame, and changes nothing):
the header's fields as above; N at most its cap (10,000,000 by default) and the
payload length at most 1032 times the compressed length (deflate's largest ratio) and
at most what N bodies can need, 12 + 53 N + ceil(Nb / 8) bytes in compressed mode and
18 + 108 N + ceil(Nb / 8) in full mode, before anything is allocated or inflated; the
zlib stream inflates to exactly the payload length and ends the frame; the payload is
consumed exactly; P <= 8 (<= 4 for id gaps, <= 1 for the index stream); ids within
uint32 and, in a delta, added ids new to the baseline and kept + added = N; a baseline
that is held, of the same mode, resolution and orientation bits, and for D > 0 decoded
against seq baseline - D, with step gaps in range; residuals below 2**62 in magnitude,
positions below 2**40 units, components within 0 .. 2**b - 1, index residuals within
0..3; full-mode values finite.
"""
from __future__ import annotations

import math
import struct
import zlib
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._core import codec as _codec

__all__ = ["VERSION", "MAX_BODIES", "MAX_POSITION_UNITS", "HEADER_SIZE", "Snapshot",
           "SnapshotEncoder", "SnapshotDecoder", "SnapshotError", "frame_info",
           "orientation_error_bound"]

#: Snapshot frame format version, written in every header. Version 2 added the
#: RANGE_CODED flag; a decoder reads versions 1 and 2.
VERSION = 2
_READS_VERSIONS = (1, 2)
#: The header's magic bytes.
MAGIC = b"WS"
#: The most bodies a frame may carry; a decoder refuses larger counts before allocating.
MAX_BODIES = 10_000_000
#: Quantized positions must satisfy |round(x / resolution)| < MAX_POSITION_UNITS; at the
#: default resolution of 1 mm that is 1.1e9 m, far beyond any scene.
MAX_POSITION_UNITS = 2 ** 40

_HEADER = struct.Struct("<2sBBBBHIIQddIId")
#: Size of the fixed frame header, bytes.
HEADER_SIZE = _HEADER.size  # 56

_MODES = {"compressed": 0, "full": 1}
_MODE_NAMES = {v: k for k, v in _MODES.items()}
_FLAG_BASELINE = 0x01
_FLAG_SAME_IDS = 0x02
_FLAG_RANGE = 0x04
_KNOWN_FLAGS = _FLAG_BASELINE | _FLAG_SAME_IDS | _FLAG_RANGE
# The range-coded table's column groups (bit c: column c starts one): positions 0-2 with
# the index 3 after them, then the three orientation components 4-6.
_RANGE_GROUPS = 0b10001
# Bytes a range-coded value can take at most: 20 unary class bits, the 6-bit escape, the
# sign and 2 modelled mantissa bits at up to 11 bits each (probabilities are kept at or
# above 32/65536), and 59 plain bits: 318 bits.
_RANGE_VALUE_BYTES = 40
_CODERS = ("range", "zlib")
_MIN_BITS, _MAX_BITS = 6, 16
_MAX_SEQ = 2 ** 32 - 1
_MAX_STEP = 2 ** 64 - 1
_MAX_ID = 2 ** 32 - 1
# Deflate cannot expand more than 1032:1 (a 258-byte match coded in 2 bits), so a
# payload length above this ratio to the compressed size is a lie; checking it refuses
# a forged header before any buffer is sized from it.
_DEFLATE_MAX_RATIO = 1032
# A residual the decoder adds to a baseline value must stay far from int64 overflow.
_MAX_RESIDUAL = 2 ** 62
_SQRT2 = math.sqrt(2.0)
# The three components kept for each index of the largest one.
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], dtype=np.intp)
_MAX_GAP = 65535  # predictor distance, and the step gaps prediction spans
_MAX_EXTRAPOLATION = 16  # num <= 16 den: bounds the predicted offset to 16 |m|
_FULL_COLUMNS = 13  # position 3, orientation 4, linear velocity 3, angular velocity 3
_COMPRESSED_STREAMS = 7
# Stream names, for error messages.
_STREAM_NAMES = (
    ("position x", "position y", "position z", "orientation index", "orientation component 1",
     "orientation component 2", "orientation component 3"),
    tuple(f"{quantity} {axis}" for quantity, axes in (("position", "xyz"), ("orientation", "xyzw"),
                                                      ("linear velocity", "xyz"),
                                                      ("angular velocity", "xyz"))
          for axis in axes))


class SnapshotError(ValueError):
    """A snapshot that cannot be encoded, or a frame that cannot be decoded; the message
    names what is wrong."""


def orientation_error_bound(bits: int) -> float:
    """Largest rotation angle (rad) between a unit quaternion and its decoding with
    `bits`-bit smallest-three components.

    Each of the three stored components is off by at most e = 1 / (sqrt(2) (2**b - 1))
    (half a quantization step over [-1/sqrt(2), 1/sqrt(2)]), so they move by at most
    sqrt(3) e together. The rebuilt largest component L = sqrt(1 - |c|**2) moves by at
    most |c| / L <= sqrt(3) times as much (L >= 1/2 because it is the largest of four
    with unit norm), so the 4-vector moves by at most 2 sqrt(3) e, and the rotation
    angle is twice the angle between the quaternions: to first order
    4 sqrt(3) e = 2 sqrt(6) / (2**b - 1), reached when the three stored components
    are all near 1/2 and all round up by half a step. The factor (1 + 4 / (2**b - 1))
    covers the second-order term (the curvature of the square root near L = 1/2, at
    most about 2.3 / (2**b - 1) relative) and float rounding. For b = 12: 1.2e-3 rad
    (0.069 degrees); the worst case found numerically is within 0.3 % of the bound.
    """
    steps = (1 << int(bits)) - 1
    return 2.0 * math.sqrt(6.0) / steps * (1.0 + 4.0 / steps)


@dataclass(eq=False)
class Snapshot:
    """The state of a scene's bodies at one instant.

    Rows are bodies, in ascending id order. Units: m, m/s, rad/s; quaternions are
    (x, y, z, w), body to world. Velocities are needed to encode in full mode and are
    None in snapshots decoded from compressed frames.

    A snapshot returned by :meth:`SnapshotDecoder.decode` owns fresh, C-contiguous,
    writable arrays; changing them does not change the decoder's baseline (it keeps its
    own quantized copy, ``_record``).
    """
    seq: int  #: snapshot sequence number, increasing per scene, 0 .. 2**32 - 1
    step: int  #: world step count, 0 .. 2**64 - 1
    time: float  #: simulated time, s
    ids: np.ndarray  #: (N,) uint32, strictly ascending body ids
    positions: np.ndarray  #: (N, 3) float64, m
    orientations: np.ndarray  #: (N, 4) float64 unit quaternions (x, y, z, w)
    linear_velocities: np.ndarray | None = None  #: (N, 3) m/s, full mode only
    angular_velocities: np.ndarray | None = None  #: (N, 3) rad/s, full mode only
    #: The server's clock (Unix time, s) at capture; 0.0 when unknown. Carried as is, for
    #: measuring end-to-end delay.
    wall_time: float = 0.0
    # The exact integers (compressed) or bit patterns (full) the decoder holds for this
    # snapshot, the values later deltas are coded against.
    _record: Any = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(eq=False)
class _Record:
    """What both ends hold of one snapshot to serve as a baseline: the exact values
    deltas are taken against (never the caller's floats, which it may change)."""
    seq: int
    step: int
    mode: int
    resolution: float
    bits: int
    ids: np.ndarray  # (N,) int64
    # Compressed mode: (N, 7) int64 columns p_x, p_y, p_z, i, u_0, u_1, u_2.
    # Full mode: (N, 13) uint64 float64 bit patterns.
    values: np.ndarray
    # The snapshot this one was delta-coded against (compressed mode): the basis of
    # its motion when it serves as a predicting baseline. Holding the basis's arrays
    # (not its record) keeps memory within two snapshots per record, with no chains.
    basis: "_Basis | None" = None
    # Encoder only: this seq was coded against more than one basis, so a client may
    # hold either version, and no frame may predict from it.
    ambiguous: bool = False
    # Compressed mode, when this snapshot's frame had a baseline: the residuals it
    # carried, clipped to -8..8 (int8; the range coder uses only their sign and bit
    # length up to 3), the context of a frame that predicts from this one.
    residual: np.ndarray | None = None

    def same_content(self, other: "_Record") -> bool:
        return (self.mode == other.mode and self.resolution == other.resolution
                and self.bits == other.bits and np.array_equal(self.ids, other.ids)
                and np.array_equal(self.values, other.values))


@dataclass(eq=False)
class _Basis:
    seq: int
    step: int
    ids: np.ndarray
    values: np.ndarray


def _basis_of(record: "_Record | None") -> "_Basis | None":
    if record is None or record.mode != 0:
        return None
    return _Basis(record.seq, record.step, record.ids, record.values)


def _prediction_gaps(base: _Record, step: int) -> tuple[int, int, int] | None:
    """(D, num, den) when a frame at `step` may predict from `base`, else None."""
    basis = base.basis
    if basis is None or base.ambiguous or base.mode != 0:
        return None
    distance, den, num = base.seq - basis.seq, base.step - basis.step, step - base.step
    if not (1 <= distance <= _MAX_GAP and 1 <= den <= _MAX_GAP
            and 1 <= num <= min(_MAX_GAP, _MAX_EXTRAPOLATION * den)):
        return None
    return distance, num, den


def _predicted(base: _Record, num: int, den: int) -> tuple[np.ndarray, np.ndarray]:
    """The baseline's values extrapolated by num / den of its motion since its basis
    (module docstring, "Prediction"), and that motion (one row per baseline body);
    exact integer arithmetic, the same at both ends."""
    basis = base.basis
    values = base.values
    if np.array_equal(basis.ids, base.ids):
        motion = values - basis.values
    else:
        present, rows = _match(basis.ids, base.ids)
        motion = np.zeros_like(values)
        motion[present] = values[present] - basis.values[rows[present]]
    # Components under different largest indices are different quantities: a body
    # whose index changed gets no orientation motion (absent bodies already have none).
    motion[motion[:, 3] != 0, 4:] = 0
    motion[:, 3] = 0
    return values + np.floor_divide(motion * num, den), motion


def _gather(table: np.ndarray, present: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
    """A baseline table's rows for this frame's bodies: row rows[i] for body i where
    present[i], zeros for a body new to the baseline; rows None (the same ids) gives
    `table` itself, not a copy (callers only read it)."""
    if rows is None:
        return table
    out = np.zeros((len(present),) + table.shape[1:], dtype=table.dtype)
    out[present] = table[rows[present]]
    return out


def _side_info(base: _Record, base_motion: np.ndarray, present: np.ndarray,
               rows: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The range coder's side information for a frame predicting from `base`, row by
    row of the frame (zeros for bodies new to the baseline): the baseline's motion and
    the residuals the baseline's own frame carried (module docstring; None for zeros)."""
    previous = None if base.residual is None else _gather(base.residual, present, rows)
    return _gather(base_motion, present, rows), previous


def _clipped(residual: np.ndarray) -> np.ndarray:
    """Residuals as a baseline keeps them for the range coder's context: -8..8, int8."""
    return np.clip(residual, -8, 8).astype(np.int8)


# ---------------------------------------------------------------------------------------
# Integer coding helpers (shared by both ends so they cannot disagree)

def _zigzag(d: np.ndarray) -> np.ndarray:
    """int64 -> uint64, small magnitudes to small values."""
    d = d.astype(np.int64, copy=False)
    return ((d << 1) ^ (d >> 63)).view(np.uint64)


def _unzigzag(z: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_zigzag`."""
    return ((z >> np.uint64(1)) ^ (np.uint64(0) - (z & np.uint64(1)))).view(np.int64)


def _put_stream(out: list, values: np.ndarray) -> None:
    """Appends a stream: plane count, then the needed byte planes of uint64 `values`."""
    values = np.ascontiguousarray(values, dtype=np.uint64)
    top = int(values.max()) if values.size else 0
    planes = (top.bit_length() + 7) // 8
    out.append(bytes((planes,)))
    if planes:
        as_bytes = values.astype("<u8", copy=False).view(np.uint8).reshape(-1, 8)
        out.append(np.ascontiguousarray(as_bytes[:, :planes].T).tobytes())


def _id_gaps(ids: np.ndarray) -> np.ndarray:
    """Gaps of ascending ids: first id, then the number of ids skipped before each."""
    return (np.diff(ids.astype(np.int64), prepend=-1) - 1).astype(np.uint64)


def _match(base_ids: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each id, whether the (ascending) baseline ids hold it and at which row."""
    if base_ids.size == 0 or ids.size == 0:
        return np.zeros(ids.size, dtype=bool), np.zeros(ids.size, dtype=np.intp)
    rows = np.minimum(np.searchsorted(base_ids, ids), base_ids.size - 1)
    return base_ids[rows] == ids, rows


class _Reader:
    """Reads a decompressed payload, every read checked against its end."""

    def __init__(self, data: bytes):
        self.data = data
        self.pos = 0

    def take(self, n: int, what: str) -> bytes:
        if n > len(self.data) - self.pos:
            raise SnapshotError(f"snapshot payload truncated in {what}: needs {n} bytes at "
                                f"offset {self.pos}, {len(self.data) - self.pos} left")
        chunk = self.data[self.pos:self.pos + n]
        self.pos += n
        return chunk

    def uint32(self, what: str) -> int:
        return int.from_bytes(self.take(4, what), "little")

    def stream(self, n: int, what: str, max_planes: int = 8) -> np.ndarray:
        planes = self.take(1, what)[0]
        if planes > max_planes:
            raise SnapshotError(f"snapshot stream {what} has {planes} byte planes, at most "
                                f"{max_planes} allowed")
        out = np.zeros((n, 8), dtype=np.uint8)
        if planes:
            raw = np.frombuffer(self.take(planes * n, what), dtype=np.uint8)
            out[:, :planes] = raw.reshape(planes, n).T
        return out.view("<u8").reshape(n).astype(np.uint64)

    def ids(self, n: int, what: str) -> np.ndarray:
        gaps = self.stream(n, what, max_planes=4)
        ids = np.cumsum(gaps.astype(np.int64) + 1) - 1  # <= 1e7 * 2**32: no overflow
        if n and ids[-1] > _MAX_ID:
            raise SnapshotError(f"snapshot {what} exceed the uint32 range: {int(ids[-1])}")
        return ids


# ---------------------------------------------------------------------------------------
# Quantization

def _quantize_positions(positions: np.ndarray, ids: np.ndarray, resolution: float) -> np.ndarray:
    """(N, 3) positions (m) -> (N, 3) int64 multiples of `resolution`, round half to even."""
    units = np.rint(positions / resolution)
    bad = ~(np.abs(units) < MAX_POSITION_UNITS)  # also catches NaN
    if bad.any():
        row = int(np.argmax(bad.any(axis=1)))
        raise SnapshotError(
            f"position {positions[row].tolist()} of body {int(ids[row])} is outside the "
            f"quantized range (|x| < {MAX_POSITION_UNITS} * {resolution} m) or not finite")
    return units.astype(np.int64)


def _quantize_orientations(q: np.ndarray, ids: np.ndarray, bits: int) -> np.ndarray:
    """(N, 4) quaternions -> (N, 4) int64: largest index, then three components."""
    norms = np.sqrt(np.einsum("ij,ij->i", q, q))
    bad = ~(np.isfinite(norms) & (norms > 0))
    if bad.any():
        row = int(np.argmax(bad))
        raise SnapshotError(f"orientation {q[row].tolist()} of body {int(ids[row])} is not a "
                            f"finite non-zero quaternion")
    q = q / norms[:, None]
    largest = np.argmax(np.abs(q), axis=1)
    # q and -q are the same rotation: pick the sign that makes the largest positive.
    sign = np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)
    rest = np.take_along_axis(q, _OTHERS[largest], axis=1) * sign[:, None]
    top = (1 << bits) - 1
    units = np.clip(np.rint((rest * _SQRT2 + 1.0) * (0.5 * top)), 0, top).astype(np.int64)
    return np.column_stack((largest.astype(np.int64), units))


def _dequantize_orientations(codes: np.ndarray, bits: int) -> np.ndarray:
    """(N, 4) int64 from :func:`_quantize_orientations` -> (N, 4) unit quaternions."""
    n = len(codes)
    top = (1 << bits) - 1
    rest = (codes[:, 1:].astype(np.float64) * (2.0 / top) - 1.0) / _SQRT2
    largest = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", rest, rest)))
    q = np.empty((n, 4), dtype=np.float64)
    index = codes[:, 0].astype(np.intp)
    np.put_along_axis(q, _OTHERS[index], rest, axis=1)
    q[np.arange(n), index] = largest
    q /= np.sqrt(np.einsum("ij,ij->i", q, q))[:, None]  # >= 1 - tiny: never zero
    return q


# ---------------------------------------------------------------------------------------
# Header

def _parse_header(frame: bytes, max_bodies: int = MAX_BODIES) -> dict:
    if isinstance(frame, (bytearray, memoryview)):
        frame = bytes(frame)
    if not isinstance(frame, bytes):
        raise SnapshotError(f"a snapshot frame must be bytes, got {type(frame).__name__}")
    if len(frame) < HEADER_SIZE:
        raise SnapshotError(f"snapshot frame truncated: {len(frame)} bytes, the header alone "
                            f"is {HEADER_SIZE}")
    (magic, version, mode, flags, bits, distance, seq, baseline, step, time_s, resolution,
     count, payload_length, wall_time) = _HEADER.unpack_from(frame)
    if magic != MAGIC:
        raise SnapshotError(f"not a snapshot frame: magic {magic!r}, expected {MAGIC!r}")
    if version not in _READS_VERSIONS:
        raise SnapshotError(f"snapshot frame version {version} is not supported (this "
                            f"decoder reads versions {_READS_VERSIONS[0]}..{_READS_VERSIONS[-1]})")
    if mode not in _MODE_NAMES:
        raise SnapshotError(f"snapshot frame mode {mode} is unknown (0 compressed, 1 full)")
    if flags & ~_KNOWN_FLAGS or (version < 2 and flags & _FLAG_RANGE):
        raise SnapshotError(f"snapshot frame flags {flags:#04x} set reserved bits")
    if flags & _FLAG_RANGE and mode != _MODES["compressed"]:
        raise SnapshotError("snapshot frame flags RANGE_CODED in full mode")
    has_baseline = bool(flags & _FLAG_BASELINE)
    if distance and (not has_baseline or mode != _MODES["compressed"]):
        raise SnapshotError(f"snapshot frame predictor distance {distance} needs a compressed "
                            f"frame with a baseline")
    same_ids = bool(flags & _FLAG_SAME_IDS)
    if same_ids and not has_baseline:
        raise SnapshotError("snapshot frame flags SAME_IDS without BASELINE")
    if not has_baseline and baseline:
        raise SnapshotError(f"snapshot key frame names baseline {baseline}; must be 0")
    if mode == _MODES["compressed"]:
        if not _MIN_BITS <= bits <= _MAX_BITS:
            raise SnapshotError(f"snapshot frame orientation bits {bits} outside "
                                f"{_MIN_BITS}..{_MAX_BITS}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise SnapshotError(f"snapshot frame position resolution {resolution} is not "
                                f"finite and > 0")
    elif bits or resolution != 0.0:
        raise SnapshotError(f"full-mode snapshot frame has orientation bits {bits} and "
                            f"resolution {resolution}; both must be 0")
    if count > max_bodies:
        raise SnapshotError(f"snapshot frame claims {count} bodies, more than the cap "
                            f"{max_bodies}")
    compressed_length = len(frame) - HEADER_SIZE
    if payload_length > _DEFLATE_MAX_RATIO * compressed_length:
        raise SnapshotError(f"snapshot frame claims a {payload_length}-byte payload from "
                            f"{compressed_length} compressed bytes, beyond zlib's "
                            f"{_DEFLATE_MAX_RATIO}:1")
    return {"version": version, "mode": _MODE_NAMES[mode], "seq": seq,
            "baseline": baseline if has_baseline else None, "same_ids": same_ids,
            "predictor_distance": distance,
            "step": step, "time": time_s, "wall_time": wall_time, "count": count,
            "position_resolution": resolution if mode == 0 else None,
            "orientation_bits": bits if mode == 0 else None, "flags": flags,
            "payload_length": payload_length, "compressed_length": compressed_length,
            "frame_length": len(frame)}


def frame_info(frame: bytes) -> dict:
    """The header fields of a snapshot frame, without decompressing or decoding its body.

    Returns a dict: ``version``, ``mode`` ("compressed" or "full"), ``seq``,
    ``baseline`` (seq of the baseline, None for a key frame), ``same_ids`` (bool),
    ``predictor_distance`` (0, or D when the frame predicts from its baseline's motion),
    ``step``, ``time`` (s), ``wall_time`` (s), ``count`` (bodies), ``position_resolution`` (m; None in full
    mode), ``orientation_bits`` (None in full mode), ``flags`` (raw), ``payload_length``
    (decompressed bytes), ``compressed_length`` and ``frame_length`` (bytes).
    Raises :class:`SnapshotError` for a header that is truncated or invalid.
    """
    return _parse_header(frame)


def _payload_bound(mode: int, count: int, base_count: int, range_coded: bool = False) -> int:
    """The largest payload a valid frame of `count` bodies can have (bytes): id gaps
    (or keep mask, added count and id gaps) plus streams of up to 8 planes, the index
    stream up to 1, or the range-coded table."""
    ids = 1 + 4 * count + (base_count + 7) // 8 + 4
    if range_coded:
        return ids + _RANGE_VALUE_BYTES * _COMPRESSED_STREAMS * count + 8
    if mode == 0:
        return ids + (_COMPRESSED_STREAMS - 1) * (1 + 8 * count) + 1 + count
    return ids + _FULL_COLUMNS * (1 + 8 * count)


# ---------------------------------------------------------------------------------------
# Encoder and decoder

def _check_int(name: str, value: Any, top: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise SnapshotError(f"snapshot {name} must be an integer, got {value!r}")
    value = int(value)
    if not 0 <= value <= top:
        raise SnapshotError(f"snapshot {name} {value} outside 0..{top}")
    return value


def _check_array(name: str, value: Any, n: int, width: int) -> np.ndarray:
    if value is None:
        raise SnapshotError(f"snapshot {name} are needed in full mode, got None")
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SnapshotError(f"snapshot {name} are not numeric: {exc}") from None
    if array.shape != (n, width):
        raise SnapshotError(f"snapshot {name} must have shape ({n}, {width}), got {array.shape}")
    return array


def _history_size(history: Any) -> int:
    if isinstance(history, bool) or not isinstance(history, (int, np.integer)) or history < 1:
        raise ValueError(f"history must be an integer >= 1, got {history!r}")
    return int(history)


class SnapshotEncoder:
    """Server side: turns snapshots into frames, delta-coded against a baseline. Not
    thread-safe: call it from one thread at a time.

    Keep one per mode (frames of one mode can be shared by every client of that mode:
    the quantization is deterministic, so a seq encoded against different baselines
    decodes to the same values), or one per client.

    Parameters:
        mode: "compressed" (quantized, delta-coded) or "full" (exact float64 values and
            velocities).
        position_resolution: quantization step of positions in compressed mode, m; the
            decoded position is within half of it of the original, per component. The
            default, 1/512 m, is the precision of Fiedler's article.
        orientation_bits: bits per smallest-three component in compressed mode (6..16);
            the rotation error is at most :func:`orientation_error_bound` of it. The
            default, 9 bits (at most 0.55 degrees), is the article's too.
        history: how many snapshots (by seq, newest kept) the encoder holds as
            possible baselines; bounds its memory.
        level: zlib compression level of the payload, -1..9.
        coder: how compressed mode codes the body state: "range" (the adaptive range
            coder with contexts, ``wmo._core.codec``: 29 % smaller than "zlib" on the
            boxes3000 stream at the default precision) or "zlib" (byte planes, left to
            the payload's zlib; the format of version 1 frames).
        predict: in compressed mode, code against the baseline's extrapolated motion
            when the baseline's own basis is known unambiguously (module docstring,
            "Prediction"); False codes against the baseline itself.
    """

    def __init__(self, mode: str = "compressed", position_resolution: float = 1 / 512,
                 orientation_bits: int = 9, history: int = 64, level: int = 1,
                 predict: bool = True, coder: str = "range"):
        if mode not in _MODES:
            raise ValueError(f"mode must be 'compressed' or 'full', got {mode!r}")
        try:
            resolution = float(position_resolution)
        except (TypeError, ValueError):
            raise ValueError(f"position_resolution must be a number, got "
                             f"{position_resolution!r}") from None
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"position_resolution must be finite and > 0 m, got "
                             f"{position_resolution!r}")
        if (isinstance(orientation_bits, bool)
                or not isinstance(orientation_bits, (int, np.integer))
                or not _MIN_BITS <= orientation_bits <= _MAX_BITS):
            raise ValueError(f"orientation_bits must be an integer in {_MIN_BITS}..{_MAX_BITS}, "
                             f"got {orientation_bits!r}")
        if (isinstance(level, bool) or not isinstance(level, (int, np.integer))
                or not -1 <= level <= 9):
            raise ValueError(f"level must be a zlib level in -1..9, got {level!r}")
        if coder not in _CODERS:
            raise ValueError(f"coder must be 'range' or 'zlib', got {coder!r}")
        self.coder = coder
        self.mode = mode
        self._mode = _MODES[mode]
        # Full mode quantizes nothing: its header carries 0 for both.
        self.position_resolution = resolution if self._mode == 0 else 0.0
        self.orientation_bits = int(orientation_bits) if self._mode == 0 else 0
        self.history = _history_size(history)
        self.level = int(level)
        self.predict = bool(predict)
        # seq -> _Record, oldest first; None marks a seq whose content changed, which
        # is never used as a baseline again (clients may hold either version).
        self._records: OrderedDict[int, _Record | None] = OrderedDict()

    def __len__(self) -> int:
        """Number of snapshots held as possible baselines (<= history)."""
        return len(self._records)

    @property
    def held(self) -> tuple[int, ...]:
        """Seqs of the snapshots held, oldest first."""
        return tuple(self._records)

    def encode(self, snap: Snapshot, baseline_seq: int | None) -> bytes:
        """A frame for `snap`, delta-coded against the snapshot with seq `baseline_seq`
        if this encoder still holds it (encoded by this encoder), else a key frame.

        Records `snap`'s quantized values under ``snap.seq``, evicting the oldest
        beyond `history`. Encoding the same seq again against another baseline is fine
        (that seq then stops serving as a predicting baseline, as clients may hold
        either version); encoding different content under a seq already held stops that
        seq from serving as a baseline at all. The velocities are read in full mode
        only.

        Raises :class:`SnapshotError` for a snapshot with bad shapes, unsorted or
        out-of-range ids, non-finite values, or positions beyond the quantized range
        (|x| / position_resolution >= 2**40); nothing is recorded then.
        """
        record = self._quantize(snap)
        base = None
        if baseline_seq is not None:
            base = self._records.get(baseline_seq)  # an unhashable seq is a caller bug
        flags = 0
        parts: list = []
        n = len(record.ids)
        if base is None:
            _put_stream(parts, _id_gaps(record.ids))
            present = np.zeros(n, dtype=bool)
            rows = np.zeros(n, dtype=np.intp)
        else:
            flags |= _FLAG_BASELINE
            if np.array_equal(base.ids, record.ids):
                flags |= _FLAG_SAME_IDS
                present, rows = np.ones(n, dtype=bool), None  # row i is the baseline's row i
            else:
                present, rows = _match(base.ids, record.ids)
                keep, _ = _match(record.ids, base.ids)
                parts.append(np.packbits(keep, bitorder="little").tobytes())
                added = record.ids[~present]
                parts.append(struct.pack("<I", len(added)))
                _put_stream(parts, _id_gaps(added))
        reference = np.zeros_like(record.values)
        # When predicting: the baseline's motion and its own residuals, row by row of
        # this frame (the range coder's side information).
        motion = previous = None
        distance = 0
        if base is not None:
            source = base.values
            gaps = _prediction_gaps(base, record.step) if self.predict else None
            if gaps is not None:
                distance = gaps[0]
                source, base_motion = _predicted(base, gaps[1], gaps[2])
                motion, previous = _side_info(base, base_motion, present, rows)
            reference = _gather(source, present, rows)
            record.basis = _basis_of(base)
        if self._mode == 0:
            delta = record.values - reference
            delta[:, 3] %= 4  # largest-component index: modular, 0..3
            if base is not None:
                record.residual = _clipped(delta)
            if self.coder == "range":
                flags |= _FLAG_RANGE
                parts.append(_codec.encode_residuals(delta, motion, previous, _RANGE_GROUPS))
            else:
                for column in range(_COMPRESSED_STREAMS):
                    if column == 3:
                        _put_stream(parts, delta[:, 3].astype(np.uint64))
                    else:
                        _put_stream(parts, _zigzag(delta[:, column]))
        else:
            delta = record.values ^ reference
            for column in range(_FULL_COLUMNS):
                _put_stream(parts, delta[:, column])
        payload = b"".join(parts)
        header = _HEADER.pack(MAGIC, VERSION, self._mode, flags, self.orientation_bits, distance,
                              record.seq, base.seq if base is not None else 0, record.step,
                              float(snap.time), self.position_resolution, n, len(payload),
                              float(snap.wall_time))
        self._remember(record)
        return header + zlib.compress(payload, self.level)

    def _quantize(self, snap: Snapshot) -> _Record:
        """Checks `snap` and returns the exact values a decoder will hold for it."""
        if not isinstance(snap, Snapshot):
            raise SnapshotError(f"expected a Snapshot, got {type(snap).__name__}")
        seq = _check_int("seq", snap.seq, _MAX_SEQ)
        step = _check_int("step", snap.step, _MAX_STEP)
        try:
            time_s = float(snap.time)
        except (TypeError, ValueError):
            raise SnapshotError(f"snapshot time must be a number, got {snap.time!r}") from None
        if not math.isfinite(time_s):
            raise SnapshotError(f"snapshot time must be finite, got {time_s}")
        ids = np.asarray(snap.ids)
        if ids.ndim != 1 or (ids.size and ids.dtype.kind not in "iu"):
            raise SnapshotError(f"snapshot ids must be a 1-d integer array, got shape "
                                f"{ids.shape} dtype {ids.dtype}")
        n = ids.size
        if n > MAX_BODIES:
            raise SnapshotError(f"snapshot has {n} bodies, more than {MAX_BODIES}")
        # Range first, on the caller's dtype: a cast of uint64 ids could wrap.
        if n and (int(ids.min()) < 0 or int(ids.max()) > _MAX_ID):
            raise SnapshotError(f"snapshot ids must lie in 0..{_MAX_ID}, got "
                                f"{int(ids.min())}..{int(ids.max())}")
        ids = ids.astype(np.int64)
        if n > 1 and not (np.diff(ids) > 0).all():
            row = int(np.argmax(np.diff(ids) <= 0))
            raise SnapshotError(f"snapshot ids must be strictly ascending: id {int(ids[row])} "
                                f"at row {row} is followed by {int(ids[row + 1])}")
        positions = _check_array("positions", snap.positions, n, 3)
        orientations = _check_array("orientations", snap.orientations, n, 4)
        if self._mode == 0:
            values = np.empty((n, _COMPRESSED_STREAMS), dtype=np.int64)
            values[:, :3] = _quantize_positions(positions, ids, self.position_resolution)
            values[:, 3:] = _quantize_orientations(orientations, ids, self.orientation_bits)
        else:
            floats = np.empty((n, _FULL_COLUMNS), dtype=np.float64)
            floats[:, 0:3] = positions
            floats[:, 3:7] = orientations
            floats[:, 7:10] = _check_array("linear_velocities", snap.linear_velocities, n, 3)
            floats[:, 10:13] = _check_array("angular_velocities", snap.angular_velocities, n, 3)
            bad = ~np.isfinite(floats).all(axis=1)
            if bad.any():
                row = int(np.argmax(bad))
                raise SnapshotError(f"body {int(ids[row])} has a non-finite position, "
                                    f"orientation or velocity: {floats[row].tolist()}")
            values = floats.view(np.uint64)
        return _Record(seq, step, self._mode, self.position_resolution, self.orientation_bits,
                       ids, values)

    def _remember(self, record: _Record) -> None:
        seq = record.seq
        old = self._records.pop(seq, record)
        if old is not record:  # this seq was encoded before
            if old is None or not old.same_content(record):
                record = None  # a seq whose content changed: never a baseline again
            elif old.ambiguous or _basis_seq(old) != _basis_seq(record):
                record.basis, record.ambiguous = None, True
        self._records[seq] = record
        while len(self._records) > self.history:
            self._records.popitem(last=False)


def _basis_seq(record: _Record) -> int | None:
    return record.basis.seq if record.basis is not None else None


class SnapshotDecoder:
    """Client side: turns frames back into snapshots. Not thread-safe.

    Holds the last `history` decoded snapshots (by seq, most recently decoded kept) as
    baselines for later frames; acknowledge to the server only seqs it decoded.

    `max_bodies` caps the body count a frame may claim (at most :data:`MAX_BODIES`).
    Decoding takes about 270 bytes per body at peak, 480 for a frame that predicts from
    its baseline's motion (330 and 540 for version 1 byte-plane frames, 540 in full
    mode; measured with tracemalloc on 100,000 bodies), and even a tiny valid frame may
    claim many bodies (bodies all at zero cost nothing), so a client
    that knows its scenes are smaller (the WMO server allows 100,000 bodies) should
    pass a lower cap.
    """

    def __init__(self, history: int = 64, max_bodies: int = MAX_BODIES):
        self.history = _history_size(history)
        if (isinstance(max_bodies, bool) or not isinstance(max_bodies, (int, np.integer))
                or not 0 <= max_bodies <= MAX_BODIES):
            raise ValueError(f"max_bodies must be an integer in 0..{MAX_BODIES}, got "
                             f"{max_bodies!r}")
        self.max_bodies = int(max_bodies)
        self._records: OrderedDict[int, _Record] = OrderedDict()

    def __len__(self) -> int:
        """Number of decoded snapshots held as baselines (<= history)."""
        return len(self._records)

    @property
    def held(self) -> tuple[int, ...]:
        """Seqs of the snapshots held, oldest first."""
        return tuple(self._records)

    def decode(self, frame: bytes) -> Snapshot:
        """The snapshot a frame carries, with fresh C-contiguous writable float64 arrays
        (velocities None in compressed mode), recorded as a baseline for later frames.

        Raises :class:`SnapshotError` naming the problem for a frame that is truncated,
        has a bad magic, version, mode or flags, names a baseline this decoder does not
        hold (or one of another mode or quantization), claims more bodies than the cap
        or a payload larger than its count allows, fails to decompress to exactly the
        stated length, or holds inconsistent counts or out-of-range values. A frame that
        fails leaves the decoder unchanged.
        """
        if isinstance(frame, (bytearray, memoryview)):
            frame = bytes(frame)
        info = _parse_header(frame, self.max_bodies)
        mode = _MODES[info["mode"]]
        n = info["count"]
        base = None
        if info["baseline"] is not None:
            base = self._records.get(info["baseline"])
            if base is None:
                raise SnapshotError(f"snapshot {info['seq']} is a delta against snapshot "
                                    f"{info['baseline']}, which this decoder does not hold "
                                    f"(it holds {len(self._records)} snapshots, newest "
                                    f"{next(reversed(self._records), None)})")
            if base.mode != mode:
                raise SnapshotError(f"snapshot {info['seq']} ({info['mode']} mode) has baseline "
                                    f"{base.seq} of the other mode")
            if mode == 0 and (base.resolution != info["position_resolution"]
                              or base.bits != info["orientation_bits"]):
                raise SnapshotError(
                    f"snapshot {info['seq']} quantizes with resolution "
                    f"{info['position_resolution']} m and {info['orientation_bits']} bits, its "
                    f"baseline {base.seq} with {base.resolution} m and {base.bits} bits")
        gaps = None
        if info["predictor_distance"]:
            gaps = _prediction_gaps(base, info["step"])
            if gaps is None or gaps[0] != info["predictor_distance"]:
                raise SnapshotError(
                    f"snapshot {info['seq']} predicts from baseline {base.seq} and its basis "
                    f"{base.seq - info['predictor_distance']}, but this decoder decoded "
                    f"{base.seq} against {_basis_seq(base)}, or the step gaps are out of range")
        base_count = len(base.ids) if base is not None else 0
        range_coded = bool(info["flags"] & _FLAG_RANGE)
        bound = _payload_bound(mode, n, base_count, range_coded)
        if info["payload_length"] > bound:
            raise SnapshotError(f"snapshot frame claims a {info['payload_length']}-byte payload; "
                                f"{n} bodies need at most {bound}")
        payload = _inflate(frame[HEADER_SIZE:], info["payload_length"])
        reader = _Reader(payload)

        # Body ids, and which rows of the baseline the bodies continue.
        if base is None:
            ids = reader.ids(n, "ids")
            present = np.zeros(n, dtype=bool)
            rows = np.zeros(n, dtype=np.intp)
        elif info["same_ids"]:
            if n != base_count:
                raise SnapshotError(f"snapshot {info['seq']} keeps its baseline's ids but counts "
                                    f"{n} bodies, the baseline {base_count}")
            ids = base.ids.copy()
            present, rows = np.ones(n, dtype=bool), None  # row i is the baseline's row i
        else:
            mask = np.frombuffer(reader.take((base_count + 7) // 8, "keep mask"), dtype=np.uint8)
            bits = np.unpackbits(mask, bitorder="little")
            if bits[base_count:].any():
                raise SnapshotError("snapshot keep mask sets padding bits")
            kept = base.ids[bits[:base_count].astype(bool)]
            added_count = reader.uint32("added count")
            if len(kept) + added_count != n:
                raise SnapshotError(f"snapshot {info['seq']} keeps {len(kept)} bodies and adds "
                                    f"{added_count}, but counts {n}")
            added = reader.ids(added_count, "added ids")
            if _match(base.ids, added)[0].any():
                raise SnapshotError(f"snapshot {info['seq']} adds ids its baseline already has")
            ids = np.sort(np.concatenate((kept, added)), kind="stable")
            present, rows = _match(base.ids, ids)

        # The values the residuals are against, one row per baseline body.
        source = motion = previous = None
        if base is not None:
            source = base.values
            if gaps is not None:
                source, base_motion = _predicted(base, gaps[1], gaps[2])
                motion, previous = _side_info(base, base_motion, present, rows)
        streams = _COMPRESSED_STREAMS if mode == 0 else _FULL_COLUMNS
        if range_coded:
            try:
                residual = _codec.decode_residuals(payload[reader.pos:], n, streams, motion, previous,
                                                   _RANGE_GROUPS)
            except ValueError as exc:
                raise SnapshotError(f"snapshot body state: {exc}") from None
        else:
            coded = np.empty((n, streams), dtype=np.uint64)
            for column in range(streams):
                coded[:, column] = reader.stream(n, _STREAM_NAMES[mode][column],
                                                 1 if mode == 0 and column == 3 else 8)
            if reader.pos != len(payload):
                raise SnapshotError(f"snapshot payload has {len(payload) - reader.pos} bytes "
                                    f"after its last stream")
            if mode == 0:
                residual = _unzigzag(np.ascontiguousarray(coded))
                residual[:, 3] = coded[:, 3].astype(np.int64)  # modular, not zigzagged

        if mode == 0:
            values = _reconstruct_compressed(residual, source, present, rows, info)
            with np.errstate(over="ignore"):  # a huge resolution: refused just below
                positions = values[:, :3].astype(np.float64) * info["position_resolution"]
            if not np.isfinite(positions).all():
                raise SnapshotError("snapshot positions overflow float64 at this resolution")
            orientations = _dequantize_orientations(values[:, 3:], info["orientation_bits"])
            linear = angular = None
            resolution, bits_ = info["position_resolution"], info["orientation_bits"]
        else:
            values = coded if base is None else coded ^ _gather(source, present, rows)
            floats = values.view(np.float64)
            if not np.isfinite(floats).all():
                raise SnapshotError("snapshot full-mode values are not all finite")
            positions = np.ascontiguousarray(floats[:, 0:3])
            orientations = np.ascontiguousarray(floats[:, 3:7])
            linear = np.ascontiguousarray(floats[:, 7:10])
            angular = np.ascontiguousarray(floats[:, 10:13])
            resolution, bits_ = 0.0, 0

        record = _Record(info["seq"], info["step"], mode, resolution, bits_, ids, values,
                         basis=_basis_of(base))
        if mode == 0 and base is not None:
            record.residual = _clipped(residual)
        self._records[record.seq] = record
        self._records.move_to_end(record.seq)
        while len(self._records) > self.history:
            self._records.popitem(last=False)
        return Snapshot(seq=info["seq"], step=info["step"], time=info["time"], wall_time=info["wall_time"],
                        ids=ids.astype(np.uint32), positions=positions,
                        orientations=orientations, linear_velocities=linear,
                        angular_velocities=angular, _record=record)


def _inflate(body: bytes, length: int) -> bytes:
    """Decompresses exactly `length` bytes, never more (a zip bomb stops there)."""
    inflater = zlib.decompressobj()
    try:
        payload = inflater.decompress(body, length)
    except zlib.error as exc:
        raise SnapshotError(f"snapshot payload does not decompress: {exc}") from None
    if len(payload) < length or not inflater.eof:
        if len(payload) < length:
            raise SnapshotError(f"snapshot payload decompresses to {len(payload)} bytes, the "
                                f"header says {length}")
        raise SnapshotError(f"snapshot payload decompresses to more than the header's "
                            f"{length} bytes")
    if inflater.unused_data:
        raise SnapshotError(f"snapshot frame has {len(inflater.unused_data)} bytes after its "
                            f"zlib stream")
    return payload


def _reconstruct_compressed(residual: np.ndarray, source: np.ndarray | None, present: np.ndarray,
                            rows: np.ndarray | None, info: dict) -> np.ndarray:
    """Reference values (the baseline's, maybe predicted) plus residuals (int64, the
    index column modular), each checked against its valid range."""
    reference = 0 if source is None else _gather(source, present, rows)
    if ((residual[:, 3] < 0) | (residual[:, 3] > 3)).any():
        raise SnapshotError("snapshot largest-component residual outside 0..3")
    # Compared both ways, not with abs(): abs of int64's minimum wraps to negative.
    if ((residual >= _MAX_RESIDUAL) | (residual <= -_MAX_RESIDUAL)).any():
        raise SnapshotError("snapshot residual out of range")
    values = reference + residual
    values[:, 3] %= 4
    if (np.abs(values[:, :3]) >= MAX_POSITION_UNITS).any():
        raise SnapshotError(f"snapshot position outside the quantized range "
                            f"(|p| < {MAX_POSITION_UNITS} resolution units)")
    top = (1 << info["orientation_bits"]) - 1
    if ((values[:, 4:] < 0) | (values[:, 4:] > top)).any():
        raise SnapshotError(f"snapshot orientation component outside 0..{top}")
    return values
