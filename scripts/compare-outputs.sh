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
# The base is built from a worktree in the same target directory (its
# dependencies are already compiled there) and its binary copied aside
# before the working tree's is built over it.
target=$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')
git worktree add --detach "$work/base" "$base" >/dev/null
(cd "$work/base" && CARGO_TARGET_DIR="$target" cargo build --quiet --bin terraplan)
cp "$target/debug/terraplan" "$work/terraplan-base"
cargo build --quiet --bin terraplan
python3 scripts/output_snapshot.py "$work/terraplan-base" "$work/before"
python3 scripts/output_snapshot.py "$target/debug/terraplan" "$work/after"
files=$(cd "$work/after" && find . -type f | wc -l)
if diff -r "$work/before" "$work/after"; then
    echo "outputs identical to $base: $files files"
else
    echo "outputs differ from $base (above)" >&2
    exit 1
fi
