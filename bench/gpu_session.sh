#!/bin/bash
# The whole GPU measurement in one run, for a machine lent for minutes: the
# render bench's sweep at 10^8 points (overview, mid, deep; every stage's
# time) on the raster and the compute splat paths, the compute path's blob
# radius, then playback through a particle-mesh series on both paths, and
# the 10^8 store rendered and fetched by 8 clients at once through nginx
# (remote bench; where nginx is there). Writes its tables and logs under OUT, eight files
# (the most a lent machine gives back). Run from the repository root on the
# GPU machine, after ../shared/gpu/bundle.sh packed build/ with the programs
# it runs (docs/BENCHMARKS.md):
#
#   ../shared/gpu/bundle.sh build tools/octocosm bench/octocosm-bench-render \
#       bench/octocosm-bench-remote ../../../usr/sbin/nginx
#   bash .gpu/run.sh bash bench/gpu_session.sh "$OUT"
#
# Times only, by default: the reference rendering that gives the PSNR and
# SSIM columns costs about 150 s a call at 10^8 points even on 16 cores (the
# neighbour search of every particle); REFERENCE=1 adds it. On an H100 host
# (16 cores) generating 10^8 points took 2-3 s, ingesting them 75-82 s, and
# the whole run 200-260 s. Keep the call under the device's per-call limit.
#
# POINTS (default 1e8), PM_SIDE (default 128) and BACKEND (default egl) make a
# dry run possible on any machine:
#   POINTS=2e5 PM_SIDE=16 BACKEND=osmesa bash bench/gpu_session.sh /tmp/out
set -euo pipefail
out=${1:?usage: gpu_session.sh OUT_DIR}
points=${POINTS:-1e8}
backend=${BACKEND:-egl}
work=${WORK:-/tmp/octocosm-gpu-session}
mkdir -p "$out" "$work"
bench=$(command -v octocosm-bench-render || echo build/bench/octocosm-bench-render)
octocosm=$(command -v octocosm || echo build/tools/octocosm)
log() { echo "== $*" | tee -a "$out/session.log"; }
reference=--no-reference
[ "${REFERENCE:-0}" = 1 ] && reference=

gpu=$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo no nvidia-smi)
log "$(date -u +%FT%TZ) $gpu, $(nproc) cores"
log "render bench: $points points, overview at thresholds and budgets, mid and deep"
"$bench" --backend "$backend" --dir "$work/rb" --points "$points" $reference --views overview --splat raster,compute \
  --thresholds 16,8,4,2,1 --budgets 0,2e6 --coarse clusters 2>&1 | tee "$out/render_overview.txt"
cp "$work/rb/render_bench.csv" "$out/render_overview.csv"
"$bench" --backend "$backend" --dir "$work/rb" --points "$points" $reference --views mid,deep --splat raster,compute \
  --thresholds 16,8,4 --budgets 0 --coarse clusters 2>&1 | tee "$out/render_zoomed.txt"
cp "$work/rb/render_bench.csv" "$out/render_zoomed.csv"

log "playback: a 128^3 particle-mesh series, 5 epochs, Hermite interpolation, compute and raster"
if [ ! -f "$work/pm/store/manifest.json" ]; then
  "$octocosm" synth pm -o "$work/pm/snapshots" --particles-per-side "${PM_SIDE:-128}" --outputs 5 \
    > "$out/pm_prepare.txt" 2>&1
  "$octocosm" ingest "$work"/pm/snapshots/snap_00? -o "$work/pm/store" --capacity 4000 >> "$out/pm_prepare.txt" 2>&1
fi
# The raster path draws this series' large blobs at a few frames a second:
# fewer frames tell its rate.
"$bench" --backend "$backend" --playback "$work/pm/store" --frames-per-epoch 60 --splat compute 2>&1 |
  tee "$out/playback.txt"
"$bench" --backend "$backend" --playback "$work/pm/store" --frames-per-epoch 15 --splat raster 2>&1 |
  tee -a "$out/playback.txt"
log "compute path: largest blob drawn by the compute shader, 2 and 8 pixels (4 above)"
for radius in 2 8; do
  "$bench" --backend "$backend" --dir "$work/rb" --points "$points" $reference --views overview,deep --splat compute \
    --compute-radius $radius --thresholds 4 --budgets 0 --no-full --coarse clusters 2>&1 |
    tee -a "$out/render_radius.txt"
done
remote=$(command -v octocosm-bench-remote || echo build/bench/octocosm-bench-remote)
if command -v nginx >/dev/null || [ -x /usr/sbin/nginx ]; then
  log "remote: the render bench's store through nginx, one client, then 8 at once (20 ms, 100 MiB/s each, 800 MiB/s shared)"
  "$remote" "$work/rb/store-clusters" --backend "$backend" --frames 8 --error 8 --clients 8 --no-query --follow 0 \
    2>&1 | tee -a "$out/session.log"
  log "remote: 8 clients fetching without drawing, on 16 cores (the 2-core machine's cores bound it)"
  "$remote" "$work/rb/store-clusters" --backend "$backend" --frames 8 --error 8 --clients 8 --no-query --follow 0 \
    --fetch-only 2>&1 | tee -a "$out/session.log"
else
  log "remote: skipped, no nginx (bundle it: ../shared/gpu/bundle.sh build ... ../../../usr/sbin/nginx)"
fi
log "$(date -u +%FT%TZ) done"
