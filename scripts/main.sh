#!/usr/bin/env bash
# Installs everything (scripts/setup.sh), then runs the main job: the narrowphase
# benchmark (WMO special routines and GJK/EPA against libccd and FCL). It prints its
# table and writes CSV and PNG plots to results/narrowphase/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/cmake --build build/py -j"$(nproc)" --target bench_narrowphase
.venv/bin/python benchmarks/narrowphase/run.py --out results/narrowphase "$@"
