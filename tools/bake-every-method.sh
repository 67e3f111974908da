#!/bin/bash
# Bakes every method once at small settings with the given `aobake` binary
# and prints each asset's sha256 and bake key: run it with the binaries of
# two commits and diff the outputs to check that a change kept assets and
# keys byte for byte.
#
#   tools/bake-every-method.sh target/release/aobake /tmp/after > after.txt
set -euo pipefail
B=$1; O=$2; D=$(cd "$(dirname "$0")/../tests/data/characters" && pwd)
mkdir -p "$O"
V=(--poses 24 --samples 8 --eval-poses 4 --param eval_folds=2 --seed 3)
C=(--param cubemap.resolution=8 --param cubemap.shells=2 --param cubemap.times=15 --param cubemap.rays=8
   --param cubemap.eval_points=64 --param cubemap.eval_ground=64 --param cubemap.eval_rays=16 --param cubemap.eval_times=2 --seed 3)
G=(--param grid.resolution=8 --param grid.rays=16 --param grid.eval_rays=16 --param grid.eval_frames=2
   --param grid.eval_ground=64 --param grid.tclip_resolution=8 --param grid.average_frames=4 --seed 3)
bake() { "$B" bake "$D/$1" --method "$2" "${@:4}" --out "$O/$3.aob" --report "$O/$3.json" >/dev/null 2>&1; }
bake RiggedFigure/RiggedFigure.glb static-average sa "${V[@]}"
bake RiggedFigure/RiggedFigure.glb vertex-linear vl "${V[@]}"
bake RiggedFigure/RiggedFigure.glb vertex-clustered vc "${V[@]}" --param clustered.pose_clusters=2
bake RiggedSimple/RiggedSimple.glb cubemap-discrete cd "${C[@]}"
bake RiggedSimple/RiggedSimple.glb cubemap-continuous cc "${C[@]}"
bake CesiumMilkTruck/CesiumMilkTruck.glb grid gr "${G[@]}"
for f in sa vl vc cd cc gr; do
  printf '%s  %s  key %s\n' "$(sha256sum "$O/$f.aob" | cut -d' ' -f1)" "$f.aob" \
    "$(grep -o '"bake_key": *"[0-9a-f]*"' "$O/$f.json" | grep -o '[0-9a-f]\{64\}')"
done
