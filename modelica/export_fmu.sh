#!/usr/bin/env bash
# Export ArmExo.ArmExoPlant (or the model given as $1) as an FMI 2.0 Co-Simulation FMU with
# OpenModelica's omc, into fmus/build/. Without omc it says so and exits with status 2;
# the C FMU (python -m fmus.build) needs only a C compiler.
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 -m fmus.export_omc --model "${1:-ArmExo.ArmExoPlant}"
