#!/usr/bin/env bash
# Times `terraplan route` (A*) next to scikit-image's MCP_Geometric and
# pyastar2d on a 4000 x 4000 costmap built from the opengeos DTM, and a
# D* Lite replan after blocking 20 m of the route; prints a table and
# writes target/bench-route.json. Run by hand:
#   bash scripts/bench-route.sh [--runs 3] [--size 4000]
# Needs GDAL's command-line tools and the validators' venv (made here).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --with-validators
# pyastar2d, the benchmark's other peer, from PyPI (its own stamp).
stamp=".venv/.bench-route-$(sha1sum scripts/bench-route-requirements.txt | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  .venv/bin/pip install --quiet --disable-pip-version-check --no-deps \
    -r scripts/bench-route-requirements.txt
  touch "$stamp"
fi
cargo build --release --bin terraplan
exec .venv/bin/python scripts/bench_route.py "$@"
