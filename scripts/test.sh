#!/usr/bin/env bash
# Installs everything (scripts/setup.sh), then runs every C++ test (ctest) and every
# Python test (pytest). Exit status is non-zero if any test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "[test] building C++ tests and benchmarks (build/py)"
.venv/bin/cmake --build build/py -j"$(nproc)"
echo "[test] C++ tests (ctest)"
.venv/bin/ctest --test-dir build/py --output-on-failure -j"$(nproc)" --timeout 900
echo "[test] Python tests (pytest)"
.venv/bin/python -m pytest -q tests/python
