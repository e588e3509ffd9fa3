#!/bin/bash
# One epoch at scale on one machine: PARTICLES clustered points (octocosm
# synth scale, multi-file GADGET-2 with positions, velocities and IDs),
# ingested with positions and IDs only (--no-velocity) under --memory MEMORY,
# then verified, and a frame rendered. Prints the ingest's wall time, rate and
# peak RSS (/usr/bin/time -v), the most disk it used (store and temporary
# files, sampled each second), the store's size and bytes per particle, the
# verify time and the frame's time.
#
#   bash bench/epoch_scale.sh WORK [PARTICLES=1000000000] [MEMORY=2G]
#
# The snapshot takes 28 bytes a particle (28 GB at 10^9) and stays in
# WORK/snapshot to be reused; out of core the ingest spills every particle to
# temporary files once (16 bytes a particle: float positions and 32-bit IDs)
# and sorts the (ID, leaf) pairs through them (16 bytes a particle) while the
# store replaces them, so 10^9 needs about 70 GB of disk (check `df` first).
# NEIGHBOURS (default 0: the density-grid lengths) passes --neighbours to the
# ingest; 32 adds the neighbour pass, about 2 microseconds a particle and
# core. PARTICLES=1e6 is a dry run of a few seconds.
set -euo pipefail
work=${1:?usage: epoch_scale.sh WORK [PARTICLES] [MEMORY]}
particles=$(awk -v n="${2:-1000000000}" 'BEGIN { printf "%.0f", n }')
memory=${3:-2G}
neighbours=${NEIGHBOURS:-0}
source "$(dirname "$0")/scale_measure.sh"
prepare_work "$work"

snapshot="$work/snapshot"
if [ "$(cat "$snapshot/complete" 2>/dev/null)" != "$particles" ]; then
  rm -rf "$snapshot"
  start=$(now)
  "$octocosm" synth scale -o "$snapshot" -n "$particles" --prefix snap >"$work/synth.log" 2>&1
  echo "$particles" >"$snapshot/complete"
  echo "generated $particles clustered particles in $(since "$start") s ($(du -sh "$snapshot" | cut -f1))"
fi

store="$work/store"
measured_ingest "$work" "$store" "$snapshot/snap" --memory "$memory" --neighbours "$neighbours" --no-velocity
bytes=$(du -sb "$store" | cut -f1)

start=$(now)
"$octocosm" verify "$store" >"$work/verify.log" 2>&1
verify_s=$(since "$start")

start=$(now)
"$octocosm" render "$store" -o "$work/frame.png" >"$work/render.log" 2>&1
render_s=$(since "$start")

echo "epoch:  $particles clustered particles, positions and IDs, --memory $memory, --neighbours $neighbours, $(nproc) cores"
echo "ingest: $wall wall ($(awk -v n="$particles" -v s="$wall_s" 'BEGIN { printf "%.2f", n / s / 1e6 }') M points/s), peak RSS $((peak_kib / 1024)) MiB"
echo "disk:   $(gib "$peak_disk") GiB at most while ingesting (store and temporary files; sampled each second)"
echo "store:  $(gib "$bytes") GiB, $(awk -v b="$bytes" -v n="$particles" 'BEGIN { printf "%.1f", b / n }') bytes a particle"
echo "verify: $verify_s s ($(tail -1 "$work/verify.log"))"
echo "render: the default view in $render_s s ($work/frame.png; $(tail -1 "$work/render.log"))"
