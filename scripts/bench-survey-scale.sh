#!/usr/bin/env bash
# Times `terraplan survey` (release build) against the ROI's vertex count
# (round fields of 1 000 … 50 000 vertices) and the number of no-fly zones
# (10 … 5 000 small hexagons in a 2 km square) and prints each series with
# its slope on a log-log scale (issue 17's target: at most 1.2). Writes
# target/bench-survey-scale.json. Run by hand:
#   bash scripts/bench-survey-scale.sh [--max-seconds 120]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin terraplan
exec python3 scripts/bench_survey_scale.py "$@"
