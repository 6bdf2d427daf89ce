#!/usr/bin/env bash
# Contract test: schemathesis against a live `terraplan serve` (its own
# OpenAPI document), a bounded number of examples per operation.
# Pass 1 calls as the first-start admin (its API token): no 5xx, every
# answer as documented, and `ignored_auth` checks that each operation that
# declares credentials refuses a request without them. Revoking tokens and
# disabling users are left out of it: its stateful phase would revoke its
# own token or disable its own user (tests/tests/accounts.rs covers both). Pass 2 sends no
# credentials: every operation that requires them answers 401.
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'kill -TERM "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
# Rate limits off: the contract test sends far more than a person would.
target/debug/terraplan serve --port 0 --data-dir "$work/data" \
  --planning-per-minute 0 --sign-in-per-minute 0 >"$work/out" 2>"$work/log" &
pid=$!
token=""
for _ in $(seq 1 300); do
  token=$(sed -n 's/^first start: .*Bearer \(tp_[A-Za-z0-9_-]*\).*/\1/p' "$work/out")
  [ -n "$token" ] && break
  sleep 0.1
done
base=$(sed -n 's/^listening on //p' "$work/out")
[ -n "$base" ] && [ -n "$token" ] || {
  cat "$work/log" >&2
  echo "schemathesis.sh: the server did not start, or printed no first-start token" >&2
  exit 1
}
common=(--seed 1 --no-color)
echo "== schemathesis, signed in with an API token"
TERRAPLAN_TOKEN="$token" .venv/bin/schemathesis --config-file tests/validators/schemathesis.toml \
  run "$base/api/v1/openapi.json" \
  --url "$base" \
  --checks not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance,response_headers_conformance,ignored_auth \
  --exclude-operation-id delete_token --exclude-operation-id disable_user \
  --max-examples "${SCHEMATHESIS_MAX_EXAMPLES:-40}" \
  "${common[@]}"
echo "== schemathesis, without credentials"
SCHEMATHESIS_HOOKS=schemathesis_hooks PYTHONPATH=tests/validators \
  .venv/bin/schemathesis run "$base/api/v1/openapi.json" \
  --url "$base" \
  --checks not_a_server_error,refused_without_credentials \
  --max-examples "${SCHEMATHESIS_NOAUTH_EXAMPLES:-8}" \
  "${common[@]}"
