"""Deepest penetration of boxes3000 (sleeping off) under given World settings: the probe
behind issue 4's notes on where the scene's deep overlaps come from.

Runs 10 simulated seconds (600 steps of 1/60 s, or 600 k steps of 1/(60 k) with
`--split k`), with CCD on no box or on every box, and prints the deepest penetration after
any step (World.max_penetration: the step's contact pairs collided again at its end
poses) and the wall time of the steps. The scene is chaotic: a change that should not
matter moves these maxima by a centimetre or more. Settings are World keywords:

    .venv/bin/python benchmarks/ccd/penetration.py                       # defaults: 0.828 m
    .venv/bin/python benchmarks/ccd/penetration.py --ccd all             # 0.082 m (overlap
        # projection; 0.41 m with the shock pass alone)
    .venv/bin/python benchmarks/ccd/penetration.py --set iterations=10   # 0.715 m
    .venv/bin/python benchmarks/ccd/penetration.py --split 4 --set substeps=1            # 0.989 m
    .venv/bin/python benchmarks/ccd/penetration.py --split 4 --set substeps=4 \\
        --set contact_hertz=120 --set iterations=2                                       # 0.124 m
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
    wall = 0.0
    for k in range(steps):
        t0 = time.perf_counter()
        w.step()
        wall += time.perf_counter() - t0
        if w.max_penetration > deepest:
            deepest, at = w.max_penetration, (k + 1) * w.dt
    print(f"boxes3000 {kwargs} split={args.split} ccd={args.ccd}: deepest penetration {deepest:.3f} m "
          f"(at t = {at:.2f} s), {wall:.1f} s wall for {args.seconds:g} s simulated")


if __name__ == "__main__":
    main()
