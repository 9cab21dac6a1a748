#!/usr/bin/env bash
# Set up a fresh machine: pinned Python dependencies, this project (editable), the plant FMUs.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --disable-pip-version-check -r requirements-ci.txt
python3 -m pip install --quiet --disable-pip-version-check --no-deps -e .
# The Modelica exporter (modelica==0.0.205, pinned in requirements-export.txt) needs
# Python >= 3.12: installed into such an interpreter when one exists (pyenv, or
# python3.12/3.13 on PATH). Without one, `python3 -m fmus.build` says so in one line and
# builds the C plant only.
export_python=""
if command -v pyenv >/dev/null 2>&1; then
    for v in $(pyenv versions --bare 2>/dev/null | grep -E '^3\.(1[2-9])(\.|$)' | sort -V); do
        export_python="$(pyenv root)/versions/$v/bin/python"
        break
    done
fi
if [ -z "$export_python" ]; then
    for name in python3.12 python3.13; do
        if command -v "$name" >/dev/null 2>&1; then export_python="$(command -v "$name")"; break; fi
    done
fi
if [ -n "$export_python" ]; then
    "$export_python" -m pip install --quiet --disable-pip-version-check -r requirements-export.txt \
        || echo "note: installing the Modelica exporter into $export_python failed; the C plant is used"
else
    echo "note: no Python >= 3.12 found for the Modelica exporter; the C plant is used"
fi
python3 -m fmus.build
