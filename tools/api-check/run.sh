#!/usr/bin/env bash
# Lints api-spec/openapi.yaml (openapi-spec-validator) and runs schemathesis
# against a live `aobake serve` on a temporary data directory. Needs
# Python 3 and network access to PyPI the first time (a venv in
# target/api-check-venv). Usage: tools/api-check/run.sh [max examples]
set -euo pipefail
cd "$(dirname "$0")/../.."
venv=target/api-check-venv
if [ ! -x "$venv/bin/schemathesis" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q 'schemathesis>=4,<5' openapi-spec-validator
fi
"$venv/bin/python" - <<'PY'
from openapi_spec_validator import validate
from openapi_spec_validator.readers import read_from_filename
spec, _ = read_from_filename("api-spec/openapi.yaml")
validate(spec)
print("api-spec/openapi.yaml: valid OpenAPI 3.1")
PY
cargo build --release --bin aobake
data=$(mktemp -d)
AOBAKE_ADMIN_TOKEN=api-check-token target/release/aobake serve --data "$data" \
    --listen 127.0.0.1:0 --workers 1 --rate 100000 2>"$data/server.log" &
server=$!
trap 'kill $server; wait $server 2>/dev/null; rm -rf "$data"' EXIT
while [ ! -s "$data/server.url" ]; do sleep 0.1; done
url=$(cat "$data/server.url")
# A character, so that reads find something.
curl -sf -X POST -H "Authorization: Bearer api-check-token" \
    -H "Content-Type: model/gltf-binary" \
    --data-binary @tests/data/characters/RiggedSimple/RiggedSimple.glb \
    "$url/v1/characters" >/dev/null
"$venv/bin/schemathesis" run api-spec/openapi.yaml --url "$url" \
    -H "Authorization: Bearer api-check-token" \
    --checks not_a_server_error,status_code_conformance,content_type_conformance,response_headers_conformance,response_schema_conformance \
    --max-examples "${1:-50}"
if grep -q "error: internal" "$data/server.log"; then
    echo "the server logged internal errors:" >&2
    grep "error: internal" "$data/server.log" >&2
    exit 1
fi
