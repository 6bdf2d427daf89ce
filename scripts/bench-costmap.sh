#!/usr/bin/env bash
# Times `terraplan costmap` next to `gdaldem slope` (wall time and peak RSS)
# on the largest shared DEM and a 4000 x 4000 upsample of the opengeos DTM;
# prints a table and writes target/bench-costmap.json. Run by hand:
#   bash scripts/bench-costmap.sh [--runs 3] [--size 4000]
# Needs GDAL's command-line tools (gdal-bin).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin terraplan
exec /usr/bin/python3 scripts/bench_costmap.py "$@"
