"""benchmarks/narrowphase/run.py re-reads what a filtered run of the binary wrote (one
method, as the binary's WMO_BENCH_METHODS allows for a profiler) without failing: that
run has no tolerance sweep, and the script used to divide by its zero pairs."""
from __future__ import annotations

import csv
import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BINARY = ROOT / "build" / "py" / "bench_narrowphase"


@pytest.mark.skipif(not BINARY.exists(), reason=f"{BINARY} is not built (the dev build, scripts/setup.sh, builds it)")
def test_run_py_reads_a_run_of_one_method(tmp_path):
    env = dict(os.environ, WMO_BENCH_METHODS="wmo_special")
    subprocess.run([str(BINARY), str(tmp_path), "50", "box_box"], env=env, check=True, capture_output=True,
                   timeout=300)
    rows = list(csv.DictReader(open(tmp_path / "narrowphase.csv")))
    assert {(r["pair"], r["method"]) for r in rows} == {("box_box", "wmo_special")}
    assert not list(csv.DictReader(open(tmp_path / "tolerance_sweep.csv")))
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks/narrowphase/run.py"), "--out", str(tmp_path),
                          "--no-run"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "no GJK/EPA method was run" in out.stdout
    assert (tmp_path / "narrowphase_time.png").stat().st_size > 0
    assert not (tmp_path / "tolerance_sweep.png").exists()
