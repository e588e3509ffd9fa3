#!/bin/bash
# An ingest of a linked series spread over MPI ranks against one process:
# a particle-mesh run of SIDE^3 particles with EPOCHS output epochs (octocosm
# synth pm: IDs and velocities, so the store links the epochs), ingested once
# by one process with all cores, then under mpirun -n P for each P in RANKS
# (each rank with its share of the cores and of --memory MEMORY; --bind-to
# none, so that one rank may use every core), each store
# verified. Prints wall time, the largest process's peak RSS (/usr/bin/time
# -v of mpirun: the ranks are its children), and the speed-up over one
# process; runs alternate REPEAT times, the table takes each setting's best.
#
#   bash bench/ranks_scale.sh WORK [SIDE=128] [EPOCHS=8] [MEMORY=1G] [RANKS="1 2"]
#
# NEIGHBOURS (default 32, ingest's default) passes --neighbours; REPEAT
# (default 2) the number of rounds. The snapshots stay in WORK/snapshots and
# are reused. SIDE=32 EPOCHS=4 is a dry run of a few seconds. EPOCHS=1 is a
# single snapshot, whose particles mpirun spreads over the ranks; SNAPSHOT=
# PATH ingests that snapshot instead of a particle-mesh run (SIDE and EPOCHS
# are then ignored), e.g. one of octocosm synth scale.
set -euo pipefail
work=${1:?usage: ranks_scale.sh WORK [SIDE] [EPOCHS] [MEMORY] [RANKS]}
side=${2:-128}
epochs=${3:-8}
memory=${4:-1G}
ranks_list=${5:-1 2}
neighbours=${NEIGHBOURS:-32}
repeat=${REPEAT:-2}
octocosm=$(command -v octocosm || echo build/tools/octocosm)
octocosm=$(realpath "$octocosm")
command -v mpirun >/dev/null || { echo "ranks_scale.sh: mpirun not found (apt-get install openmpi-bin)" >&2; exit 1; }
# Root in containers and CI; shared-memory copies through Open MPI's own buffers.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none
export OMPI_MCA_rmaps_base_oversubscribe=1
cores=$(nproc)
mkdir -p "$work"

snapshots="$work/snapshots"
if [ -n "${SNAPSHOT:-}" ]; then
  paths=("$SNAPSHOT")
elif [ ! -e "$snapshots/complete-$epochs" ]; then
  rm -rf "$snapshots"
  "$octocosm" synth pm -q -o "$snapshots" -N "$side" --grid-factor 1 --steps 10 --z-start 9 --outputs "$epochs" \
    --files 2 >"$work/synth.log" 2>&1
  touch "$snapshots/complete-$epochs"
fi
if [ -z "${SNAPSHOT:-}" ]; then
  mapfile -t inputs < <(ls "$snapshots" | sed -n 's/^\(snap_[0-9]*\)\.0$/\1/p' | sort)
  paths=()
  for name in "${inputs[@]}"; do paths+=("$snapshots/$name"); done
fi

# One ingest: "1" is one process without mpirun, "mpi P" P ranks. Prints
# "wall_seconds peak_rss_kib".
run() {
  local store="$work/store" log="$work/ingest.log" times="$work/ingest.time"
  rm -rf "$store"
  local launcher=()
  local budget=$memory
  if [ "$1" = mpi ]; then
    launcher=(mpirun --bind-to none -n "$2")
    # Each rank's share of the budget: the whole job gets MEMORY, as one process does.
    budget=$(( $(numfmt --from=iec "$memory") / $2 ))
  fi
  /usr/bin/time -v "${launcher[@]}" "$octocosm" ingest -q "${paths[@]}" -o "$store" --memory "$budget" \
    --neighbours "$neighbours" >"$log" 2>"$times" || { tail -5 "$times" >&2; exit 1; }
  "$octocosm" verify "$store" >/dev/null || { echo "verify failed: $*" >&2; exit 1; }
  local wall rss
  wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$times" |
    awk -F: '{ s = 0; for (i = 1; i <= NF; ++i) s = s * 60 + $i; printf "%.2f", s }')
  rss=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$times")
  echo "$wall $rss"
}

declare -A best_wall best_rss
settings=("one" )
for p in $ranks_list; do settings+=("mpi $p"); done
for ((round = 0; round < repeat; ++round)); do
  for setting in "${settings[@]}"; do
    read -r wall rss < <(if [ "$setting" = one ]; then run one; else run $setting; fi)
    if [ -z "${best_wall[$setting]:-}" ] || awk -v a="$wall" -v b="${best_wall[$setting]}" 'BEGIN { exit !(a < b) }'; then
      best_wall[$setting]=$wall
      best_rss[$setting]=$rss
    fi
  done
done

# Particles an epoch, from the last store's manifest (its first epoch).
particles=$(grep -o '"points": *[0-9]*' "$work/store/manifest.json" | head -1 | grep -o '[0-9]*$')
echo "${SNAPSHOT:-$side^3 particle mesh}: $particles particles x ${#paths[@]} epochs, --neighbours $neighbours, --memory $memory in all, $cores cores, best of $repeat"
printf "%-22s %10s %14s %12s %10s\n" "run" "wall (s)" "M particle-epochs/s" "peak RSS" "speed-up"
one=${best_wall[one]}
for setting in "${settings[@]}"; do
  wall=${best_wall[$setting]}
  label=$([ "$setting" = one ] && echo "one process" || echo "mpirun -n ${setting#mpi }")
  awk -v l="$label" -v w="$wall" -v n="$particles" -v e="${#paths[@]}" -v r="${best_rss[$setting]}" -v o="$one" \
    'BEGIN { printf "%-22s %10.2f %14.2f %9.0f MiB %9.2fx\n", l, w, n * e / w / 1e6, r / 1024, o / w }'
done
