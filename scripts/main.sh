#!/usr/bin/env bash
# Installs everything (scripts/setup.sh), then runs the main job: the boxes3000 scene
# benchmark (shared/SCENES.md) in WMO, PyBullet and MuJoCo in the same run, 600 steps,
# sleeping off, one thread. It prints the summary with the ratios and writes a CSV per
# step and PNG plots to results/bench/. Extra arguments go to `wmo bench`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -m wmo bench boxes3000 --out results/bench "$@"
