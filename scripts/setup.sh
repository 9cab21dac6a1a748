#!/usr/bin/env bash
# Set up a fresh machine: pinned Python dependencies, this project (editable), the plant FMU.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --disable-pip-version-check -r requirements-ci.txt
python3 -m pip install --quiet --disable-pip-version-check --no-deps -e .
python3 -m fmus.build
