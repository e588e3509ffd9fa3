# Shared by the scale benches (bench/epoch_scale.sh, bench/series_scale.sh):
# the program they measure, timing helpers and one measured ingest. Source it.

octocosm=$(command -v octocosm || echo build/tools/octocosm)

# prepare_work WORK: creates the work directory and shows its disk's room.
prepare_work() {
  mkdir -p "$1"
  df -h "$1" | tail -1
}

now() { date +%s.%N; }
# Seconds since a time from `now`, to a tenth.
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# measured_ingest WORK STORE ARGS...: runs `octocosm ingest ARGS... -o STORE`
# under /usr/bin/time -v (its output in WORK/ingest.log and WORK/ingest.time)
# and samples the store directory's size each second: the store's directory
# holds the ingest's temporary files too, so its peak is the disk the ingest
# needs besides its input. Sets wall (h:mm:ss), wall_s, peak_kib and
# peak_disk (bytes); on failure prints the ingest's error and exits.
measured_ingest() {
  local work=$1 store=$2
  shift 2
  rm -rf "$store"
  /usr/bin/time -v "$octocosm" ingest "$@" -o "$store" >"$work/ingest.log" 2>"$work/ingest.time" &
  local ingest=$! used
  peak_disk=0
  while kill -0 "$ingest" 2>/dev/null; do
    used=$( (du -sb "$store" 2>/dev/null || true) | cut -f1 | head -n 1)  # files come and go while du reads
    if [ "${used:-0}" -gt "$peak_disk" ]; then peak_disk=$used; fi
    sleep 1
  done
  wait "$ingest" || { tail -3 "$work/ingest.time" >&2; grep -m1 octocosm: "$work/ingest.time" >&2; exit 1; }
  wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$work/ingest.time")
  wall_s=$(awk -v t="$wall" 'BEGIN { n = split(t, p, ":"); s = 0; for (i = 1; i <= n; ++i) s = s * 60 + p[i]; print s }')
  peak_kib=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$work/ingest.time")
}

# GiB, to a tenth, of a byte count.
gib() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 2^30 }'; }
