#!/usr/bin/env bash
# terraplan's flock makespans next to OR-tools' routing solver (5 s and
# 30 s, guided local search) and PyVRP on the same routing instances, the
# ones `terraplan experiment flock --instances` writes (issue 21, item 3);
# prints a table and writes target/bench-flock.json. Run by hand:
#   bash scripts/bench-flock.sh            # 14 representative instances, ~10 min
#   bash scripts/bench-flock.sh --all      # all 60, ~40 min
# (other options: see scripts/bench_flock.py). The solvers come from PyPI
# into their own venv; nothing else is downloaded.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
venv="$target/bench-flock-venv"
stamp="$venv/.stamp-$(sha1sum scripts/bench-flock-requirements.txt | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check \
    -r scripts/bench-flock-requirements.txt
  touch "$stamp"
fi
cargo build --release --bin terraplan
exec "$venv/bin/python" scripts/bench_flock.py "$@"
