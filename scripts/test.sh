#!/usr/bin/env bash
# Sets up a fresh machine and runs every test: formatting, clippy, unit and property
# tests, end-to-end tests of the real binary (CLI and HTTP service, with the
# external validators pymavlink, shapely and pyproj inside them) on SQLite,
# the service suite again on a throwaway PostgreSQL, schemathesis against
# the live OpenAPI document, and the web page's unit and browser tests.
set -euo pipefail
cd "$(dirname "$0")/.."
# A fresh clone gains nothing from incremental state; it only costs disk.
if [ "${CI:-}" = "true" ]; then export CARGO_INCREMENTAL=0; fi
bash scripts/setup.sh --with-validators
cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
# The end-to-end tests run the real binary, so build it first.
cargo build --workspace --bins
export TERRAPLAN_VENV="$PWD/.venv"

echo "== all tests (SQLite)"
cargo nextest run --workspace --no-fail-fast

echo "== service tests on PostgreSQL"
pgdir=$(mktemp -d)
trap 'bash scripts/pg-cluster.sh stop "$pgdir"; rm -rf "$pgdir"' EXIT
TERRAPLAN_TEST_DATABASE_URL=$(bash scripts/pg-cluster.sh start "$pgdir")
export TERRAPLAN_TEST_DATABASE_URL
cargo nextest run -p terraplan-e2e --no-fail-fast -E 'binary(service) | binary(load) | binary(dems) | binary(survey_terrain) | binary(flock) | binary(costmaps) | binary(routes) | binary(hostile_clients) | binary(memory) | binary(limits) | binary(isolation) | binary(accounts) | binary(auth_matrix) | binary(replicas) | binary(replicas_tiles) | binary(dem_upload_replicas)'
unset TERRAPLAN_TEST_DATABASE_URL

echo "== contract tests (schemathesis)"
bash scripts/schemathesis.sh

echo "== web page: unit tests (Vitest) and browser tests (Chromium)"
(cd web-ui && npm test --silent && npm run --silent test:browser)
