#!/usr/bin/env bash
# Sets up a fresh machine and runs every test: formatting, unit and property
# tests, end-to-end tests against the real binary, and the external
# validators (pymavlink, shapely) inside them.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --with-validators
cargo fmt --all -- --check
# The end-to-end tests run the real binary, so build it first.
cargo build --workspace --bins
TERRAPLAN_VENV="$PWD/.venv" cargo nextest run --workspace --no-fail-fast
