"""What continuous collision detection costs: step time and deepest penetration of the
canonical scenes (shared/SCENES.md, built by wmo.scenes) with CCD

  * switch_off: the World's ``ccd`` switch off (the stage cannot run);
  * none:       switch on, no body asks for CCD (what every scene pays for the feature);
  * 1pct:       every 100th dynamic body asks (``body.ccd = True``);
  * all:        every dynamic body asks.

boxes3000 runs with sleeping off (SCENES.md's throughput protocol); the pyramid with
sleeping on (a resting pile: no fast bodies, the case that must cost what no CCD costs).
Modes are run interleaved, `--repeats` times each, and the fastest repeat is kept (the
least disturbed by the machine). Per run: mean step time, the ccd stage's share, bodies
swept and put back per step, and the deepest penetration after any step
(World.max_penetration). Writes `ccd.csv` and `ccd.png`.

    .venv/bin/python benchmarks/ccd/run.py --out results/ccd
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

import wmo

MODES = ("switch_off", "none", "1pct", "all")


def build(scene: str, mode: str) -> wmo.World:
    kwargs = {"ccd": mode != "switch_off"}
    if scene == "boxes3000":
        w = wmo.scenes.boxes3000(sleeping=False, **kwargs)
    else:
        w = wmo.scenes.pyramid(**kwargs)
    if mode in ("1pct", "all"):
        step = 100 if mode == "1pct" else 1
        dynamic = [i for i in range(w.body_count) if w.body(i).kind == "dynamic"]
        for i in dynamic[::step]:
            w.body(i).ccd = True
    return w


def run_once(scene: str, mode: str, steps: int) -> dict:
    w = build(scene, mode)
    deepest = 0.0
    swept = hits = 0
    t_total = 0.0
    for _ in range(steps):
        t0 = time.perf_counter()
        w.step()
        t_total += time.perf_counter() - t0
        deepest = max(deepest, w.max_penetration)
        swept += w.profile["ccd"]["count"]
        hits += w.ccd_hits
    prof = w.profile
    return dict(scene=scene, mode=mode, steps=steps, step_ms=1e3 * t_total / steps,
                ccd_stage_ms=1e3 * prof["ccd"]["total_seconds"] / steps,
                swept_per_step=swept / steps, hits_per_step=hits / steps,
                deepest_penetration_m=deepest,
                ccd_bodies=sum(w.body(i).ccd for i in range(w.body_count)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="results/ccd")
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenes", default="boxes3000,pyramid")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    scenes = args.scenes.split(",")
    best: dict[tuple, dict] = {}
    for rep in range(args.repeats):
        for scene in scenes:
            for mode in MODES:
                r = run_once(scene, mode, args.steps)
                key = (scene, mode)
                if key not in best or r["step_ms"] < best[key]["step_ms"]:
                    best[key] = r
                print(f"  repeat {rep + 1}/{args.repeats} {scene:10s} {mode:10s} {r['step_ms']:8.3f} ms/step",
                      flush=True)
    rows = [best[(s, m)] for s in scenes for m in MODES]
    path = os.path.join(args.out, "ccd.csv")
    with open(path, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0]))
        wr.writeheader()
        wr.writerows(rows)
    print(f"\n{'scene':10s} {'mode':10s} {'bodies':>7s} {'ms/step':>9s} {'vs none':>8s} {'ccd ms':>8s} "
          f"{'swept':>7s} {'hits':>6s} {'deepest m':>10s}")
    for r in rows:
        base = best[(r["scene"], "none")]["step_ms"]
        print(f"{r['scene']:10s} {r['mode']:10s} {r['ccd_bodies']:7d} {r['step_ms']:9.3f} "
              f"{r['step_ms'] / base:8.3f} {r['ccd_stage_ms']:8.3f} {r['swept_per_step']:7.1f} "
              f"{r['hits_per_step']:6.2f} {r['deepest_penetration_m']:10.3f}")
    print(f"\nwrote {path}")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot")
        return
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.5 * len(scenes), 4), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        rs = [best[(scene, m)] for m in MODES]
        x = np.arange(len(MODES))
        ax.bar(x, [r["step_ms"] for r in rs], color="#4c72b0", label="step")
        ax.bar(x, [r["ccd_stage_ms"] for r in rs], color="#dd8452", label="of which ccd stage")
        for xi, r in zip(x, rs):
            ax.annotate(f"{r['deepest_penetration_m']:.3f} m", (xi, r["step_ms"]), ha="center", va="bottom",
                        fontsize=8)
        ax.set_xticks(x, MODES)
        ax.set_ylabel("ms per step")
        ax.set_title(f"{scene}: step time (labels: deepest penetration)")
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    png = os.path.join(args.out, "ccd.png")
    fig.savefig(png, dpi=120)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
