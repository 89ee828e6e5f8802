"""`wmo experiment latency` end to end, small: a server process, the latency proxy, a
client, CSVs and the plot. Checks what the experiment records, not how fast anything
is (the measured figures are in the closing notes and the README)."""
from __future__ import annotations

import csv

import pytest

pytest.importorskip("msgpack")
pytest.importorskip("websockets")
pytest.importorskip("matplotlib")

from wmo.remote.experiment import run_latency_experiment  # noqa: E402


def test_latency_experiment_records_the_added_delay(tmp_path):
    runs = run_latency_experiment(tmp_path, delays_ms=(0, 60), seconds=2.0, scene_base="tower", warmup=0.0)
    assert [r.label for r in runs] == ["0 ms", "60 ms"]
    fast, slow = (r.summary() for r in runs)
    for s in (fast, slow):
        assert s["snapshots"] > 20  # a 60 Hz scene over 2 s, even on a loaded machine
        assert s["server_steps_per_s"] > 0
        assert s["mbit_per_s"] > 0
    # The proxy delays the server-to-client direction by 60 ms: every snapshot arrives
    # at least that long after its capture (same clock: one machine).
    assert min(1000 * (t - c) for t, c in zip(runs[1].receipt, runs[1].capture)) >= 59.0
    assert slow["delay_median_ms"] > fast["delay_median_ms"] + 50
    with open(tmp_path / "latency_summary.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["label"] for r in rows] == ["0 ms", "60 ms"]
    with open(tmp_path / "latency.csv") as f:
        assert sum(1 for _ in f) == 1 + fast["snapshots"] + slow["snapshots"]
    assert (tmp_path / "latency.png").stat().st_size > 10_000
