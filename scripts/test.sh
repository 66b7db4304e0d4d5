#!/usr/bin/env bash
# Sets everything up (idempotent), then lints and runs the whole test suite, slow tests included.
set -euo pipefail
cd "$(dirname "$(readlink -f "$0")")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
.venv/bin/ruff format --check .
# Two workers (pytest-xdist) on the 2 cores; tests marked xdist_group share one worker.
.venv/bin/python -m pytest -q -n 2 --dist loadgroup --durations=15 "$@"
