#!/usr/bin/env bash
# Sets everything up (idempotent), then lints and runs the whole test suite, slow tests included.
set -euo pipefail
cd "$(dirname "$(readlink -f "$0")")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
.venv/bin/ruff format --check .
.venv/bin/python -m pytest -q "$@"
