#!/usr/bin/env python3
"""Run the narrowphase benchmark, print a table per pair and plot the results.

Runs bench_narrowphase (C++; see benchmarks/narrowphase/bench_narrowphase.cpp for what
each method computes and how the error reference is chosen), which writes
narrowphase.csv, tolerance_sweep.csv and reference_check.csv into --out, then writes
narrowphase_time.png (ns/query per pair and method, log scale) and tolerance_sweep.png
(depth error against ns/query as the GJK/EPA tolerance varies, log-log), and
matched_accuracy.csv (WMO's GJK/EPA, manifold and one-contact, against libccd and FCL at
equal or better accuracy,
from the sweep).

Usage: .venv/bin/python benchmarks/narrowphase/run.py --out results/narrowphase
"""
from __future__ import annotations

import argparse
import csv
import math
import platform
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
METHODS = ["wmo_special", "wmo_gjk_epa", "wmo_gjk_epa_point", "libccd_gjk_epa", "libccd_mpr", "fcl", "fcl_gjk_epa"]
RATIOS = [
    ("wmo_special", "libccd_gjk_epa"),
    ("wmo_special", "fcl"),
    ("wmo_gjk_epa", "libccd_gjk_epa"),
    ("wmo_gjk_epa", "fcl"),
    ("wmo_gjk_epa", "fcl_gjk_epa"),
]


def find_binary(given: str | None) -> Path:
    if given:
        p = Path(given)
        if not p.is_absolute():
            p = REPO / p
        if not p.exists():
            sys.exit(f"run.py: --binary {p} does not exist")
        return p
    default = REPO / "build" / "py" / "bench_narrowphase"
    if default.exists():
        return default
    found = sorted((REPO / "build").glob("*/bench_narrowphase"), key=lambda q: q.stat().st_mtime, reverse=True)
    if not found:
        sys.exit("run.py: no bench_narrowphase binary under build/; build it first "
                 "(cmake --build build/py --target bench_narrowphase)")
    return found[0]


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def num(s: str) -> float:
    try:
        return float(s)
    except (TypeError, ValueError):
        return math.nan


def fmt_ns(v: float) -> str:
    return "-" if math.isnan(v) else f"{v:9.1f}"


def fmt_err(v: float) -> str:
    return "-" if math.isnan(v) else f"{v:9.2e}"


def print_tables(rows: list[dict[str, str]]) -> None:
    by_pair: dict[str, dict[str, dict[str, str]]] = defaultdict(dict)
    for r in rows:
        by_pair[r["pair"]][r["method"]] = r
    for pair, ms in by_pair.items():
        any_row = next(iter(ms.values()))
        print(f"\n== {pair}  ({any_row['n_overlap']} overlapping, {any_row['n_separated']} separated)")
        print(f"  {'method':<18}{'ns/query':>10}{'median err':>12}{'max err':>12}{'wrong verdicts':>16}")
        for m in METHODS:
            if m not in ms:
                continue
            r = ms[m]
            print(f"  {m:<18}{fmt_ns(num(r['ns_per_query'])):>10}{fmt_err(num(r['median_error'])):>12}"
                  f"{fmt_err(num(r['max_error'])):>12}{r.get('n_wrong_verdict', '-'):>16}")
        parts = []
        for a, b in RATIOS:
            if a in ms and b in ms:
                ratio = num(ms[a]["ns_per_query"]) / num(ms[b]["ns_per_query"])
                parts.append(f"{a}/{b} = {ratio:.2f}")
        if parts:
            print("  time ratios: " + ", ".join(parts))


# The references' own default tolerances (libccd's epa_tolerance, FCL's gjk_tolerance):
# the points of the sweep at which "equal accuracy" is judged.
PEER_DEFAULTS = {"libccd_gjk_epa": 1e-4, "fcl": 1e-6, "fcl_gjk_epa": 1e-6}
# WMO's methods in the sweep: the manifold (GJK, EPA, clipping) and the one-contact
# answer that libccd's and FCL's GJK/EPA give (the like-for-like comparison).
WMO_SWEPT = ["wmo_gjk_epa", "wmo_gjk_epa_point"]

# Errors below this (m) are round-off of the 0.05..2 m shapes (a few ulp of 1 m is
# 1e-15; 1e-12 leaves room for a few hundred operations) and compare as equal, so an
# exact closed form (FCL's sphere pairs, error 2.2e-16) and an exact GJK (5.6e-16) are
# "equally accurate" rather than the ulp deciding.
ROUND_OFF = 1e-12


def matched_accuracy(sweep: list[dict[str, str]]) -> list[dict[str, object]]:
    """WMO's GJK/EPA (each of WMO_SWEPT) against each reference at equal or better accuracy.

    For every pair, WMO method and reference, on the sweep's overlapping configurations: the
    reference at its default tolerance, and the loosest WMO tolerance whose median
    error, max error and wrong verdicts are all no worse (errors below ROUND_OFF count
    as equal; the loosest, not the
    fastest-measured, so timing noise cannot pick the setting). No such tolerance means
    WMO is less accurate at every setting (reported as such, never hidden).
    """
    out: list[dict[str, object]] = []
    pairs = list(dict.fromkeys(r["pair"] for r in sweep))
    for pair, wmo_method, (peer, tol) in ((p, m, d) for p in pairs for m in WMO_SWEPT for d in PEER_DEFAULTS.items()):
        rows = [r for r in sweep if r["pair"] == pair]
        wmo = [r for r in rows if r["method"] == wmo_method]
        if not wmo:
            continue
        ref = [r for r in rows if r["method"] == peer and math.isclose(num(r["tolerance"]), tol, rel_tol=1e-6)]
        if not ref:
            continue
        ref_row = ref[0]
        r_med, r_max = num(ref_row["median_error"]), num(ref_row["max_error"])
        r_wrong = int(ref_row.get("n_wrong_verdict") or 0)
        ok = [w for w in wmo
              if num(w["median_error"]) <= max(r_med, ROUND_OFF)
              and num(w["max_error"]) <= max(r_max, ROUND_OFF)
              and int(w.get("n_wrong_verdict") or 0) <= r_wrong]
        best = max(ok, key=lambda w: num(w["tolerance"])) if ok else None
        out.append({
            "pair": pair, "wmo_method": wmo_method, "reference": peer, "reference_tolerance": tol,
            "reference_ns": num(ref_row["ns_per_query"]), "reference_median_error": r_med,
            "reference_max_error": r_max,
            "wmo_tolerance": num(best["tolerance"]) if best else math.nan,
            "wmo_ns": num(best["ns_per_query"]) if best else math.nan,
            "wmo_median_error": num(best["median_error"]) if best else math.nan,
            "wmo_max_error": num(best["max_error"]) if best else math.nan,
            "time_ratio": (num(best["ns_per_query"]) / num(ref_row["ns_per_query"])) if best else math.nan,
        })
    return out


def print_matched(rows: list[dict[str, object]], path: Path) -> None:
    print("\nEqual accuracy (overlapping configurations of the sweep): the reference at its default"
          "\ntolerance against the loosest WMO GJK/EPA tolerance with no worse median error, max error"
          "\nand verdicts. ratio < 1: WMO faster.")
    print(f"  {'pair':<18}{'wmo method':<19}{'reference':<16}{'ref ns':>9}{'ref med err':>12}{'ref max err':>12}"
          f"{'wmo tol':>9}{'wmo ns':>9}{'wmo med err':>12}{'wmo max err':>12}{'ratio':>7}")
    for r in rows:
        ratio = r["time_ratio"]
        print(f"  {r['pair']:<18}{r['wmo_method']:<19}{r['reference']:<16}{fmt_ns(r['reference_ns']):>9}"
              f"{fmt_err(r['reference_median_error']):>12}{fmt_err(r['reference_max_error']):>12}"
              f"{('-' if math.isnan(r['wmo_tolerance']) else format(r['wmo_tolerance'], '.0e')):>9}"
              f"{fmt_ns(r['wmo_ns']):>9}{fmt_err(r['wmo_median_error']):>12}{fmt_err(r['wmo_max_error']):>12}"
              f"{('  none' if math.isnan(ratio) else format(ratio, '7.2f')):>7}")
    if rows:
        with path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)


def plot_times(rows: list[dict[str, str]], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pairs = list(dict.fromkeys(r["pair"] for r in rows))
    present = [m for m in METHODS if any(r["method"] == m for r in rows)]
    val = {(r["pair"], r["method"]): num(r["ns_per_query"]) for r in rows}
    fig, ax = plt.subplots(figsize=(13, 5.5))
    width = 0.8 / len(present)
    for i, m in enumerate(present):
        xs = [j + (i - (len(present) - 1) / 2) * width for j in range(len(pairs))]
        ys = [val.get((p, m), math.nan) for p in pairs]
        ax.bar(xs, ys, width, label=m)
    ax.set_yscale("log")
    ax.set_xticks(range(len(pairs)))
    ax.set_xticklabels(pairs, rotation=20, ha="right")
    ax.set_ylabel("time per query (ns, log scale)")
    ax.set_title("Narrowphase: overlap test + penetration depth per query (median of 7 repetitions)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(ncol=len(present), fontsize=9, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_sweep(rows: list[dict[str, str]], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pairs = list(dict.fromkeys(r["pair"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    markers = {"wmo_gjk_epa": "o", "wmo_gjk_epa_point": "P", "libccd_gjk_epa": "s", "libccd_mpr": "^", "fcl": "D",
               "fcl_gjk_epa": "v"}
    ncol = min(len(pairs), 5)
    nrow = (len(pairs) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 4.0 * nrow), squeeze=False)
    flat = [ax for row in axes for ax in row]
    for ax in flat[len(pairs):]:
        ax.set_visible(False)
    # Zero errors cannot be drawn on a log axis; plot them at a floor below round-off.
    floor = 1e-17
    for ax, pair in zip(flat, pairs):
        for m in methods:
            pts = [(num(r["ns_per_query"]), num(r["median_error"]), num(r["tolerance"]))
                   for r in rows if r["pair"] == pair and r["method"] == m]
            pts = [(t, max(e, floor), tol) for t, e, tol in pts if not (math.isnan(t) or math.isnan(e))]
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=markers.get(m, "x"), label=m)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(pair)
        ax.set_xlabel("ns per query")
        ax.grid(which="both", alpha=0.3)
    axes[0][0].set_ylabel("median |depth error| (m)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("Tolerance sweep 1e-2 .. 1e-10 (overlapping configurations; zero error drawn at 1e-17)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/narrowphase", help="output directory (default: results/narrowphase)")
    ap.add_argument("--binary", default=None,
                    help="bench_narrowphase executable (default: build/py/bench_narrowphase, else build/*/)")
    ap.add_argument("--configs", type=int, default=4000, help="configurations per pair (default 4000)")
    ap.add_argument("--no-run", action="store_true", help="only re-read the CSVs and re-plot")
    args = ap.parse_args()

    out = Path(args.out)
    if not out.is_absolute():
        out = Path.cwd() / out
    out.mkdir(parents=True, exist_ok=True)
    if not args.no_run:
        binary = find_binary(args.binary)
        print(f"[run.py] {binary} -> {out}  (machine: {platform.node()}, {platform.processor() or platform.machine()})")
        subprocess.run([str(binary), str(out), str(args.configs)], check=True)

    rows = read_csv(out / "narrowphase.csv")
    print_tables(rows)
    ref_path = out / "reference_check.csv"
    if ref_path.exists():
        print("\nReference check (overlapping configurations; libccd at tolerance 1e-10):")
        for r in read_csv(ref_path):
            print(f"  {r['pair']:<18} reference {r['reference']:<18} median |ref - libccd gjk/epa| "
                  f"{fmt_err(num(r['median_diff_libccd_gjk_epa']))}  |ref - libccd mpr| "
                  f"{fmt_err(num(r['median_diff_libccd_mpr']))}")
    # A binary run for some methods only (WMO_BENCH_METHODS) or pairs may leave a table
    # without rows: say so instead of drawing an empty figure.
    wrote = []
    if rows:
        plot_times(rows, out / "narrowphase_time.png")
        wrote.append(out / "narrowphase_time.png")
    sweep = read_csv(out / "tolerance_sweep.csv")
    if sweep:
        print_matched(matched_accuracy(sweep), out / "matched_accuracy.csv")
        plot_sweep(sweep, out / "tolerance_sweep.png")
        wrote.append(out / "tolerance_sweep.png")
    else:
        print("\n[run.py] tolerance_sweep.csv has no rows (no GJK/EPA method was run): no sweep plot or "
              "equal-accuracy table")
    print(f"\n[run.py] wrote {', '.join(str(p) for p in wrote) or 'no plots'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
