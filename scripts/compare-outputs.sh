#!/usr/bin/env bash
# Plans the same real inputs (scripts/output_snapshot.py: surveys with NFZs,
# flocks and sorties, terrain following, costmaps, a route with a replan)
# with the binary of a base revision and with the working tree's, and
# compares every output file byte for byte (wall-clock timings masked).
# For refactors that must not change any result. Run by hand:
#   bash scripts/compare-outputs.sh [BASE_REV]      (default: HEAD)
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-HEAD}
work=$(mktemp -d)
trap 'git worktree remove --force "$work/base" >/dev/null 2>&1 || true; rm -rf "$work"' EXIT
# The base is built in a worktree next to this one (the inputs are read
# from ../shared relative to the checkout), with its own target directory.
git worktree add --detach "$work/base" "$base" >/dev/null
base_target=${BASE_TARGET_DIR:-$PWD/target/compare-base}
(cd "$work/base" && CARGO_TARGET_DIR="$base_target" cargo build --quiet --bin terraplan)
cargo build --quiet --bin terraplan
target=${CARGO_TARGET_DIR:-target}
python3 scripts/output_snapshot.py "$base_target/debug/terraplan" "$work/before"
python3 scripts/output_snapshot.py "$target/debug/terraplan" "$work/after"
files=$(cd "$work/after" && find . -type f | wc -l)
if diff -r "$work/before" "$work/after"; then
    echo "outputs identical to $base: $files files"
else
    echo "outputs differ from $base (above)" >&2
    exit 1
fi
