#!/usr/bin/env bash
# The crates that run only while building (proc macros, build scripts and
# their dependencies), the list behind `[profile.dev.package]`'s
# `opt-level = 0` entries in Cargo.toml:
#
#   tools/build-only-crates.sh            # the names, one per line
#   tools/build-only-crates.sh --check    # exit 1 naming any not in Cargo.toml
#
# Cargo's `package."*"` override outranks `build-override`, so such a
# crate not listed is compiled at opt-level 2 (slower builds, nothing
# wrong). Crates that also run in a test (cbindgen in the header test,
# and the syn, quote, proc-macro2 and unicode-ident it parses with) are
# listed by hand in Cargo.toml. The check looks for `NAME = { opt-level =
# 0 }` lines, the form Cargo.toml's table uses.
set -euo pipefail
cd "$(dirname "$0")/.."
export LC_ALL=C

packages() {
    local tree
    tree=$(cargo tree --workspace --prefix none --format '{p}' "$@") || {
        echo "cargo tree failed" >&2
        exit 2
    }
    echo "$tree" | awk '{print $1}' | sort -u
}

all=$(packages -e normal,build,dev)
run_time=$(packages -e normal,dev,no-proc-macro)
build_only=$(comm -23 <(echo "$all") <(echo "$run_time"))

if [ "${1:-}" != "--check" ]; then
    echo "$build_only"
    exit 0
fi
missing=()
for name in $build_only; do
    if ! grep -Eq "^${name} = \{ opt-level = 0 \}" Cargo.toml; then
        missing+=("$name")
    fi
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "built only while building, but optimised (add to [profile.dev.package] in Cargo.toml):" >&2
    printf '  %s = { opt-level = 0 }\n' "${missing[@]}" >&2
    exit 1
fi
echo "every crate that runs only while building is unoptimised"
