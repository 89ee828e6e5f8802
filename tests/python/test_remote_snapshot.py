"""Tests of wmo.remote.snapshot: the snapshot frames a server streams to its clients.

Covered: key and delta round trips in both modes, the stated error bounds, a 600-frame
delta chain (errors must not accumulate), body sets that change, baselines missing at
either end, garbage frames (truncated, random, forged counts, zlib bombs), bounded
histories, motion prediction and its safety with a shared encoder, and frame sizes for
the 3008 bodies of boxes3000.
"""
from __future__ import annotations

import math
import struct
import zlib

import functools

import numpy as np
import pytest

from wmo.remote.snapshot import (
    HEADER_SIZE, MAX_BODIES, MAX_POSITION_UNITS, VERSION, Snapshot, SnapshotDecoder,
    SnapshotEncoder, SnapshotError, frame_info, orientation_error_bound)

# Doubles carry 52 fraction bits: quantizing (x / r) and rebuilding (q * r) each round
# once, relative to |x|, so the position bound is r / 2 plus a few units of |x| * eps.
EPS = np.finfo(np.float64).eps
N_BOXES3000 = 3008  # boxes3000's dynamic boxes (47 layers of 8 x 8)


def unit_quaternions(rng, n):
    """n uniformly random unit quaternions (x, y, z, w)."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def rotation_angles(q, r):
    """Rotation angle (rad) between unit quaternions q and r, row by row, robust for
    tiny angles (arcsin of the chord, not arccos of the dot product) and blind to the
    sign (q and -q are the same rotation)."""
    sign = np.where(np.einsum("ij,ij->i", q, r) < 0, -1.0, 1.0)
    chord = np.linalg.norm(q - sign[:, None] * r, axis=1)
    return 4.0 * np.arcsin(np.minimum(1.0, chord / 2.0))


def position_tolerance(positions, resolution):
    """Half a resolution step, plus the float rounding of x / r and q * r (both
    relative to |x|); 4 eps covers both with margin."""
    return resolution / 2 + 4 * EPS * (np.abs(positions) + resolution)


def make_snapshot(rng, seq, n=50, ids=None, spread=20.0, step=None, velocities=True):
    """A snapshot of n bodies at random poses (and velocities)."""
    ids = np.arange(1, n + 1, dtype=np.uint32) if ids is None else np.asarray(ids, np.uint32)
    n = len(ids)
    return Snapshot(
        seq=seq, step=seq if step is None else step, time=seq / 60.0, ids=ids,
        positions=rng.uniform(-spread, spread, (n, 3)), orientations=unit_quaternions(rng, n),
        linear_velocities=rng.normal(size=(n, 3)) if velocities else None,
        angular_velocities=rng.normal(size=(n, 3)) if velocities else None)


def moved(snap, seq, rng, ids=None, scale=1e-2):
    """`snap` one step later: every body moved and turned a little; `ids` (a subset or
    superset) picks the bodies kept, new ones at random poses."""
    ids = snap.ids if ids is None else np.asarray(ids, dtype=np.uint32)
    n = len(ids)
    positions = rng.uniform(-20, 20, (n, 3))
    orientations = unit_quaternions(rng, n)
    old = np.isin(ids, snap.ids)
    rows = np.searchsorted(snap.ids, ids)
    positions[old] = snap.positions[rows[old]] + rng.normal(scale=scale, size=(old.sum(), 3))
    q = snap.orientations[rows[old]] + rng.normal(scale=scale, size=(old.sum(), 4))
    orientations[old] = q / np.linalg.norm(q, axis=1)[:, None]
    return Snapshot(seq=seq, step=snap.step + 1, time=snap.time + 1 / 60, ids=ids,
                    positions=positions, orientations=orientations,
                    linear_velocities=rng.normal(size=(n, 3)),
                    angular_velocities=rng.normal(size=(n, 3)))


def assert_fresh_arrays(snap):
    """Decoded arrays must be the caller's to keep and change."""
    arrays = [snap.positions, snap.orientations]
    if snap.linear_velocities is not None:
        arrays += [snap.linear_velocities, snap.angular_velocities]
    for array in arrays:
        assert array.dtype == np.float64
        assert array.flags.c_contiguous and array.flags.writeable and array.flags.owndata
    assert snap.ids.dtype == np.uint32


def assert_within_bounds(decoded, original, resolution=1 / 512, bits=9):
    """Decoded within the quantization bounds (the encoder defaults: 1/512 m, 9 bits)."""
    np.testing.assert_array_equal(decoded.ids, original.ids)
    error = np.abs(decoded.positions - original.positions)
    assert (error <= position_tolerance(original.positions, resolution)).all(), error.max()
    angles = rotation_angles(decoded.orientations, original.orientations)
    assert angles.max(initial=0.0) <= orientation_error_bound(bits)
    norms = np.linalg.norm(decoded.orientations, axis=1)
    np.testing.assert_allclose(norms, 1.0, rtol=0, atol=4 * EPS)  # renormalised


def assert_identical(a, b):
    """Two decoded snapshots hold exactly the same values."""
    np.testing.assert_array_equal(a.ids, b.ids)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.orientations, b.orientations)


# ---- construction -------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, field", [
    ({"mode": "fast"}, "mode"),
    ({"position_resolution": 0.0}, "position_resolution"),
    ({"position_resolution": -1e-3}, "position_resolution"),
    ({"position_resolution": float("nan")}, "position_resolution"),
    ({"position_resolution": float("inf")}, "position_resolution"),
    ({"position_resolution": "fine"}, "position_resolution"),
    ({"orientation_bits": 5}, "orientation_bits"),
    ({"orientation_bits": 17}, "orientation_bits"),
    ({"orientation_bits": 12.0}, "orientation_bits"),
    ({"orientation_bits": True}, "orientation_bits"),
    ({"history": 0}, "history"),
    ({"history": -3}, "history"),
    ({"level": 10}, "level"),
])
def test_encoder_rejects_bad_arguments_naming_field_and_value(kwargs, field):
    with pytest.raises(ValueError, match=field) as info:
        SnapshotEncoder(**kwargs)
    value = next(iter(kwargs.values()))
    assert repr(value) in str(info.value) or str(value) in str(info.value)


def test_decoder_rejects_bad_arguments():
    with pytest.raises(ValueError, match="history"):
        SnapshotDecoder(history=0)
    with pytest.raises(ValueError, match="max_bodies"):
        SnapshotDecoder(max_bodies=MAX_BODIES + 1)


def test_snapshot_error_is_a_value_error():
    assert issubclass(SnapshotError, ValueError)


# ---- round trips ----------------------------------------------------------------------

@pytest.mark.parametrize("resolution, bits", [(1e-3, 12), (1e-4, 16), (0.05, 6)])
def test_compressed_key_frame_round_trip_within_bounds(resolution, bits):
    rng = np.random.default_rng(1)
    snap = make_snapshot(rng, seq=7, n=400, spread=1e4, step=123456789012)  # 10 km: large
    encoder = SnapshotEncoder(position_resolution=resolution, orientation_bits=bits)
    frame = encoder.encode(snap, None)
    info = frame_info(frame)
    assert (info["version"], info["mode"], info["seq"], info["baseline"], info["count"]) == (
        VERSION, "compressed", 7, None, 400)
    assert (info["step"], info["position_resolution"], info["orientation_bits"]) == (
        123456789012, resolution, bits)
    out = SnapshotDecoder().decode(frame)
    assert (out.seq, out.step, out.time) == (7, 123456789012, snap.time)
    assert out.linear_velocities is None and out.angular_velocities is None
    assert_fresh_arrays(out)
    assert_within_bounds(out, snap, resolution, bits)


def test_compressed_delta_round_trip_equals_key_frame_decoding():
    """A delta frame must decode to exactly the values a key frame gives: deltas are
    lossless on the quantized integers."""
    rng = np.random.default_rng(2)
    encoder, decoder = SnapshotEncoder(), SnapshotDecoder()
    first = make_snapshot(rng, seq=1, n=300)
    decoder.decode(encoder.encode(first, None))
    second = moved(first, 2, rng)
    frame = encoder.encode(second, 1)
    assert frame_info(frame)["baseline"] == 1 and frame_info(frame)["same_ids"]
    out = decoder.decode(frame)
    assert_within_bounds(out, second)
    assert_identical(out, SnapshotDecoder().decode(SnapshotEncoder().encode(second, None)))


def test_orientation_error_bound_over_random_and_worst_case_quaternions():
    """10,000 random unit quaternions stay within the documented bound, and the
    bound is tight: quaternions built to hit the first-order worst case (three stored
    components near 1/2, each rounding up by half a step) come within 2 % of it."""
    rng = np.random.default_rng(3)
    for bits in (6, 8, 12, 16):
        ids = np.arange(1, 10_001, dtype=np.uint32)
        q = unit_quaternions(rng, 10_000)
        snap = Snapshot(seq=1, step=1, time=0.0, ids=ids, positions=np.zeros((10_000, 3)),
                        orientations=q)
        out = SnapshotDecoder().decode(SnapshotEncoder(orientation_bits=bits).encode(snap, None))
        bound = orientation_error_bound(bits)
        assert rotation_angles(out.orientations, q).max() <= bound
        # q and -q are one rotation: the decoding must not depend on the sign.
        flipped = Snapshot(seq=1, step=1, time=0.0, ids=ids, positions=np.zeros((10_000, 3)),
                           orientations=-q)
        out_flipped = SnapshotDecoder().decode(
            SnapshotEncoder(orientation_bits=bits).encode(flipped, None))
        np.testing.assert_array_equal(out_flipped.orientations, out.orientations)

        steps = (1 << bits) - 1
        k = np.floor((0.5 * math.sqrt(2) + 1) / 2 * steps - 0.5) - np.arange(4)
        v = ((k + 0.5 + 1e-9) * 2 / steps - 1) / math.sqrt(2)  # just above a half step
        worst = np.column_stack([v, v, v, np.sqrt(1 - 3 * v * v)])
        snap = Snapshot(seq=1, step=1, time=0.0, ids=np.arange(4, dtype=np.uint32),
                        positions=np.zeros((4, 3)), orientations=worst)
        out = SnapshotDecoder().decode(SnapshotEncoder(orientation_bits=bits).encode(snap, None))
        angles = rotation_angles(out.orientations, worst)
        assert angles.max() <= bound
        assert angles.max() >= (0.9 if bits <= 6 else 0.98) * bound  # 6 bits: curvature


def test_full_mode_is_exact_bit_for_bit():
    rng = np.random.default_rng(4)
    encoder, decoder = SnapshotEncoder("full"), SnapshotDecoder()
    first = make_snapshot(rng, seq=1, n=200)
    # Values whose bits a careless codec loses: signed zero, subnormals, extremes.
    first.positions[0] = (-0.0, 5e-324, 1.7976931348623157e308)
    first.linear_velocities[1] = (-0.0, -5e-324, -1e-300)
    first.orientations[2] = (0.1, 0.2, 0.3, 0.9)  # not unit: full mode passes it as is
    snaps = [first, moved(first, 2, rng), None]
    snaps[2] = moved(snaps[1], 3, rng, ids=np.r_[np.arange(1, 150), np.arange(205, 230)])
    for k, snap in enumerate(snaps):
        frame = encoder.encode(snap, k if k else None)
        assert frame_info(frame)["mode"] == "full"
        out = decoder.decode(frame)
        assert_fresh_arrays(out)
        for name in ("positions", "orientations", "linear_velocities", "angular_velocities"):
            np.testing.assert_array_equal(getattr(out, name).view(np.uint64),
                                          np.asarray(getattr(snap, name)).view(np.uint64))
        np.testing.assert_array_equal(out.ids, snap.ids)
    assert frame_info(frame)["baseline"] == 2


def test_full_mode_needs_velocities():
    rng = np.random.default_rng(5)
    snap = make_snapshot(rng, seq=1, n=5, velocities=False)
    with pytest.raises(SnapshotError, match="linear_velocities"):
        SnapshotEncoder("full").encode(snap, None)
    SnapshotEncoder("compressed").encode(snap, None)  # compressed mode ignores them


def test_600_delta_chain_does_not_accumulate_error():
    """Each frame is a delta (often predicted) against the previous one; if deltas were
    taken against unquantized values, rounding errors would add up over the chain.
    After 600 frames the error is still within the single-quantization bound, and the
    decoding equals a key-frame decoding of the same snapshot exactly."""
    rng = np.random.default_rng(6)
    n = 100
    encoder, decoder = SnapshotEncoder(), SnapshotDecoder()
    base_pos = rng.uniform(-10, 10, (n, 3))
    velocity = rng.normal(scale=0.3, size=(n, 3))  # m/s: slow drifts, sub-mm per step
    axis = unit_quaternions(rng, n)[:, :3]
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    spin = rng.normal(scale=0.5, size=n)  # rad/s
    q0 = unit_quaternions(rng, n)
    ids = np.arange(10, 10 + n, dtype=np.uint32)
    predicted = 0
    for k in range(601):
        t = k / 60.0
        half = spin * t / 2
        turn = np.column_stack([axis * np.sin(half)[:, None], np.cos(half)])
        x1, y1, z1, w1 = turn.T
        x2, y2, z2, w2 = q0.T
        q = np.column_stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                             w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                             w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                             w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])
        snap = Snapshot(seq=k + 1, step=k, time=t, ids=ids, positions=base_pos + velocity * t,
                        orientations=q)
        frame = encoder.encode(snap, k if k else None)
        predicted += frame_info(frame)["predictor_distance"] > 0
        out = decoder.decode(frame)
        assert_within_bounds(out, snap)
    assert frame_info(frame)["baseline"] == 600
    assert predicted >= 598  # all but the key frame and the first delta predict
    assert_identical(out, SnapshotDecoder().decode(SnapshotEncoder().encode(snap, None)))


# ---- the documented format ----------------------------------------------------------

def reference_decode(frame, held):
    """A second decoder, written from the module docstring's layout alone (plain Python
    integers, one body at a time), so that the text PROTOCOL.md copies is checked
    against what the encoder writes. `held`: seq -> what an earlier call returned.
    Returns (seq, ids, positions, orientations) or, in full mode, the 13 float64
    columns instead of positions and orientations."""
    (magic, version, mode, flags, bits, distance, seq, baseline, step, _time, resolution,
     count, payload_length, wall_time) = struct.unpack_from("<2sBBBBHIIQddIId", frame, 0)
    assert magic == b"WS" and version in (1, 2)
    payload = zlib.decompress(frame[56:])
    assert len(payload) == payload_length
    pos = 0

    def stream(n):
        nonlocal pos
        planes = payload[pos]
        pos += 1
        values = [0] * n
        for k in range(planes):
            for i in range(n):
                values[i] |= payload[pos + k * n + i] << (8 * k)
        pos += planes * n
        return values

    def ids_from_gaps(gaps):
        ids, last = [], -1
        for gap in gaps:
            last += gap + 1
            ids.append(last)
        return ids

    base = held[baseline] if flags & 1 else None
    if base is None:
        ids = ids_from_gaps(stream(count))
    elif flags & 2:
        ids = list(base["ids"])
    else:
        mask = payload[pos:pos + (len(base["ids"]) + 7) // 8]
        pos += len(mask)
        kept = [i for k, i in enumerate(base["ids"]) if mask[k // 8] >> (k % 8) & 1]
        added = int.from_bytes(payload[pos:pos + 4], "little")
        pos += 4
        ids = sorted(kept + ids_from_gaps(stream(added)))
    reference = dict(zip(base["ids"], base["values"])) if base else {}
    motions, previous = {}, {}
    if distance:
        basis = base["basis"]
        assert basis["seq"] == baseline - distance
        num, den = step - base["step"], base["step"] - basis["step"]
        before = dict(zip(basis["ids"], basis["values"]))
        for body, now in reference.items():
            motion = [0] * 7
            if body in before:
                then = before[body]
                motion[0:3] = [now[c] - then[c] for c in range(3)]
                if now[3] == then[3]:
                    motion[4:7] = [now[c] - then[c] for c in range(4, 7)]
            reference[body] = [now[c] + (motion[c] * num) // den for c in range(7)]  # floor
            motions[body] = motion
        previous = {body: [max(-8, min(8, r)) for r in residual] for body, residual in base["residuals"].items()}

    if flags & 4:  # RANGE_CODED: signed residuals, the index one modular
        table = range_decode_reference(payload[pos:], [motions.get(body, [0] * 7) for body in ids],
                                       [previous.get(body, [0] * 7) for body in ids])
        columns = [[v if c == 3 else (v << 1) ^ (v >> 63) for v in table[c]] for c in range(7)]
    else:
        columns = [stream(count) for _ in range(7 if mode == 0 else 13)]
        assert pos == len(payload)
    assert len(ids) == count

    values, residuals = [], {}
    for i, body in enumerate(ids):
        ref = reference.get(body, [0] * len(columns))
        if mode == 0:
            residual = [(columns[c][i] >> 1) ^ -(columns[c][i] & 1) for c in range(7)]
            residual[3] = columns[3][i]
            row = [ref[c] + residual[c] for c in range(7)]
            row[3] %= 4
            if base is not None:
                residuals[body] = residual
        else:
            row = [ref[c] ^ columns[c][i] for c in range(13)]
        values.append(row)
    held[seq] = {"seq": seq, "step": step, "ids": ids, "values": values, "basis": base, "residuals": residuals}

    if mode == 1:
        floats = [[struct.unpack("<d", struct.pack("<Q", v))[0] for v in row] for row in values]
        return seq, ids, np.array(floats).reshape(-1, 13)
    top = (1 << bits) - 1
    positions, orientations = [], []
    for row in values:
        positions.append([p * resolution for p in row[:3]])
        rest = [(u * 2 / top - 1) / math.sqrt(2) for u in row[4:]]
        q = rest[:row[3]] + [math.sqrt(max(0.0, 1 - sum(c * c for c in rest)))] + rest[row[3]:]
        norm = math.sqrt(sum(c * c for c in q))
        orientations.append([c / norm for c in q])
    return (seq, ids, np.array(positions).reshape(-1, 3), np.array(orientations).reshape(-1, 4))


def range_decode_reference(data, motion, previous):
    """The range-coded table of the module docstring ("Range-coded body state"),
    decoded bit by bit in plain Python: 7 columns of len(motion) values. `motion` and
    `previous`: one list of 7 values per row."""
    rows, pos = len(motion), 0
    state = {"range": 2 ** 32 - 1, "code": int.from_bytes(data[:4], "big")}
    pos = 4

    def normalize():
        nonlocal pos
        while state["range"] < 2 ** 24:
            assert pos < len(data), "read past the end"
            state["range"] = (state["range"] << 8) % 2 ** 32
            state["code"] = ((state["code"] << 8) | data[pos]) % 2 ** 32
            pos += 1

    def bit(prob):  # prob: [p0, updates]
        bound = (state["range"] >> 16) * prob[0]
        if state["code"] < bound:
            state["range"], b = bound, 0
        else:
            state["code"] -= bound
            state["range"] -= bound
            b = 1
        shift = min(1 + prob[1], 4)
        prob[1] = min(prob[1] + 1, 3)
        prob[0] = prob[0] - (prob[0] >> shift) if b else prob[0] + ((65536 - prob[0]) >> shift)
        prob[0] = min(max(prob[0], 32), 65504)
        normalize()
        return b

    def plain(count):
        value = 0
        for _ in range(count):
            state["range"] >>= 1
            b = int(state["code"] >= state["range"])
            if b:
                state["code"] -= state["range"]
            value = (value << 1) | b
            normalize()
        return value

    def fresh():
        return [32768, 0]

    classes = {}
    signs = {}
    tops = {}
    table = [[0] * rows for _ in range(7)]

    def length(v):
        return min(abs(v).bit_length(), 15)

    def sign(v):
        return 0 if v == 0 else (1 if v > 0 else 2)

    for c in range(7):
        for i in range(rows):
            previous_column = 0 if c in (0, 4) else table[c - 1][i]
            previous_row = table[c][i - 1] if i else 0
            ctx = (min((length(motion[i][c]) + 2 * length(previous_column) + length(previous_row) + 1) // 2, 23),
                   min(length(previous[i][c]), 3))
            k = 0
            while k < 20 and bit(classes.setdefault((c, ctx, k), fresh())):
                k += 1
            if k == 20:
                k += plain(6)
            assert k <= 62
            if k == 0:
                continue
            negative = bit(signs.setdefault((c, sign(previous_column), sign(previous_row), sign(previous[i][c])),
                                            fresh()))
            u = 1
            for j in range(min(k - 1, 2)):
                u = (u << 1) | bit(tops.setdefault((c, k, j), fresh()))
            if k > 3:
                u = (u << (k - 3)) | plain(k - 3)
            table[c][i] = -u if negative else u
    assert pos == len(data), "bytes after the table"
    return table


@pytest.mark.parametrize("coder", ["range", "zlib"])
def test_frames_follow_the_documented_layout(coder):
    """Key, same-ids, predicted and id-changing frames in both modes decode the same
    with the reference decoder: exactly in full mode, to a few ulps in compressed mode
    (the float formulas may round in another order)."""
    rng = np.random.default_rng(23)
    snaps = [make_snapshot(rng, seq=1, n=30)]
    for seq, ids in ((2, None), (3, None), (4, np.r_[1:10, 15:31, 40, 41]), (5, None),
                     (6, np.r_[1:5, 40, 77])):
        snaps.append(moved(snaps[-1], seq, rng, ids=ids))
    for mode in ("compressed", "full"):
        encoder, decoder, held = SnapshotEncoder(mode, coder=coder), SnapshotDecoder(), {}
        distances = []
        for k, snap in enumerate(snaps):
            frame = encoder.encode(snap, k if k else None)
            distances.append(frame_info(frame)["predictor_distance"])
            out = decoder.decode(frame)
            ref = reference_decode(frame, held)
            assert ref[0] == out.seq and ref[1] == out.ids.tolist()
            if mode == "full":
                columns = np.hstack([out.positions, out.orientations, out.linear_velocities,
                                     out.angular_velocities])
                np.testing.assert_array_equal(ref[2].view(np.uint64), columns.view(np.uint64))
            else:
                np.testing.assert_allclose(ref[2], out.positions, rtol=4 * EPS, atol=0)
                np.testing.assert_allclose(ref[3], out.orientations, rtol=0, atol=4 * EPS)
        assert distances == ([0, 0, 1, 1, 1, 1] if mode == "compressed" else [0] * 6)


# ---- body sets ------------------------------------------------------------------------

def test_body_set_changes_between_baseline_and_snapshot():
    rng = np.random.default_rng(7)
    encoder, decoder = SnapshotEncoder(), SnapshotDecoder()
    full_encoder, full_decoder = SnapshotEncoder("full"), SnapshotDecoder()
    id_sets = [
        np.arange(1, 101),                                   # key frame
        np.arange(1, 101),                                   # unchanged: SAME_IDS
        np.r_[np.arange(1, 40), np.arange(60, 101)],         # removed from the middle
        np.r_[np.arange(1, 40), 45, 50, np.arange(60, 101), 5000, 70000],  # added between
        np.array([2, 3, 5, 7, 11, 13, 45, 70000, 4294967295]),  # most removed, max id
        np.array([], dtype=np.int64),                        # all removed
        np.array([0, 1, 2]),                                 # from nothing
        np.array([0, 1, 2]),                                 # and on, with prediction
        np.array([1, 2, 3]),                                 # 0 removed, 3 added
    ]
    snap = make_snapshot(rng, seq=1, ids=id_sets[0])
    predicted = 0
    for k, ids in enumerate(id_sets):
        if k:
            snap = moved(snap, k + 1, rng, ids=ids)
        frame = encoder.encode(snap, k if k else None)
        info = frame_info(frame)
        predicted += info["predictor_distance"] > 0
        assert info["count"] == len(ids)
        assert info["same_ids"] == (k > 0 and np.array_equal(ids, id_sets[k - 1]))
        out = decoder.decode(frame)
        assert out.ids.dtype == np.uint32 and out.ids.shape == (len(ids),)
        assert_within_bounds(out, snap)
        out_full = full_decoder.decode(full_encoder.encode(snap, k if k else None))
        np.testing.assert_array_equal(out_full.ids, ids)
        np.testing.assert_array_equal(out_full.positions, snap.positions)
    # Every delta after the first predicts, across the id changes of its basis too.
    assert predicted == len(id_sets) - 2


def test_id_change_costs_little():
    """Removing one body of 3008 sends a keep mask (zlib squeezes its ones) and no ids."""
    rng = np.random.default_rng(8)
    encoder = SnapshotEncoder()
    snap = make_snapshot(rng, seq=1, n=N_BOXES3000)
    encoder.encode(snap, None)
    keep = np.r_[0:1000, 1001:N_BOXES3000]
    fewer = Snapshot(seq=2, step=2, time=0.0, ids=snap.ids[keep], positions=snap.positions[keep],
                     orientations=snap.orientations[keep])
    frame = encoder.encode(fewer, 1)
    print(f"\n3008 bodies at rest, one removed: {len(frame)} bytes")
    assert not frame_info(frame)["same_ids"]
    assert len(frame) < 200  # measured 78: header 56 + a few bytes of mask and zeros


@pytest.mark.parametrize("ids", [[3, 2, 5], [1, 1, 2], [-1, 2], [0, 2 ** 32], [[1, 2]]])
def test_encoder_refuses_ids_not_strictly_ascending_uint32(ids):
    n = len(np.ravel(ids))
    snap = Snapshot(seq=1, step=1, time=0.0, ids=np.array(ids), positions=np.zeros((n, 3)),
                    orientations=np.tile([0.0, 0, 0, 1], (n, 1)))
    with pytest.raises(SnapshotError, match="ids"):
        SnapshotEncoder().encode(snap, None)


@pytest.mark.parametrize("change, match", [
    (lambda s: s.positions.__setitem__((1, 0), np.nan), "position"),
    (lambda s: s.positions.__setitem__((1, 0), 3e9), "position"),  # > 2**40 / 512 m
    (lambda s: s.orientations.__setitem__(1, 0.0), "orientation"),
    (lambda s: setattr(s, "positions", np.zeros((3, 2))), "positions"),
    (lambda s: setattr(s, "orientations", np.zeros((4, 4))), "orientations"),
    (lambda s: setattr(s, "seq", -1), "seq"),
    (lambda s: setattr(s, "seq", 2 ** 32), "seq"),
    (lambda s: setattr(s, "step", 2 ** 64), "step"),
    (lambda s: setattr(s, "step", 1.5), "step"),
    (lambda s: setattr(s, "time", float("inf")), "time"),
])
def test_encoder_refuses_bad_snapshots(change, match):
    rng = np.random.default_rng(9)
    snap = make_snapshot(rng, seq=1, n=3)
    change(snap)
    encoder = SnapshotEncoder()
    with pytest.raises(SnapshotError, match=match):
        encoder.encode(snap, None)
    assert len(encoder) == 0  # nothing recorded


@pytest.mark.parametrize("coder", ["range", "zlib"])
def test_position_range_limit(coder):
    """|x| / resolution must stay below 2**40: at 1 mm, 1.1e9 m passes the limit."""
    inside = (MAX_POSITION_UNITS - 1) * 1e-3
    snap = Snapshot(seq=1, step=1, time=0.0, ids=np.array([1, 2], np.uint32),
                    positions=np.array([[inside, -inside, 0.0], [1e4, -1e4, 1e4]]),
                    orientations=np.tile([0.0, 0, 0, 1], (2, 1)))
    encoder = SnapshotEncoder(position_resolution=1e-3, coder=coder)
    decoder = SnapshotDecoder()
    out = decoder.decode(encoder.encode(snap, None))
    assert_within_bounds(out, snap, resolution=1e-3)
    # The largest residuals a delta can carry: from +inside to -inside and back.
    flipped = Snapshot(seq=2, step=2, time=0.0, ids=snap.ids, positions=-snap.positions,
                       orientations=snap.orientations)
    assert_within_bounds(decoder.decode(encoder.encode(flipped, 1)), flipped, resolution=1e-3)
    snap.positions[0, 0] = MAX_POSITION_UNITS * 1e-3
    with pytest.raises(SnapshotError, match="body 1"):
        encoder.encode(snap, None)


# ---- baselines and histories ----------------------------------------------------------

def test_encoder_sends_a_key_frame_for_a_baseline_it_does_not_hold():
    rng = np.random.default_rng(10)
    encoder = SnapshotEncoder(history=4)
    snaps = [make_snapshot(rng, seq=k, n=20) for k in range(1, 11)]
    for snap in snaps:
        encoder.encode(snap, None)
    assert encoder.held == (7, 8, 9, 10)
    decoder = SnapshotDecoder()
    for baseline in (3, 99, None):  # evicted, never encoded, none asked
        frame = encoder.encode(snaps[-1], baseline)
        assert frame_info(frame)["baseline"] is None
        assert_within_bounds(decoder.decode(frame), snaps[-1])
    assert frame_info(encoder.encode(snaps[-1], 8))["baseline"] == 8


def test_decoder_refuses_a_delta_against_a_baseline_it_does_not_hold():
    rng = np.random.default_rng(11)
    encoder = SnapshotEncoder()
    first = make_snapshot(rng, seq=1, n=20)
    key = encoder.encode(first, None)
    delta = encoder.encode(moved(first, 2, rng), 1)
    with pytest.raises(SnapshotError, match="does not hold"):
        SnapshotDecoder().decode(delta)
    # Evicted from a short history: refused the same way.
    decoder = SnapshotDecoder(history=1)
    decoder.decode(key)
    decoder.decode(encoder.encode(moved(first, 3, rng), None))
    assert decoder.held == (3,)
    with pytest.raises(SnapshotError, match="does not hold"):
        decoder.decode(delta)
    assert decoder.held == (3,)  # a refused frame changes nothing


def test_decoder_refuses_a_baseline_of_another_mode_or_quantization():
    rng = np.random.default_rng(12)
    snap = make_snapshot(rng, seq=1, n=10)
    later = moved(snap, 2, rng)
    for other in (SnapshotEncoder("full"), SnapshotEncoder(position_resolution=1e-2),
                  SnapshotEncoder(orientation_bits=10)):
        decoder = SnapshotDecoder()
        decoder.decode(other.encode(snap, None))
        encoder = SnapshotEncoder()
        encoder.encode(snap, None)
        with pytest.raises(SnapshotError, match="baseline 1"):
            decoder.decode(encoder.encode(later, 1))


def test_histories_stay_bounded():
    rng = np.random.default_rng(13)
    encoder, decoder = SnapshotEncoder(history=5), SnapshotDecoder(history=3)
    snap = make_snapshot(rng, seq=1, n=30)
    decoder.decode(encoder.encode(snap, None))
    for seq in range(2, 101):
        snap = moved(snap, seq, rng)
        decoder.decode(encoder.encode(snap, seq - 1))
        assert len(encoder) <= 5 and len(decoder) <= 3
    assert encoder.held == (96, 97, 98, 99, 100)
    assert decoder.held == (98, 99, 100)
    # The decoder's baselines keep no chain of older snapshots alive: a record holds
    # its own arrays and at most its basis's (for prediction).
    record = decoder.decode(encoder.encode(moved(snap, 101, rng), 100))._record
    assert record.basis.seq == 100 and not hasattr(record.basis, "basis")


def test_decoded_arrays_are_the_callers_to_change():
    """Writing into a decoded snapshot must not corrupt the decoder's baseline."""
    rng = np.random.default_rng(14)
    encoder, decoder = SnapshotEncoder(), SnapshotDecoder()
    first = make_snapshot(rng, seq=1, n=40)
    out = decoder.decode(encoder.encode(first, None))
    out.positions[:] = 1e6
    out.orientations[:] = 0.0
    out.ids[:] = 0
    second = moved(first, 2, rng)
    assert_within_bounds(decoder.decode(encoder.encode(second, 1)), second)


# ---- prediction -----------------------------------------------------------------------

def test_prediction_makes_steady_motion_free():
    """Bodies moving at different constant velocities: against the previous frame
    every body has a different delta, against the extrapolation none (up to rounding)."""
    rng = np.random.default_rng(15)
    n = 1000
    start = rng.uniform(-20, 20, (n, 3))
    velocity = rng.uniform(-0.2, 0.2, (n, 3))  # m per step: 0..200 resolution steps
    sizes = {}
    for predict in (False, True):
        encoder, decoder = SnapshotEncoder(predict=predict), SnapshotDecoder()
        for k in range(4):
            snap = Snapshot(seq=k + 1, step=10 * k, time=k / 6, ids=np.arange(n, dtype=np.uint32),
                            positions=start + velocity * k,
                            orientations=np.tile([0.0, 0, 0, 1], (n, 1)))
            frame = encoder.encode(snap, k if k else None)
            assert_within_bounds(decoder.decode(frame), snap)
        sizes[predict] = len(frame)
        assert frame_info(frame)["predictor_distance"] == (1 if predict else 0)
    print(f"\n1000 bodies at different steady velocities: {sizes[False]} bytes per delta, "
          f"{sizes[True]} predicted")
    # Residuals of -1..1 (two roundings) against deltas of up to 200 steps: measured
    # 949 against 4046 bytes.
    assert sizes[True] < 0.4 * sizes[False]


def test_shared_encoder_never_predicts_from_an_ambiguous_baseline():
    """A server encodes the newest snapshot once per distinct client baseline. Client A
    decodes seq 3 against 1, client B against 2, so neither end can tell which motion a
    client holds for seq 3: the encoder must not predict from it, and both clients
    must decode seq 4 against 3."""
    rng = np.random.default_rng(16)
    encoder = SnapshotEncoder()
    snaps = [make_snapshot(rng, seq=1, n=50)]
    for seq in (2, 3, 4):
        snaps.append(moved(snaps[-1], seq, rng))
    client_a, client_b = SnapshotDecoder(), SnapshotDecoder()
    client_a.decode(encoder.encode(snaps[0], None))
    client_b.decode(encoder.encode(snaps[0], None))
    client_b.decode(encoder.encode(snaps[1], 1))
    client_a.decode(encoder.encode(snaps[2], 1))
    client_b.decode(encoder.encode(snaps[2], 2))
    frame = encoder.encode(snaps[3], 3)
    assert frame_info(frame)["predictor_distance"] == 0
    for client in (client_a, client_b):
        assert_within_bounds(client.decode(frame), snaps[3])


def test_decoder_refuses_a_prediction_from_another_basis():
    """A client that holds seq 2 as a key frame cannot follow a frame predicting from
    seq 2's motion since seq 1: refused, not silently wrong."""
    rng = np.random.default_rng(17)
    first = make_snapshot(rng, seq=1, n=20)
    second, third = moved(first, 2, rng), None
    third = moved(second, 3, rng)
    encoder = SnapshotEncoder()
    encoder.encode(first, None)
    encoder.encode(second, 1)
    frame = encoder.encode(third, 2)
    assert frame_info(frame)["predictor_distance"] == 1
    decoder = SnapshotDecoder()
    decoder.decode(SnapshotEncoder().encode(second, None))
    with pytest.raises(SnapshotError, match="predicts"):
        decoder.decode(frame)


def test_changed_content_under_a_held_seq_is_never_a_baseline():
    rng = np.random.default_rng(18)
    encoder = SnapshotEncoder()
    first = make_snapshot(rng, seq=1, n=10)
    encoder.encode(first, None)
    encoder.encode(make_snapshot(rng, seq=1, n=10), None)  # seq 1 again, other poses
    assert frame_info(encoder.encode(moved(first, 2, rng), 1))["baseline"] is None


# ---- garbage --------------------------------------------------------------------------

def small_frames(coder="range"):
    """A key frame and a delta frame (with ids changed)."""
    rng = np.random.default_rng(19)
    encoder = SnapshotEncoder(coder=coder)
    first = make_snapshot(rng, seq=1, n=6)
    key = encoder.encode(first, None)
    delta = encoder.encode(moved(first, 2, rng, ids=[1, 2, 4, 9]), 1)
    return key, delta


def decoder_with_baseline(key):
    decoder = SnapshotDecoder()
    decoder.decode(key)
    return decoder


@pytest.mark.filterwarnings("error")  # no NumPy overflow warnings either
@pytest.mark.parametrize("coder", ["range", "zlib"])
def test_every_truncation_is_refused(coder):
    key, delta = small_frames(coder)
    for frame, decoder in ((key, SnapshotDecoder()), (delta, decoder_with_baseline(key))):
        held = decoder.held
        for length in range(len(frame)):
            with pytest.raises(SnapshotError):
                decoder.decode(frame[:length])
            assert decoder.held == held
        decoder.decode(frame)  # and the whole frame still decodes


@pytest.mark.filterwarnings("error")
def test_random_bytes_and_bit_flips_never_crash():
    """Garbage gives SnapshotError and nothing else; a flipped bit may also decode to
    another valid snapshot (zlib's Adler-32 catches most), never crash."""
    rng = np.random.default_rng(20)
    key, delta = small_frames()
    decoder = decoder_with_baseline(key)
    for _ in range(300):
        junk = rng.integers(0, 256, rng.integers(0, 200), dtype=np.uint8).tobytes()
        for frame in (junk, key[:4] + junk):  # random, and random behind a valid start
            with pytest.raises(SnapshotError):
                decoder.decode(frame)
    for frame in (key, delta):
        for bit in range(8 * len(frame)):
            flipped = bytearray(frame)
            flipped[bit // 8] ^= 1 << (bit % 8)
            try:
                decoder.decode(bytes(flipped))
            except SnapshotError:
                pass
    with pytest.raises(SnapshotError, match="bytes"):
        decoder.decode("not a frame")


@pytest.mark.filterwarnings("error")
def test_mutated_payloads_never_crash():
    """Payloads changed after zlib (so the checksum passes and the parser sees them):
    byte changes, deletions, insertions, random payloads, in key, delta, predicted and
    full frames, some with a header byte changed too. Each decodes or raises
    SnapshotError; nothing else."""
    rng = np.random.default_rng(22)
    encoder, full_encoder = SnapshotEncoder(), SnapshotEncoder("full")
    snaps = [make_snapshot(rng, seq=1, n=8)]
    snaps.append(moved(snaps[0], 2, rng, ids=[1, 2, 4, 9, 12]))
    snaps.append(moved(snaps[1], 3, rng))
    snaps.append(moved(snaps[2], 4, rng, ids=[1, 2, 4, 12, 13]))
    frames = [encoder.encode(snap, k if k else None) for k, snap in enumerate(snaps)]
    assert frame_info(frames[3])["predictor_distance"] == 1
    full = [full_encoder.encode(snaps[0], None), full_encoder.encode(snaps[1], 1)]
    cases = [(frames[k], frames[:k]) for k in range(4)] + [(full[0], []), (full[1], full[:1])]
    outcomes = {"decoded": 0, "refused": 0}
    for trial in range(1200):
        frame, before = cases[trial % len(cases)]
        payload = bytearray(zlib.decompress(frame[HEADER_SIZE:]))
        where = int(rng.integers(len(payload)))
        kind = trial // len(cases) % 4
        if kind == 0:
            payload[where] = int(rng.integers(256))
        elif kind == 1:
            del payload[where]
        elif kind == 2:
            payload.insert(where, int(rng.integers(256)))
        else:
            payload = bytearray(rng.integers(0, 256, len(payload), dtype=np.uint8).tobytes())
        header = bytearray(frame[:HEADER_SIZE])
        if rng.random() < 0.3:
            header[int(rng.integers(4, HEADER_SIZE - 4))] = int(rng.integers(256))
        mutated = forge(bytes(header) + zlib.compress(bytes(payload)), payload_length=len(payload))
        decoder = SnapshotDecoder()
        for earlier in before:
            decoder.decode(earlier)
        try:
            decoder.decode(mutated)
            outcomes["decoded"] += 1
        except SnapshotError:
            outcomes["refused"] += 1
    assert outcomes["refused"] > 0 and outcomes["decoded"] > 0  # both paths exercised


def forge(frame, **fields):
    """`frame` with header fields replaced (names as in the header layout)."""
    names = ["magic", "version", "mode", "flags", "bits", "distance", "seq", "baseline",
             "step", "time", "resolution", "count", "payload_length", "wall_time"]
    layout = struct.Struct("<2sBBBBHIIQddIId")
    values = dict(zip(names, layout.unpack_from(frame)))
    values.update(fields)
    return layout.pack(*(values[name] for name in names)) + frame[HEADER_SIZE:]


@pytest.mark.parametrize("fields, match", [
    ({"magic": b"XS"}, "magic"),
    ({"version": 3}, "version"),
    ({"version": 1}, "flags"),  # version 1 has no RANGE_CODED flag
    ({"mode": 2}, "mode"),
    ({"flags": 0x80}, "flags"),
    ({"flags": 0x02}, "SAME_IDS"),
    ({"baseline": 5}, "baseline"),
    ({"bits": 5}, "bits"),
    ({"bits": 17}, "bits"),
    ({"resolution": float("nan")}, "resolution"),
    ({"resolution": 0.0}, "resolution"),
    ({"distance": 3}, "predictor"),
    ({"count": 2 ** 32 - 1}, "bodies"),
    ({"count": MAX_BODIES + 1}, "bodies"),
    # Counts that disagree with the payload: its streams no longer parse.
    ({"count": 7}, "truncated|after the table"),
    ({"count": 5}, "truncated|after the table"),
    ({"payload_length": 10 ** 6}, "payload"),  # beyond zlib's 1032:1 on this body
    ({"payload_length": 1}, "decompress"),
])
@pytest.mark.filterwarnings("error")
def test_forged_headers_are_refused(fields, match):
    key, _ = small_frames()
    with pytest.raises(SnapshotError, match=match):
        SnapshotDecoder().decode(forge(key, **fields))


def test_huge_count_claim_is_refused_before_allocating():
    key, _ = small_frames()
    frame = forge(key, count=MAX_BODIES, payload_length=MAX_BODIES * 53)
    with pytest.raises(SnapshotError, match="zlib"):
        SnapshotDecoder().decode(frame)
    with pytest.raises(SnapshotError, match="cap"):
        SnapshotDecoder(max_bodies=1000).decode(forge(key, count=1001))


def test_zlib_bomb_is_refused_without_inflating_it():
    """100 MB of zeros squeezed to 436 kB, claimed as 6 bodies: refused whether the
    header states the real size (more than 6 bodies can need) or a small one (the
    inflater stops at the stated length)."""
    key, _ = small_frames()
    bomb = zlib.compress(bytes(100_000_000), 1)
    as_stated = forge(key[:HEADER_SIZE] + bomb, payload_length=100_000_000)
    with pytest.raises(SnapshotError, match="6 bodies need at most"):
        SnapshotDecoder().decode(as_stated)
    understated = forge(key[:HEADER_SIZE] + bomb, payload_length=frame_info(key)["payload_length"])
    with pytest.raises(SnapshotError, match="more than"):
        SnapshotDecoder().decode(understated)


@pytest.mark.filterwarnings("error")
def test_payload_inconsistencies_are_refused():
    def with_payload(data, frame):
        return forge(frame[:HEADER_SIZE] + zlib.compress(data), payload_length=len(data))

    # The range-coded table must fill the payload exactly.
    key, delta = small_frames()
    payload = zlib.decompress(key[HEADER_SIZE:])
    with pytest.raises(SnapshotError, match="after the table"):
        SnapshotDecoder().decode(with_payload(payload + b"\0", key))
    with pytest.raises(SnapshotError, match="truncated"):
        SnapshotDecoder().decode(with_payload(payload[:-1], key))

    key, delta = small_frames("zlib")
    payload = zlib.decompress(key[HEADER_SIZE:])
    with_payload = functools.partial(with_payload, frame=key)

    with pytest.raises(SnapshotError, match="after its last stream"):
        SnapshotDecoder().decode(with_payload(payload + b"\0"))
    with pytest.raises(SnapshotError, match="after its zlib stream"):
        SnapshotDecoder().decode(key + b"\0")
    with pytest.raises(SnapshotError, match="byte planes"):
        SnapshotDecoder().decode(with_payload(b"\x09" + payload[1:]))
    # Ids that overflow uint32: the first id gap set to 2**32 - 1, then more ids.
    gaps = np.zeros(6, dtype="<u8")
    gaps[0] = gaps[1] = 2 ** 32 - 1
    bad_ids = b"\x04" + gaps.view(np.uint8).reshape(6, 8)[:, :4].T.tobytes()
    ids_length = 1 + 6 * payload[0]
    with pytest.raises(SnapshotError, match="uint32"):
        SnapshotDecoder().decode(with_payload(bad_ids + payload[ids_length:]))
    # A delta whose keep mask and added count disagree with its body count.
    decoder = decoder_with_baseline(key)
    delta_payload = bytearray(zlib.decompress(delta[HEADER_SIZE:]))
    delta_payload[1:5] = struct.pack("<I", 3)  # added count (after the 1-byte mask)
    with pytest.raises(SnapshotError, match="adds"):
        decoder.decode(with_payload(bytes(delta_payload), frame=delta))


# ---- sizes ----------------------------------------------------------------------------

def boxes3000_like(rng):
    """3008 boxes on boxes3000's grid, each offset by up to 1 cm so that positions have
    arbitrary fractions of the resolution (1/512 m), as simulated ones do."""
    from wmo.scenes import boxes3000_spec
    positions = boxes3000_spec().positions + rng.uniform(-0.01, 0.01, (N_BOXES3000, 3))
    return np.arange(1, N_BOXES3000 + 1, dtype=np.uint32), positions


def test_frame_sizes_for_3008_bodies():
    rng = np.random.default_rng(21)
    ids, start = boxes3000_like(rng)
    identity = np.tile([0.0, 0.0, 0.0, 1.0], (N_BOXES3000, 1))

    def run(positions_at, frames, predict=True):
        encoder, decoder, sizes = SnapshotEncoder(predict=predict), SnapshotDecoder(), []
        for k in range(frames):
            snap = Snapshot(seq=k + 1, step=k, time=k / 60, ids=ids, positions=positions_at(k),
                            orientations=identity)
            frame = encoder.encode(snap, k if k else None)
            assert_within_bounds(decoder.decode(frame), snap)
            sizes.append(len(frame))
        return sizes

    rest = run(lambda k: start, 3)
    print(f"\n3008 bodies: grid key frame {rest[0]} bytes, delta at rest {rest[1]} bytes")
    assert rest[1] < 200  # measured 67: header 56 + a table of zeros, zlib'd

    def fall(k):  # a whole number of resolution steps per frame: 51 / 512 m
        moved_down = start.copy()
        moved_down[:, 1] -= 51 / 512 * k
        return moved_down

    steady = run(fall, 6)
    print(f"3008 bodies falling 51/512 m per frame: deltas {steady[1:]} bytes")
    # Measured 209 for the first delta (every body -51 steps in y), then 67 predicted.
    assert max(steady[1:]) < 300 and max(steady[2:]) < 100

    def gravity(k):
        moved_down = start.copy()
        moved_down[:, 1] -= 5.0 * (k / 60) ** 2  # free fall at 10 m/s^2 from rest
        return moved_down

    largest = {}
    for predict in (True, False):
        falling = run(gravity, 30, predict)
        largest[predict] = max(falling[1:])
        print(f"3008 bodies in free fall, predict={predict}: deltas {min(falling[1:])}.."
              f"{max(falling[1:])} bytes")
    # Measured 78..472 bytes with prediction, 154..1607 without: without, the residual
    # is the whole motion since the baseline, which grows with the speed; with it, the
    # second difference of three roundings plus g dt^2 (1.4 steps), whatever the speed,
    # and the range coder's previous-residual context learns that g dt^2 persists.
    assert largest[True] < 700 and largest[False] > largest[True]

    positions = rng.uniform(-20, 20, (N_BOXES3000, 3))
    q = unit_quaternions(rng, N_BOXES3000)
    snap = Snapshot(seq=1, step=0, time=0.0, ids=ids, positions=positions, orientations=q,
                    linear_velocities=rng.normal(size=(N_BOXES3000, 3)),
                    angular_velocities=rng.normal(size=(N_BOXES3000, 3)))
    key = SnapshotEncoder().encode(snap, None)
    full_key = SnapshotEncoder("full").encode(snap, None)
    print(f"3008 bodies at random poses: key frame {len(key)} bytes compressed, "
          f"{len(full_key)} bytes full")
    # 3 x 14.3 bits of position (40 m at 1/512 m) + 2 + 3 x 9 bits of orientation = 9.0
    # bytes a body of entropy: measured 27,909 bytes (9.3 a body, 3 % above).
    assert len(key) < 29_000
    assert len(full_key) < N_BOXES3000 * 13 * 8 + 1000  # random doubles barely compress
