"""Deepest penetration of boxes3000 (sleeping off) under given World settings: the probe
behind issue 4's notes on where the scene's deep overlaps come from.

Runs 10 simulated seconds (600 steps of 1/60 s, or 600 k steps of 1/(60 k) with
`--split k`), with CCD on no box or on every box, and prints the deepest penetration after
any step (World.max_penetration: the step's manifold points moved with their bodies) and
the wall time of the steps. With `--geometric` it also collides every contact pair again
at each step's end poses and prints the deepest overlap found: the reported depths miss a
corner that swings in within a step (0.37 m reported where the boxes overlapped 0.41 m
before overlap projection). The scene is chaotic: a change that should not matter moves
these maxima by a few centimetres. Settings are World keywords:

    .venv/bin/python benchmarks/ccd/penetration.py                       # defaults: ~0.7 m
    .venv/bin/python benchmarks/ccd/penetration.py --ccd all --geometric # ~0.16-0.18 m (overlap
        # projection; 0.37 m reported / 0.41 m geometric with the shock pass alone, 0.65 m before it)
    .venv/bin/python benchmarks/ccd/penetration.py --set iterations=10   # ~0.7 m
    .venv/bin/python benchmarks/ccd/penetration.py --split 4 --set substeps=1            # ~0.86 m
    .venv/bin/python benchmarks/ccd/penetration.py --split 4 --set substeps=4 \\
        --set contact_hertz=120 --set iterations=2                                       # ~0.15 m
"""
from __future__ import annotations

import argparse
import ast
import time

import wmo


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a World keyword (repeatable), e.g. substeps=8")
    ap.add_argument("--split", type=int, default=1, help="steps per 1/60 s (dt = 1 / (60 k))")
    ap.add_argument("--ccd", choices=("none", "all"), default="none")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--geometric", action="store_true",
                    help="also collide every contact pair again at the step's end poses and report the "
                         "deepest overlap found (the reported depths are the step's manifold points "
                         "moved with their bodies, which miss a corner that swings in within the step)")
    args = ap.parse_args()
    kwargs = {}
    for item in args.set:
        key, _, value = item.partition("=")
        if not key or not value:
            raise SystemExit(f"--set wants KEY=VALUE, got {item!r}")
        kwargs[key] = ast.literal_eval(value)
    if args.split < 1:
        raise SystemExit(f"--split must be >= 1, got {args.split}")
    w = wmo.scenes.boxes3000(sleeping=False, dt=1.0 / (60 * args.split), **kwargs)
    if args.ccd == "all":
        for i in range(w.body_count):
            if w.body(i).kind == "dynamic":
                w.body(i).ccd = True
    steps = round(args.seconds * 60 * args.split)
    deepest, at = 0.0, 0.0
    geo_deepest, geo_at = 0.0, 0.0
    wall = 0.0
    shapes = [w.body(i).shape for i in range(w.body_count)] if args.geometric else []
    for k in range(steps):
        t0 = time.perf_counter()
        w.step()
        wall += time.perf_counter() - t0
        if w.max_penetration > deepest:
            deepest, at = w.max_penetration, (k + 1) * w.dt
        if args.geometric:
            g = geometric_overlap(w, shapes)
            if g > geo_deepest:
                geo_deepest, geo_at = g, (k + 1) * w.dt
    print(f"boxes3000 {kwargs} split={args.split} ccd={args.ccd}: deepest penetration {deepest:.3f} m "
          f"(at t = {at:.2f} s), {wall:.1f} s wall for {args.seconds:g} s simulated")
    if args.geometric:
        print(f"deepest geometric overlap of a contact pair at a step's end: {geo_deepest:.3f} m (at t = {geo_at:.2f} s)")


def geometric_overlap(w: wmo.World, shapes: list) -> float:
    """Deepest overlap of the last step's contact pairs, collided again at the end poses.
    `shapes[i]` is body i's shape (bodies are neither added nor removed here)."""
    import numpy as np
    pairs = w.contacts["bodies"]
    if len(pairs) == 0:
        return 0.0
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    groups: dict = {}
    for a, b in pairs:
        groups.setdefault((id(shapes[a]), id(shapes[b])), []).append((a, b))
    poses = np.hstack([w.positions, w.orientations])
    deepest = 0.0
    for lst in groups.values():
        lst = np.asarray(lst)
        r = wmo.geometry.collide_batch(shapes[lst[0, 0]], shapes[lst[0, 1]], poses[lst[:, 0]], poses[lst[:, 1]])
        hit = r["count"] > 0
        if hit.any():
            deepest = max(deepest, float(r["max_depth"][hit].max()))
    return deepest


if __name__ == "__main__":
    main()
