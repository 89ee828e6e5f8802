"""Snapshot codec bandwidth on the canonical boxes3000 run, without a network.

Simulates boxes3000 for --steps steps at 60 Hz (the stream the bar "boxes3000 streamed
at 60 Hz averages under 2 Mbit/s with compression" is about), then encodes every step
with wmo.remote.snapshot's encoder as a client with a perfect link would receive it:
delta-coded against the snapshot `lag` steps back (lag 1: acknowledged at once; a real
client's lag is its round trip in frames). For each position resolution, orientation
bits, body-state coder ("range": the context-modelled range coder, the default;
"zlib": byte planes left to zlib), zlib level and lag: the average Mbit/s over the run.
Also the order-0 entropy of the lag-1 residuals (what an ideal per-value coder without
context would need), their conditional entropy given three contexts (context_entropy:
a reference point, not a bound; the range coder, which also conditions on the
previous body, comes in below it), and how many boxes still move at the end (the
scene is chaotic for all of its 10 s).

    .venv/bin/python benchmarks/remote/codec.py --out results/codec   [--steps 600]

Writes codec.csv and prints the table.
"""
from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

import wmo
from wmo.remote.snapshot import Snapshot, SnapshotEncoder, orientation_error_bound

SETTINGS = [  # (position resolution m, orientation bits, coder, zlib level)
    (1 / 512, 9, "range", 6), (1 / 512, 9, "zlib", 6),  # the default precision (Fiedler's)
    (1 / 512, 10, "range", 6), (1e-3, 10, "range", 6), (1e-3, 10, "zlib", 6),
    (1e-3, 12, "range", 6), (1e-3, 12, "zlib", 6), (1e-3, 12, "zlib", 1), (1e-3, 12, "zlib", 9),
]
LAGS = (1, 2, 4)


def record(steps: int) -> tuple[list[Snapshot], wmo.World]:
    world = wmo.scenes.boxes3000()
    ids = np.arange(1, world.body_count + 1, dtype=np.uint32)
    snaps = []
    for k in range(steps):
        world.step()
        snaps.append(Snapshot(seq=k + 1, step=k + 1, time=(k + 1) * world.dt, ids=ids,
                              positions=np.array(world.positions), orientations=np.array(world.orientations)))
    return snaps, world


def mbit_per_s(snaps: list[Snapshot], resolution: float, bits: int, coder: str, level: int, lag: int,
               dt: float) -> float:
    enc = SnapshotEncoder(position_resolution=resolution, orientation_bits=bits, coder=coder, level=level)
    total = sum(len(enc.encode(s, snaps[i - lag].seq if i >= lag else None)) for i, s in enumerate(snaps))
    return total * 8 / (len(snaps) * dt) / 1e6


def _entropy(values: np.ndarray) -> float:
    _, counts = np.unique(values, return_counts=True)
    p = counts / counts.sum()
    return float(-(p * np.log2(p)).sum())


def _residuals(snaps: list[Snapshot], resolution: float = 1e-3, bits: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """The lag-1 residuals the encoder codes and the baseline motions they are predicted
    with, both (frames - 2, N, 7) int64: the quantized integers the frames carry,
    linearly predicted from the two previous snapshots, as the codec predicts."""
    enc = SnapshotEncoder(position_resolution=resolution, orientation_bits=bits)
    values = [enc._quantize(s).values for s in snaps]
    residuals, motions = [], []
    for i in range(2, len(values)):
        motion = values[i - 1] - values[i - 2]
        motion[motion[:, 3] != 0, 4:] = 0  # as the codec: no motion across an index change
        motion[:, 3] = 0
        residuals.append(values[i] - (values[i - 1] + motion))
        motions.append(motion)
    return np.array(residuals), np.array(motions)


def residual_entropy(snaps: list[Snapshot], dt: float) -> float:
    """Order-0 entropy (Mbit/s) of the lag-1 residuals the encoder codes, column by
    column (1 mm, 12 bits, linear prediction from the two previous snapshots)."""
    r, _ = _residuals(snaps)
    bits = sum(_entropy(r[:, :, c]) for c in range(r.shape[2]))
    return bits * r.shape[1] / dt / 1e6


def context_entropy(snaps: list[Snapshot], dt: float, resolution: float, bits: int) -> float:
    """Conditional entropy (Mbit/s) of the lag-1 residuals given what both ends know:
    per column, the class (bit length) of the body's own baseline motion in that
    column, of its residual in the previous column, and of its residual in the
    previous frame, with thousands of contexts estimated from the run itself. What an
    ideal coder with exactly these contexts would need; a coder with other contexts
    can do better (the range coder conditions on the previous body too)."""
    r, m = _residuals(snaps, resolution, bits)

    def cls(a: np.ndarray) -> np.ndarray:
        return np.minimum(np.ceil(np.log2(np.abs(a) + 1)).astype(np.int64), 15)

    total = 0.0
    for c in range(r.shape[2]):
        prev_col = np.zeros_like(r[:, :, c]) if c in (0, 4) else (
            np.abs(r[:, :, :3]).max(axis=2) if c == 3 else r[:, :, c - 1])
        prev_frame = np.concatenate([np.zeros_like(r[:1, :, c]), r[:-1, :, c]])
        ctx = (cls(m[:, :, c]) * 16 + cls(prev_col)) * 16 + cls(prev_frame)
        col = r[:, :, c]
        for k in np.unique(ctx):
            sel = ctx == k
            total += sel.mean() * _entropy(col[sel])
    return total * r.shape[1] / dt / 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("results/codec"))
    ap.add_argument("--steps", type=int, default=600)
    args = ap.parse_args(argv)
    snaps, world = record(args.steps)
    dt = world.dt
    speed = np.linalg.norm(world.linear_velocities, axis=1)
    print(f"boxes3000, {args.steps} steps: at the end {int((speed > 0.5).sum())} boxes move faster than 0.5 m/s, "
          f"{int((speed > 3).sum())} faster than 3 m/s")
    rows = []
    for resolution, bits, coder, level in SETTINGS:
        for lag in LAGS:
            rate = mbit_per_s(snaps, resolution, bits, coder, level, lag, dt)
            rows.append({"position_resolution_m": resolution, "orientation_bits": bits,
                         "orientation_error_deg": float(np.degrees(orientation_error_bound(bits))),
                         "coder": coder, "zlib_level": level, "lag_frames": lag, "mbit_per_s": rate})
            print(f"resolution {resolution * 1e3:.2f} mm, {bits:2d} bits, {coder:5s} (zlib {level}), "
                  f"lag {lag}: {rate:.3f} Mbit/s")
    entropy = residual_entropy(snaps, dt)
    print(f"order-0 entropy of the lag-1 residuals (1 mm, 12 bits): {entropy:.3f} Mbit/s")
    rows.append({"position_resolution_m": 1e-3, "orientation_bits": 12, "orientation_error_deg": "",
                 "coder": "order-0 entropy", "zlib_level": "", "lag_frames": 1, "mbit_per_s": entropy})
    for resolution, bits in ((1e-3, 12), (1 / 512, 9)):
        floor = context_entropy(snaps, dt, resolution, bits)
        print(f"conditional entropy of the lag-1 residuals ({resolution * 1e3:.2f} mm, {bits} bits): "
              f"{floor:.3f} Mbit/s")
        rows.append({"position_resolution_m": resolution, "orientation_bits": bits, "orientation_error_deg": "",
                     "coder": "context entropy", "zlib_level": "", "lag_frames": 1, "mbit_per_s": floor})
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "codec.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {args.out / 'codec.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
