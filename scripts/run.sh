#!/usr/bin/env bash
# Sets up a fresh machine and runs terraplan. With no arguments: the service
# on its embedded default (http://127.0.0.1:8080, SQLite in ./terraplan-data).
# With arguments: any terraplan command, e.g.
#   bash scripts/run.sh survey --roi examples/field.geojson --out out
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if [ "$#" -eq 0 ]; then
  set -- serve
fi
exec cargo run --release --quiet -p terraplan -- "$@"
