#!/usr/bin/env bash
# Contract test: schemathesis against a live `terraplan serve` (its own
# OpenAPI document), a bounded number of examples per operation. Fails on
# any 5xx or any response that does not match the documented schema.
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'kill -TERM "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
target/debug/terraplan serve --port 0 --data-dir "$work/data" >"$work/addr" 2>"$work/log" &
pid=$!
for _ in $(seq 1 100); do
  [ -s "$work/addr" ] && break
  sleep 0.1
done
base=$(sed -n 's/^listening on //p' "$work/addr")
[ -n "$base" ] || { cat "$work/log" >&2; echo "schemathesis.sh: server did not start" >&2; exit 1; }
.venv/bin/schemathesis run "$base/api/v1/openapi.json" \
  --url "$base" \
  --checks not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance,response_headers_conformance \
  --max-examples "${SCHEMATHESIS_MAX_EXAMPLES:-40}" \
  --seed 1 \
  --no-color
