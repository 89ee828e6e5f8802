"""Plot the broadphase benchmark: time per frame against N, log-log.

Reads the CSV written by bench_broadphase (columns algorithm,n,median_us,pairs), prints a
table (one row per N, one column per algorithm) and writes a PNG with one line per
algorithm plus O(n) and O(n log n) reference slopes (dashed, grey), anchored at the
fastest algorithm's smallest-N point so the slopes can be compared by eye.

Usage: python plot_broadphase.py CSV [PNG]   (PNG defaults to the CSV path with .png)
"""

from __future__ import annotations

import csv
import math
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402

ORDER = ["brute_force", "sweep_and_prune", "aabb_tree"]
LABELS = {
    "brute_force": "brute force O(n²)",
    "sweep_and_prune": "sweep and prune (1 axis)",
    "aabb_tree": "dynamic AABB tree",
}


def read(path: Path) -> dict[str, list[tuple[int, float, int]]]:
    """algorithm -> [(n, median_us, pairs)] sorted by n."""
    rows: dict[str, list[tuple[int, float, int]]] = defaultdict(list)
    with path.open(newline="") as f:
        for r in csv.DictReader(f):
            rows[r["algorithm"]].append((int(r["n"]), float(r["median_us"]), int(r["pairs"])))
    for v in rows.values():
        v.sort()
    return rows


def print_table(rows: dict[str, list[tuple[int, float, int]]]) -> None:
    algos = [a for a in ORDER if a in rows] + sorted(a for a in rows if a not in ORDER)
    ns = sorted({n for v in rows.values() for n, _, _ in v})
    by = {(a, n): (t, p) for a in algos for n, t, p in rows[a]}
    header = f"{'n':>8} {'pairs':>8} " + " ".join(f"{a + ' [us]':>22}" for a in algos)
    print(header)
    print("-" * len(header))
    for n in ns:
        pairs = next((by[(a, n)][1] for a in algos if (a, n) in by), 0)
        cells = " ".join(f"{by[(a, n)][0]:>22.1f}" if (a, n) in by else f"{'-':>22}" for a in algos)
        print(f"{n:>8} {pairs:>8} {cells}")


def plot(rows: dict[str, list[tuple[int, float, int]]], out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7.5, 5.5), dpi=120)
    markers = {"brute_force": "s", "sweep_and_prune": "o", "aabb_tree": "^"}
    for a in [a for a in ORDER if a in rows] + sorted(a for a in rows if a not in ORDER):
        ns = [n for n, _, _ in rows[a]]
        ts = [t for _, t, _ in rows[a]]
        ax.plot(ns, ts, marker=markers.get(a, "x"), linewidth=2, label=LABELS.get(a, a))
    # Reference slopes through the lowest point at the smallest N.
    all_n = sorted({n for v in rows.values() for n, _, _ in v})
    n0 = all_n[0]
    t0 = min(t for v in rows.values() for n, t, _ in v if n == n0)
    ref_n = [n0, all_n[-1]]
    ax.plot(ref_n, [t0 * n / n0 for n in ref_n], "--", color="0.55", linewidth=1, label="O(n) reference")
    ax.plot(
        ref_n,
        [t0 * (n * math.log(n)) / (n0 * math.log(n0)) for n in ref_n],
        ":",
        color="0.35",
        linewidth=1.5,
        label="O(n log n) reference",
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("number of boxes N")
    ax.set_ylabel("time per frame: move all + update + query pairs [µs]")
    ax.set_title("Broadphase cost per frame (median), pile-density scene")
    ax.grid(True, which="major", alpha=0.4)
    ax.grid(True, which="minor", alpha=0.12)
    ax.legend(loc="upper left", fontsize=9)
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}")


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    src = Path(argv[1])
    out = Path(argv[2]) if len(argv) > 2 else src.with_suffix(".png")
    rows = read(src)
    if not rows:
        print(f"{src}: no rows")
        return 1
    print_table(rows)
    plot(rows, out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
