#!/usr/bin/env bash
# The same bake through `aobake serve` (its local workers, fresh SQLite and
# blobs each run) and through `aobake bake`, interleaved: the wall seconds
# of each, their ratio, and whether the two assets are the same bytes.
#
#   tools/service-vs-bake.sh BIN FILE METHOD [RUNS] [WORKERS] [-- BAKE OPTIONS...]
#
# The service's time runs from `submit` (upload included) to its bake's end,
# previews included; `aobake bake` renders none. Medians are printed at the
# end. Example (issue 25's check):
#   tools/service-vs-bake.sh target/release/aobake ../shared/data/Fox/Fox.glb vertex-linear 3 2
set -euo pipefail
bin=$(realpath "$1"); file=$(realpath "$2"); method=$3
runs=${4:-3}; workers=${5:-2}
shift $(( $# < 5 ? $# : 5 ))
[[ ${1:-} == -- ]] && shift
extra=("$@")
tmp=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$tmp"' EXIT
now() { date +%s.%N; }
cli_times=(); service_times=()
for run in $(seq "$runs"); do
  t0=$(now)
  "$bin" bake "$file" --method "$method" "${extra[@]}" --out "$tmp/cli.aob" --report "$tmp/cli.json" >/dev/null 2>&1
  cli=$(echo "$(now) - $t0" | bc)

  data="$tmp/data-$run"
  "$bin" serve --data "$data" --listen 127.0.0.1:0 --workers "$workers" >"$tmp/serve.log" 2>&1 &
  serve=$!
  for _ in $(seq 300); do [[ -s $data/server.url && -s $data/admin.token ]] && break; sleep 0.1; done
  t0=$(now)
  "$bin" submit --data "$data" "$file" --method "$method" "${extra[@]}" --wait >"$tmp/submit.log" 2>&1 \
    || { cat "$tmp/submit.log" "$tmp/serve.log" >&2; exit 1; }
  service=$(echo "$(now) - $t0" | bc)
  id=$(grep -o 'bake [0-9]*' "$tmp/submit.log" | head -1 | cut -d' ' -f2)
  "$bin" fetch --data "$data" "$id" --out "$tmp/service.aob" >/dev/null
  kill "$serve"; wait "$serve" 2>/dev/null || true

  same=no; cmp -s "$tmp/cli.aob" "$tmp/service.aob" && same=yes
  printf 'run %d: aobake bake %.1f s, service (%d workers) %.1f s, ratio %.3f, same bytes: %s\n' \
    "$run" "$cli" "$workers" "$service" "$(echo "$service / $cli" | bc -l)" "$same"
  [[ $same == yes ]] || { echo "the assets differ" >&2; exit 1; }
  cli_times+=("$cli"); service_times+=("$service")
done
median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
c=$(median "${cli_times[@]}"); s=$(median "${service_times[@]}")
printf 'median of %d: aobake bake %.1f s, service %.1f s, ratio %.3f\n' "$runs" "$c" "$s" "$(echo "$s / $c" | bc -l)"
