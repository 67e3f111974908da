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
# wrong). A crate used at run time too (syn, quote and proc-macro2 through
# cbindgen in the header test) is listed by hand in Cargo.toml.
set -euo pipefail
cd "$(dirname "$0")/.."

packages() {
    cargo tree --workspace --prefix none --format '{p}' "$@" 2>/dev/null |
        awk '{print $1}' | sort -u
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
