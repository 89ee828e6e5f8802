#!/usr/bin/env bash
# Installs everything (scripts/setup.sh), then runs the main job: the thesis's latency
# experiment in miniature. It starts a local WMO server simulating boxes3000 at 60 Hz, a
# browser view of it (the address is printed: open it while the job runs), and a client
# watching through the latency-injecting proxy at 0, 20, 40 and 100 ms of added latency,
# 10 s each; it prints the server's simulation rate, the client's snapshot rate, the
# end-to-end delay and the bandwidth per run and writes results/latency/latency.csv,
# latency_summary.csv and latency.png. Extra arguments go to `wmo experiment latency`.
# (The boxes3000 engine benchmark against PyBullet and MuJoCo: `wmo bench boxes3000`.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -m wmo experiment latency --out results/latency --view 8080 "$@"
