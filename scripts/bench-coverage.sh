#!/usr/bin/env bash
# Plans the same fields with `terraplan survey` and Fields2Cover 2.1.0
# (swath widths 20 m and 40 m, with and without obstacles, one UTM zone per
# field) and prints lanes, turns, path length, coverage by swath strips
# (one shapely measure for both), metres per covered hectare and time side
# by side; writes target/bench-coverage.json. Run by hand:
#   STEERING_FUNCTIONS_DIR=DIR bash scripts/bench-coverage.sh [--widths 20,40]
#       [--fields all|test_parcel,il_field1,il_field2,nl_parcel,rmnp]
#       [--obstacles both|no|yes] [--runs 1]
# DIR: Fields2Cover's steering_functions (see scripts/f2c/build.sh, which
# builds Fields2Cover from its PyPI sdist without OR-tools). Without it, or
# if that build fails, only terraplan's side is measured and the reason is
# printed in Fields2Cover's rows.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --with-validators
stamp=".venv/.bench-coverage-$(sha1sum scripts/bench-coverage-requirements.txt | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  .venv/bin/pip install --quiet --disable-pip-version-check --no-deps \
    -r scripts/bench-coverage-requirements.txt
  touch "$stamp"
fi
cargo build --release --bin terraplan
no_f2c=()
mkdir -p target
if ! bash scripts/f2c/build.sh 2>target/f2c-build.err; then
  cat target/f2c-build.err >&2
  no_f2c=(--no-f2c "not built: $(grep '^build.sh:' target/f2c-build.err | tail -1)")
fi
exec .venv/bin/python scripts/bench_coverage.py "${no_f2c[@]}" "$@"
