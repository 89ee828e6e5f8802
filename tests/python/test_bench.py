"""wmo.bench and ``python -m wmo bench``: every engine steps the same scene, the CSV
has a row per engine and step, the plots are written, and bad arguments are refused.
Speed is measured by the benchmark itself, never asserted here."""
from __future__ import annotations

import csv
import importlib.util
import math
import subprocess
import sys

import pytest

from wmo import bench

PEERS = [e for e in ("pybullet", "mujoco") if importlib.util.find_spec(e) is not None]


def test_every_engine_runs_the_same_scene(tmp_path):
    result = bench.run_bench("pyramid", steps=2, engines=["wmo", *PEERS])
    assert [r.engine for r in result.runs] == ["wmo", *PEERS]
    for r in result.runs:
        assert len(r.records) == 2
        assert all(x.seconds > 0 for x in r.records)
        # 2870 boxes resting face to face: every engine sees tens of thousands of
        # contact points and (on the first steps) almost no penetration.
        assert r.records[-1].contacts > 20000, r.engine
        assert r.records[-1].max_penetration < 0.05, r.engine
    path = tmp_path / "steps.csv"
    bench.write_csv(result, path, 1 / 60)
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == 2 * len(result.runs)
    assert set(rows[0]) == {"scene", "engine", "step", "sim_time_s", "step_seconds", "contact_points",
                            "awake_bodies", "max_penetration_m"}
    assert float(rows[1]["sim_time_s"]) == pytest.approx(2 / 60, rel=1e-8)
    for p in bench.plot(result, 1 / 60, tmp_path):
        assert p.stat().st_size > 1000
    assert "ratio to wmo" in result.summary()


def test_interleaved_turns_give_each_engine_the_same_steps_as_running_alone(monkeypatch):
    # The engines take turns of BLOCK steps (12 steps in turns of 5: 5, 5, 2), each on its
    # own scene: every engine's per-step contacts and deepest penetration are those of
    # running it alone (the engines are deterministic), and it takes exactly `steps`.
    monkeypatch.setattr(bench, "BLOCK", 5)
    together = bench.run_bench("pyramid", steps=12, engines=["wmo", *PEERS])
    alone = bench.run_bench("pyramid", steps=12, engines=["wmo", *PEERS], interleave=False)
    assert together.interleaved and not alone.interleaved
    assert "interleaved in turns of 5 steps" in together.summary()
    assert [r.engine for r in together.runs] == [r.engine for r in alone.runs] == ["wmo", *PEERS]
    for t, a in zip(together.runs, alone.runs):
        assert [x.step for x in t.records] == list(range(1, 13)), t.engine
        assert [(x.contacts, x.max_penetration) for x in t.records] == \
            [(x.contacts, x.max_penetration) for x in a.records], t.engine


def _row(a, b, x=0.0, dist=-1e-3):
    # getContactPoints' layout: flag, body A, body B, link A, link B, point on A, point on B,
    # normal on B, distance, normal force, ...
    return (0, a, b, -1, -1, (x, 0.0, 0.0), (x, 0.0, 0.0), (0.0, 1.0, 0.0), dist, 1.0)


def test_pybullet_rows_stop_where_the_server_ran_past_its_points():
    real = [_row(0, 1, 0.1), _row(0, 1, 0.2), _row(1, 2, 0.3), _row(2, 3, 0.4), _row(2, 3, 0.5)]

    def rows(extra, now=real):
        # What getContactPoints returns: the real rows, then what lay past them; and the
        # call filtered to a pair, which returns that pair's real rows only.
        return bench.pybullet_contact_rows(real + extra, lambda a, b: [r for r in now if r[1:3] == (a, b)])

    assert rows([]) == real
    # Zeros past the end (a fresh cache): a body against itself.
    assert rows([(0, 0, 0, 0, 0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, 0.0, 0.0)] * 3) == real
    # Rows left by an earlier query: a pair already seen, even when well formed.
    assert rows([_row(1, 2, 0.35), _row(7, 8)]) == real
    # Garbage: an out-of-range link, a NaN distance.
    bad_link = (0, 4, 5, 3, -1, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, -1e-3, 0.0)
    assert rows([bad_link, _row(4, 5)]) == real
    assert rows([_row(4, 5, dist=math.nan)]) == real
    # A manifold holds at most 4 points, none twice: past that, the rows are stale.
    assert rows([_row(2, 3, 0.5)]) == real
    # Stale rows of pairs with no real contact now (an earlier client's later step: new
    # contacts it had made), or continuing the last group with points it no longer has:
    # well formed, new pairs, yet not what the pair's own call returns.
    assert rows([_row(5, 6, 0.1), _row(5, 6, 0.2), _row(6, 7, 0.3)]) == real
    assert rows([_row(2, 3, 0.6), _row(2, 3, 0.7), _row(8, 9)]) == real
    # The real rows themselves are all kept, however many pairs.
    many = [_row(i, i + 1, 0.1 * k) for i in range(1, 40) for k in range(1 + i % 4)]
    assert bench.pybullet_contact_rows(many + [_row(50, 51)],
                                       lambda a, b: [r for r in many if r[1:3] == (a, b)]) == many


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="scene"):
        bench.run_bench("tower_of_babel", steps=1)
    with pytest.raises(ValueError, match="steps"):
        bench.run_bench("pyramid", steps=0)
    with pytest.raises(ValueError, match="engine"):
        bench.run_bench("pyramid", steps=1, engines=["havok"])


def test_command_line(tmp_path):
    out = subprocess.run([sys.executable, "-m", "wmo", "bench", "pyramid", "--steps", "1", "--engines", "wmo",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "wmo" in out.stdout and (tmp_path / "pyramid_steps.csv").is_file()
    bad = subprocess.run([sys.executable, "-m", "wmo", "bench", "pyramid", "--dt", "0"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "dt" in bad.stderr
    # The contact spring reaches WMO's World and is named in the settings it prints.
    stiff = subprocess.run([sys.executable, "-m", "wmo", "bench", "pyramid", "--steps", "1", "--engines", "wmo",
                            "--substeps", "8", "--contact-hertz", "45", "--out", str(tmp_path)],
                           capture_output=True, text=True, timeout=300)
    assert stiff.returncode == 0, stiff.stderr
    assert "8 substeps" in stiff.stdout and "45 Hz contacts" in stiff.stdout
    bad = subprocess.run([sys.executable, "-m", "wmo", "bench", "pyramid", "--contact-hertz", "-1"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "contact-hertz" in bad.stderr


def test_contact_hertz_reaches_the_world(monkeypatch):
    # Through run_wmo's World: a different spring gives a different first step.
    spec = bench._scenes.SPECS["pyramid"]()
    default = bench.run_wmo(spec, 2, 1 / 60, 10, 4, False)
    monkeypatch.setattr(bench, "WMO_CONTACT_HERTZ", 45.0)
    stiff = bench.run_wmo(spec, 2, 1 / 60, 10, 4, False)
    assert "45 Hz contacts" in stiff.settings and "default contact Hz" in default.settings
    assert stiff.records[-1].max_penetration != default.records[-1].max_penetration


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="memory is read from /proc (Linux)")
def test_memory_is_measured_in_a_fresh_process(tmp_path):
    # A small pyramid, a few steps: the child process reports a peak above its
    # baseline, and the scene's bytes per body are those of real storage (more than
    # the 7 doubles of a pose, less than a megabyte).
    runs, skipped = bench.measure_memory("pyramid", steps=3, engines=["wmo"])
    assert skipped == {}
    (r,) = runs
    assert r.engine == "wmo" and r.bodies == 2871
    assert r.peak_bytes > r.baseline_bytes > 0
    assert 56 < r.bytes_per_body < 1e6
    path = tmp_path / "m.csv"
    bench.write_memory_csv("pyramid", runs, path)
    rows = list(csv.DictReader(open(path)))
    assert rows[0]["engine"] == "wmo" and int(rows[0]["bodies"]) == 2871
    with pytest.raises(ValueError, match="scene"):
        bench.measure_memory("nope", steps=1)
    with pytest.raises(ValueError, match="engine"):
        bench.measure_memory("pyramid", steps=1, engines=["havok"])
