#!/bin/bash
# A time series at scale on one machine: a particle-mesh run of SIDE^3
# particles with EPOCHS output epochs (octocosm synth pm: IDs and
# velocities, so the store links the epochs), ingested under --memory
# MEMORY, then verified, and a frame rendered half way between two epochs.
# Prints the ingest's wall time and peak RSS (/usr/bin/time -v), the most
# disk it used (store and temporary files), the store's size and bytes per
# particle, the verify time and the frame's time. Snapshots beyond EPOCHS
# in WORK/snapshots are left out.
#
#   bash bench/series_scale.sh WORK [SIDE=464] [EPOCHS=5] [MEMORY=2G]
#
# SIDE 464 is 10^8 particles an epoch: the snapshots take 32 bytes a particle
# and epoch (positions, velocities, 8-byte IDs; 16 GB for 5 epochs), the
# store about 70 (check `df` first). The snapshots stay in WORK/snapshots
# and are reused. NEIGHBOURS (default 0: the density-grid lengths) passes
# --neighbours to the ingest; 32 adds the neighbour pass, about 2
# microseconds a particle and core. SIDE=64 EPOCHS=3 is a dry run of a few
# seconds.
set -euo pipefail
work=${1:?usage: series_scale.sh WORK [SIDE] [EPOCHS] [MEMORY]}
side=${2:-464}
epochs=${3:-5}
memory=${4:-2G}
neighbours=${NEIGHBOURS:-0}
source "$(dirname "$0")/scale_measure.sh"
prepare_work "$work"

snapshots="$work/snapshots"
if [ ! -e "$snapshots/complete" ]; then
  rm -rf "$snapshots"
  start=$(now)
  "$octocosm" synth pm -o "$snapshots" -N "$side" --grid-factor 1 --steps 10 --z-start 9 --outputs "$epochs" \
    --files 8 >"$work/synth.log" 2>&1
  touch "$snapshots/complete"
  echo "generated $side^3 particles x $epochs epochs in $(since "$start") s"
fi
mapfile -t inputs < <(ls "$snapshots" | sed -n 's/^\(snap_[0-9]*\)\.0$/\1/p' | sort | head -n "$epochs")
[ "${#inputs[@]}" = "$epochs" ] || { echo "expected $epochs snapshots in $snapshots, found ${#inputs[@]}" >&2; exit 1; }
paths=()
for name in "${inputs[@]}"; do paths+=("$snapshots/$name"); done

store="$work/store"
measured_ingest "$work" "$store" "${paths[@]}" --memory "$memory" --neighbours "$neighbours"
bytes=$(du -sb "$store" | cut -f1)
particles=$((side * side * side * epochs))

start=$(now)
"$octocosm" verify "$store" >"$work/verify.log" 2>&1
verify_s=$(since "$start")

start=$(now)
"$octocosm" render "$store" --time "$(( (epochs - 1) / 2 )).5" -o "$work/between.png" >"$work/render.log" 2>&1
render_s=$(since "$start")

echo "series: $side^3 = $((side * side * side)) particles x $epochs epochs, --memory $memory, --neighbours $neighbours, $(nproc) cores"
echo "ingest: $wall wall, peak RSS $((peak_kib / 1024)) MiB"
echo "disk:   $(gib "$peak_disk") GiB at most while ingesting (store and temporary files; sampled each second)"
echo "store:  $(awk -v b="$bytes" 'BEGIN { printf "%.2f", b / 2^30 }') GiB, $(awk -v b="$bytes" -v n="$particles" 'BEGIN { printf "%.1f", b / n }') bytes a particle and epoch"
echo "verify: $verify_s s ($(tail -1 "$work/verify.log"))"
echo "render: a frame between two epochs in $render_s s ($work/between.png; $(tail -1 "$work/render.log"))"
