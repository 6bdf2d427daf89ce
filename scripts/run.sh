#!/usr/bin/env bash
# Sets up a fresh machine and runs terraplan. With no arguments it plans a
# survey of a real field (Fields2Cover's test parcel) with a no-fly zone and
# writes the mission files to ./out; otherwise the arguments go to terraplan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if [ "$#" -eq 0 ]; then
  set -- survey --roi examples/field.geojson --no-fly examples/field-nfz.geojson \
    --params examples/params.json --out out
fi
exec cargo run --release --quiet -p terraplan -- "$@"
