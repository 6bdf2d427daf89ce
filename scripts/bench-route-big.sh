#!/usr/bin/env bash
# Times `terraplan route` coarse to fine next to plain A* on the route
# benchmark's 4000 x 4000 costmap (both sides: wall time, search time,
# peak RSS, cost), and coarse to fine alone on the costmap upsampled to
# 30000 x 30000 (3.6 GB in --work or a temporary directory); prints a table
# and writes target/bench-route-big.json. Run by hand:
#   bash scripts/bench-route-big.sh [--runs 3] [--size 4000] [--big-size 30000]
#        [--max-corridor-cells N] [--work DIR] [--skip-big]
# Needs GDAL's command-line tools and the validators' venv (made here).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --with-validators
cargo build --release --bin terraplan
exec .venv/bin/python scripts/bench_route_big.py "$@"
