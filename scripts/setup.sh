#!/usr/bin/env bash
# One-time (idempotent) set-up of cfvs_maniskill on a Debian 12 machine as root:
#   - system libraries SAPIEN's renderer (libx11-6) and open3d (libusb-1.0-0) need,
#   - a Python 3.11 virtual environment in .venv with the package (editable) and its pins,
#   - SwiftShader (a CPU Vulkan driver) taken out of Debian's chromium-common .deb by the
#     package's `cfvs-maniskill setup-render`, used only when no GPU is present.
# A second run takes seconds: every step checks first whether it is already done.
set -euo pipefail
cd "$(dirname "$(readlink -f "$0")")/.."
ROOT=$PWD
VENV=$ROOT/.venv
SWIFTSHADER_DIR=$VENV/share/cfvs_maniskill/swiftshader

log() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

apt_ready=0
need_apt() {
  if [ "$apt_ready" = 0 ]; then
    command -v apt-get >/dev/null || { echo "apt-get not found: install $* by hand" >&2; exit 1; }
    log "apt-get update"
    apt-get update -qq
    apt_ready=1
  fi
}

# 1. System libraries (only what is missing).
missing=()
ldconfig -p | grep 'libX11.so.6' >/dev/null || missing+=(libx11-6)
# open3d (ICP / RANSAC baselines) links libusb even in its CPU build.
ldconfig -p | grep 'libusb-1.0.so.0' >/dev/null || missing+=(libusb-1.0-0)
python3.11 -m venv --help >/dev/null 2>&1 || missing+=(python3.11-venv)
command -v python3.11 >/dev/null || missing+=(python3.11)
if [ ${#missing[@]} -gt 0 ]; then
  need_apt "${missing[@]}"
  log "installing ${missing[*]}"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# 2. Virtual environment + package. Re-installed only when pyproject.toml or the lock changes.
if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV"
  python3.11 -m venv "$VENV"
fi
stamp=$VENV/.cfvs_installed
want=$(cat pyproject.toml constraints.txt | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  log "installing the package and its pinned dependencies (first run: a few minutes)"
  # torch first, pinned: pip then never pulls the multi-GB CUDA build as a dependency.
  "$VENV/bin/pip" install -q "torch==2.13.0"
  # constraints.txt: every indirect package at the version the tests ran with.
  "$VENV/bin/pip" install -q -c constraints.txt -e ".[dev]"
  echo "$want" > "$stamp"
fi

# 3. SwiftShader Vulkan ICD (5 MB), unless a GPU render node exists or it is already here:
#    the package's own set-up command, which pip-install users run themselves.
if [ ! -f "$SWIFTSHADER_DIR/vk_swiftshader_icd.json" ]; then
  log "setting up the renderer"
  "$VENV/bin/cfvs-maniskill" setup-render --dest "$SWIFTSHADER_DIR"
fi
log "ready: $("$VENV/bin/python" -c 'import cfvs_maniskill.rendering.device as d; print(d.describe())')"
