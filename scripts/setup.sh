#!/usr/bin/env bash
# Installs everything WMO needs on a fresh Debian machine (run as root, or with sudo):
# Debian packages (compiler, Eigen, libccd, FCL, GoogleTest, and Chromium for the browser
# view's headless test), a virtual environment in
# .venv with the Python packages from PyPI, and WMO itself as an editable install whose
# build directory (build/py) also holds the C++ tests and benchmarks.
# Idempotent: a second run only rebuilds what changed.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(g++ make pkg-config python3-venv libeigen3-dev libccd-dev libfcl-dev libgtest-dev chromium)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "[setup] installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv"
  "$PY" -m venv .venv
fi
VPY=.venv/bin/python
stamp=.venv/.wmo-deps
want=$(cat pyproject.toml scripts/requirements-dev.txt | sha1sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "[setup] installing Python packages"
  $VPY -m pip install -q --upgrade pip
  $VPY -m pip install -q -r scripts/requirements-dev.txt
  echo "$want" > "$stamp"
fi

echo "[setup] building wmo (editable, build/py)"
$VPY -m pip install -q --no-build-isolation --no-deps -e . \
  -Cbuild-dir=build/py \
  -Ccmake.define.WMO_BUILD_DEV=ON \
  -Ceditable.rebuild=true \
  -Cbuild.verbose=false -Ceditable.verbose=false
