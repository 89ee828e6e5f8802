"""Time of impact: accuracy against cost for the tolerance and the iteration cap.

Three motions with a closed-form first contact time, each over many random starts:
  * sphere_sphere: two spheres closing head-on at 10..1000 m/s (pure translation);
  * spinning_rod:  a 2 m rod spinning at 20..200 rad/s about its middle, a wall's face
                   0.3..0.9 m from the axis (rotation: conservative advancement converges
                   linearly here, the hard case);
  * box_plate:     a tilted box falling at 5..100 m/s onto a plate (translation, polytopes).
For each tolerance (1e-2..1e-8 m) and iteration cap (2..256), the batched query
(`wmo.geometry.time_of_impact_batch`, C++ loop, GIL released) is timed and its error
measured as true time minus reported time (>= 0 by construction: the query never reports
a time after the contact; a negative value would be a bug and is counted). Writes
`toi.csv` and `toi.png` (error against microseconds per query, one curve per motion).

    .venv/bin/python benchmarks/toi/run.py --out results/toi
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import time

import numpy as np

import wmo
from wmo import geometry as G


def rot_z(a):
    return np.stack([np.zeros_like(a), np.zeros_like(a), np.sin(a / 2), np.cos(a / 2)], axis=1)


def cases(n, rng):
    out = {}
    # Spheres: radii 0.1, centres 1 + gap apart along x.
    gap = rng.uniform(0.05, 1.0, n)
    speed = rng.uniform(10, 1000, n)
    pa = np.zeros((n, 7)); pa[:, 6] = 1
    pb = np.zeros((n, 7)); pb[:, 6] = 1; pb[:, 0] = 0.2 + gap
    va = np.zeros((n, 3)); va[:, 0] = speed / 2
    vb = -va
    out["sphere_sphere"] = dict(a=wmo.Sphere(0.1), b=wmo.Sphere(0.1), pa=pa, pb=pb, va=va, vb=vb,
                                wa=np.zeros((n, 3)), t_true=gap / speed, duration=10.0)
    # Rod: corner (1, 0.01) reaches the wall face at height h when
    # sin(w t) + 0.01 cos(w t) = h, i.e. w t = asin(h / |(1, .01)|) - atan2(.01, 1).
    h = rng.uniform(0.3, 0.9, n)
    w = rng.uniform(20, 200, n)
    L = math.hypot(1, 0.01)
    t_true = (np.arcsin(h / L) - math.atan2(0.01, 1)) / w
    pa = np.zeros((n, 7)); pa[:, 6] = 1
    pb = np.zeros((n, 7)); pb[:, 6] = 1; pb[:, 1] = h + 0.05
    wa = np.zeros((n, 3)); wa[:, 2] = w
    out["spinning_rod"] = dict(a=wmo.Box((1.0, 0.01, 0.01)), b=wmo.Box((3, 0.05, 3)), pa=pa, pb=pb,
                               va=np.zeros((n, 3)), vb=np.zeros((n, 3)), wa=wa, t_true=t_true,
                               duration=1.0)
    # Box tilted about z by angle a: lowest point at -(0.2 |sin a| + 0.1 cos a) (a < pi/2).
    a = rng.uniform(0, 1.2, n)
    height = rng.uniform(0.5, 2.0, n)
    v = rng.uniform(5, 100, n)
    pa = np.zeros((n, 7)); pa[:, 1] = height; pa[:, 3:] = rot_z(a)
    pb = np.zeros((n, 7)); pb[:, 6] = 1
    va = np.zeros((n, 3)); va[:, 1] = -v
    low = 0.2 * np.abs(np.sin(a)) + 0.1 * np.cos(a)
    out["box_plate"] = dict(a=wmo.Box((0.2, 0.1, 0.2)), b=wmo.Box((5, 0.01, 5)), pa=pa, pb=pb, va=va,
                            vb=np.zeros((n, 3)), wa=np.zeros((n, 3)),
                            t_true=(height - low - 0.01) / v, duration=10.0)
    return out


def run_one(c, tol, iters):
    kw = dict(velocities_a=c["va"], angular_velocities_a=c["wa"], velocities_b=c["vb"],
              duration=c["duration"], tolerance=tol, max_iterations=iters)
    G.time_of_impact_batch(c["a"], c["b"], c["pa"], c["pb"], **kw)  # warm-up
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        out = G.time_of_impact_batch(c["a"], c["b"], c["pa"], c["pb"], **kw)
        times.append(time.perf_counter() - t0)
    us = 1e6 * float(np.median(times)) / len(c["t_true"])
    err = c["t_true"] - out["time"]
    return dict(us_per_query=us, median_error_s=float(np.median(err)), max_error_s=float(err.max()),
                late=int((err < 0).sum()), misses=int((~out["hit"]).sum()),
                capped=int((out["status"] == G.QueryStatus.MAX_ITERATIONS.code).sum()),
                mean_iterations=float(out["iterations"].mean()))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/toi")
    ap.add_argument("--n", type=int, default=2000, help="random starts per motion")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(1)
    cs = cases(args.n, rng)
    rows = []
    for name, c in cs.items():
        for tol in [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8]:
            r = run_one(c, tol, 256)
            rows.append(dict(motion=name, tolerance=tol, max_iterations=256, **r))
        for iters in [2, 4, 8, 16, 32, 64, 128]:
            r = run_one(c, 1e-4, iters)
            rows.append(dict(motion=name, tolerance=1e-4, max_iterations=iters, **r))
    path = os.path.join(args.out, "toi.csv")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"{'motion':14} {'tol':>8} {'iters':>5} {'us/query':>9} {'median err s':>13} "
          f"{'max err s':>10} {'mean it':>7} {'late':>4} {'capped':>6}")
    for r in rows:
        print(f"{r['motion']:14} {r['tolerance']:8.0e} {r['max_iterations']:5d} {r['us_per_query']:9.2f} "
              f"{r['median_error_s']:13.3e} {r['max_error_s']:10.3e} {r['mean_iterations']:7.1f} "
              f"{r['late']:4d} {r['capped']:6d}")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot")
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in cs:
        sub = [r for r in rows if r["motion"] == name and r["max_iterations"] == 256]
        axes[0].loglog([r["us_per_query"] for r in sub], [max(r["max_error_s"], 1e-16) for r in sub],
                       "o-", label=name)
        sub = [r for r in rows if r["motion"] == name and r["tolerance"] == 1e-4]
        axes[1].semilogx([r["max_iterations"] for r in sub], [r["capped"] / args.n for r in sub], "o-",
                         label=name)
    axes[0].set_xlabel("microseconds per query")
    axes[0].set_ylabel("max (true - reported) time, s")
    axes[0].set_title("tolerance 1e-2 .. 1e-8 m (cap 256)")
    axes[1].set_xlabel("iteration cap")
    axes[1].set_ylabel("fraction stopped by the cap")
    axes[1].set_title("tolerance 1e-4 m")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "toi.png"), dpi=110)
    print(f"wrote {path} and toi.png")


if __name__ == "__main__":
    main()
