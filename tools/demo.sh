#!/usr/bin/env bash
# The main job on an embedded default: simulate a small universe, ingest its
# epochs into a level-of-detail store, describe the store, verify it, query a
# box, follow a few particles through time, and render pictures headless
# (OSMesa): an epoch, a moment between two epochs, and the ground truth.
#   tools/demo.sh BUILD_DIR [WORK_DIR]
set -euo pipefail
build="${1:?usage: tools/demo.sh BUILD_DIR [WORK_DIR]}"
work="${2:-$build/demo}"
octocosm="$build/tools/octocosm"

rm -rf "$work"
mkdir -p "$work"
echo "== 1. synth: a 64^3 particle-mesh run, 100 Mpc/h box, 5 epochs from z = 49 to z = 0"
"$octocosm" synth pm -o "$work/snapshots" -N 64 --box 100 --steps 40 --outputs 5 --quiet
echo "== 2. ingest: every epoch into one store (node capacity 4000)"
"$octocosm" ingest "$work"/snapshots/snap_00? -o "$work/store" --capacity 4000
echo "== 3. info"
"$octocosm" info "$work/store"
echo "== 4. verify"
"$octocosm" verify "$work/store"
echo "== 5. query: a 20 Mpc/h box at level 2 of the last epoch, as PLY"
"$octocosm" query "$work/store" --epoch 4 --box 40000,40000,40000,60000,60000,60000 --level 2 \
  --columns weight --format ply -o "$work/box.ply"
echo "== 6. follow: particles 1, 1000 and 100000 through every epoch"
printf '1\n1000\n100000\n' > "$work/ids.txt"
"$octocosm" follow "$work/store" --ids "$work/ids.txt"
echo "== 7. render: z = 0 from outside the box (blobs 2 px apart at most), halfway between the last"
echo "   two epochs coloured by speed, and the ground truth (every particle of snap_004, on the CPU)"
"$octocosm" render "$work/store" --time 4 --error 2 -o "$work/z0.png"
"$octocosm" render "$work/store" --time 3.5 --error 2 --color speed -o "$work/t3.5-speed.png"
"$octocosm" render "$work/store" --time 4 --reference "$work/snapshots/snap_004" -o "$work/z0-reference.png"
echo "demo finished: the store is in $work/store, the pictures are $work/*.png"
