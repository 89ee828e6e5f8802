"""The ``wmo`` command line.

    wmo bench SCENE [--steps 600] [--engines wmo,pybullet,mujoco] [--out DIR]
                    [--iterations 10] [--substeps 4] [--dt 1/60] [--repeats 1] [--sleeping]

``bench`` steps a canonical scene (boxes3000 or pyramid, shared/SCENES.md) in WMO and in
its peers in the same run, prints a summary with the ratios, and writes
``DIR/SCENE_steps.csv`` (one row per engine and step: time, contact points, awake
bodies, deepest penetration) and PNG plots of steps per second and contact points over
simulated time.
"""
from __future__ import annotations

import argparse
import sys
from fractions import Fraction
from pathlib import Path


def _dt(text: str) -> float:
    try:
        v = float(Fraction(text))
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"dt must be a number such as 0.0166 or 1/60, got {text!r}")
    if not v > 0:
        raise argparse.ArgumentTypeError(f"dt must be > 0, got {text!r}")
    return v


def main(argv: list[str] | None = None) -> int:
    from . import bench

    ap = argparse.ArgumentParser(prog="wmo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bench", help="step a canonical scene in WMO and its peers")
    b.add_argument("scene", choices=sorted(bench._scenes.SPECS))
    b.add_argument("--steps", type=int, default=600)
    b.add_argument("--engines", default=",".join(bench.ENGINES),
                   help="comma-separated, from " + ", ".join(bench.ENGINES))
    b.add_argument("--out", type=Path, default=Path("results/bench"))
    b.add_argument("--iterations", type=int, default=10, help="peer solver iterations (default 10)")
    b.add_argument("--substeps", type=int, default=4, help="WMO soft-step substeps (default 4)")
    b.add_argument("--dt", type=_dt, default=1 / 60)
    b.add_argument("--repeats", type=int, default=1, help="runs per engine; the median run is kept")
    b.add_argument("--sleeping", action="store_true",
                   help="sleeping on (default off: the throughput figure of SCENES.md)")
    b.add_argument("--threads", type=int, default=1,
                   help="threads for WMO (default 1; the peers run single-threaded)")
    b.add_argument("--contact-hertz", type=float, default=None,
                   help="WMO's contact spring in Hz (default: the World's, 30); the pyramid stands "
                        "to the centimetre with --substeps 6 --contact-hertz 38")
    b.add_argument("--memory", action="store_true",
                   help="also measure each engine's peak memory, in a fresh process each (Linux)")
    args = ap.parse_args(argv)

    if args.command == "bench":
        engines = [e for e in args.engines.split(",") if e]
        if args.threads < 1:
            print(f"wmo bench: threads must be >= 1, got {args.threads}", file=sys.stderr)
            return 2
        if args.contact_hertz is not None and not args.contact_hertz >= 0:
            print(f"wmo bench: contact-hertz must be >= 0, got {args.contact_hertz}", file=sys.stderr)
            return 2
        bench.WMO_THREADS = args.threads
        bench.WMO_CONTACT_HERTZ = args.contact_hertz
        try:
            result = bench.run_bench(args.scene, steps=args.steps, engines=engines, dt=args.dt,
                                     iterations=args.iterations, substeps=args.substeps,
                                     repeats=args.repeats, sleeping=args.sleeping)
        except ValueError as e:
            print(f"wmo bench: {e}", file=sys.stderr)
            return 2
        print(result.summary())
        csv_path = args.out / f"{args.scene}_steps.csv"
        bench.write_csv(result, csv_path, args.dt)
        written = [csv_path, *bench.plot(result, args.dt, args.out)]
        if args.memory:
            mem, mem_skipped = bench.measure_memory(args.scene, steps=args.steps, engines=engines, dt=args.dt,
                                                    iterations=args.iterations, substeps=args.substeps,
                                                    sleeping=args.sleeping)
            print(bench.memory_summary(args.scene, mem, mem_skipped))
            mem_path = args.out / f"{args.scene}_memory.csv"
            bench.write_memory_csv(args.scene, mem, mem_path)
            written.append(mem_path)
        for p in written:
            print(f"wrote {p}")
        return 0
    return 2
