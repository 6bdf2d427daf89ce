#!/usr/bin/env bash
# Times `terraplan survey` (release build) for a fixed-wing and a VTOL plane
# against the multirotor plan of bench-survey-scale.sh's 1 000-NFZ input
# (issue 20's target: at most 3x). Writes target/bench-survey-aircraft.json.
# Run by hand:
#   bash scripts/bench-survey-aircraft.sh [--zones 1000] [--runs 3]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin terraplan
exec python3 scripts/bench_survey_aircraft.py "$@"
