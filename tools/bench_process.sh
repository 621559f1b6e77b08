#!/usr/bin/env bash
# End-to-end benchmarks of `occmask process` (release build), DVO closed loop + detector at
# 640x480, annotated copy:
#
#  scaling  total frames/s for 1, 2 and 4 input files with --jobs 1, 2 and 4 and with one or all
#           compute threads per file, on a file of the TUM folder's frames replayed forwards
#           and backwards (SCALING_MB of messages, default 240 = ~210 frames, generated here);
#           prints one table: best wall of REPEATS runs (default 3), total frames/s, speed-up
#           over one file, CPU (user+sys) per frame, peak RSS.
#  memory   peak RSS on a generated file of at least MIN_BYTES (default 2 GiB), annotated copy and
#           --sidecar, whole and its first second (--end 1), plus the TUM folder's file and its
#           eval.
#
# Usage: bash tools/bench_process.sh [scaling|memory|all] [MIN_BYTES]   (default: all)
#        REPEATS=5 SCALING_MB=480 bash tools/bench_process.sh scaling
#        TUM=DIR: the TUM-layout folder (default the excerpt fixtures/tum_fr2_desk_10;
#        TUM=$OCCMASK_DATA/tum_fr2_desk_50 for the 50-frame window)
# Files go to bench-out/process; the big ones are deleted at the end unless KEEP=1. Run it on an
# idle machine: `uptime` is printed before and after, since other work on the cores shows up as
# lower frames/s and higher CPU per frame.
set -euo pipefail
cd "$(dirname "$0")/.."
MODE=all
if [[ "${1:-}" =~ ^(scaling|memory|all)$ ]]; then
  MODE=$1
  shift
fi
MIN_BYTES=${1:-$((2 * 1024 * 1024 * 1024))}
REPEATS=${REPEATS:-3}
SCALING_MB=${SCALING_MB:-240}
TUM=${TUM:-fixtures/tum_fr2_desk_10}
OUT=bench-out/process
mkdir -p "$OUT"
cargo build --release --quiet --bin occmask --example make_big_rgbd_mcap
BIN=target/release/occmask
GEN=target/release/examples/make_big_rgbd_mcap
TIME=/usr/bin/time
CORES=$(nproc)

$BIN convert tum "$TUM" -o "$OUT/desk.mcap" --force -q

# One timed run: best-of-REPEATS wall and that run's CPU and RSS into the globals
# WALL CPU RSS_MB FRAMES. Arguments: the process arguments after the inputs.
timed() {
  local best="" line frames
  for _ in $(seq "$REPEATS"); do
    rm -rf "$OUT/scal" && mkdir -p "$OUT/scal"
    $TIME -f "%e %U %S %M" -o "$OUT/time.txt" $BIN process "$@" --out-dir "$OUT/scal" --force \
      2> "$OUT/summary.txt"
    line=$(tail -1 "$OUT/time.txt")
    # Frames: the summary table's second column, summed over the files.
    frames=$(awk '$1 ~ /^long[0-9]+\.mcap$/ { n += $2 } END { print n + 0 }' "$OUT/summary.txt")
    if [ -z "$best" ] || awk -v a="${line%% *}" -v b="${best%% *}" 'BEGIN { exit !(a < b) }'; then
      best="$line"
      FRAMES=$frames
    fi
  done
  read -r WALL user sys rss <<< "$best"
  CPU=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
  RSS_MB=$(awk -v k="$rss" 'BEGIN { printf "%.0f", k / 1024 }')
}

scaling() {
  echo "== scaling: generating a ${SCALING_MB} MB input (desk frames replayed)"
  $GEN "$OUT/desk.mcap" "$OUT/long1.mcap" "$((SCALING_MB * 1000 * 1000))"
  for i in 2 3 4; do ln -f "$OUT/long1.mcap" "$OUT/long$i.mcap"; done
  echo "load before: $(uptime)"
  echo "cores: $CORES; best wall of $REPEATS runs; fps = total frames / wall; CPU = user + sys"
  printf '%-34s %5s %4s %7s %7s %7s %8s %8s %9s %7s\n' \
    case files jobs thr/file frames wall_s fps speedup cpu_ms/fr rss_MB
  local base_fps="" one_thread_fps="" two_one_fps=""
  # case label | files | --jobs | --threads-per-file ("-" = default split)
  while IFS='|' read -r label files jobs threads; do
    local inputs=() args=()
    for i in $(seq "$files"); do inputs+=("$OUT/long$i.mcap"); done
    args=(--jobs "$jobs")
    [ "$threads" != "-" ] && args+=(--threads-per-file "$threads")
    timed "${inputs[@]}" "${args[@]}"
    local fps speedup shown_threads cpu_ms
    fps=$(awk -v f="$FRAMES" -v w="$WALL" 'BEGIN { printf "%.1f", f / w }')
    [ -z "$base_fps" ] && base_fps=$fps
    [ "$label" = "1 file, 1 thread" ] && one_thread_fps=$fps
    [ "$label" = "2 files side by side (default)" ] && two_one_fps=$fps
    speedup=$(awk -v a="$fps" -v b="$base_fps" 'BEGIN { printf "%.2f", a / b }')
    cpu_ms=$(awk -v c="$CPU" -v f="$FRAMES" 'BEGIN { printf "%.1f", 1000 * c / f }')
    shown_threads=$threads
    if [ "$threads" = "-" ]; then
      local k=$((jobs < files ? jobs : files))
      shown_threads=$((CORES / k > 0 ? CORES / k : 1))
    fi
    printf '%-34s %5s %4s %7s %7s %7s %8s %8s %9s %7s\n' \
      "$label" "$files" "$jobs" "$shown_threads" "$FRAMES" "$WALL" "$fps" "$speedup" "$cpu_ms" "$RSS_MB"
  done <<EOF
1 file (default: all cores)|1|$CORES|-
1 file, 1 thread|1|1|1
2 files one after the other|2|1|-
2 files side by side (default)|2|$CORES|-
2 files side by side, all threads|2|2|$CORES
4 files one after the other|4|1|-
4 files (default --jobs)|4|$CORES|-
4 files, 4 at a time|4|4|-
EOF
  echo "per-file-sequential scaling (2 files x 1 thread vs 1 file x 1 thread): $(awk -v a="$two_one_fps" \
    -v b="$one_thread_fps" 'BEGIN { printf "%.2f", a / b }') (ideal $CORES.00 on $CORES cores)"
  echo "load after: $(uptime)"
  if [ "${KEEP:-0}" != 1 ]; then
    rm -rf "$OUT"/long?.mcap "$OUT/scal"
  fi
}

memory() {
  cp "$OUT/desk.mcap" "$OUT/desk2.mcap"
  echo "== one file, $TUM (dvo closed loop)"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/desk.mcap" -o "$OUT/desk.out.mcap" --force
  echo "== two files in parallel, 2 x $TUM"
  mkdir -p "$OUT/par"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/desk.mcap" "$OUT/desk2.mcap" --out-dir "$OUT/par" --force
  echo "== eval of the single-file output"
  $BIN eval "$OUT/desk.out.mcap"

  echo "== generating a file of at least $MIN_BYTES bytes"
  $GEN "$OUT/desk.mcap" "$OUT/big.mcap" "$MIN_BYTES"
  ls -l "$OUT/big.mcap"
  echo "== big file, annotated copy"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.out.mcap" --force -q
  ls -l "$OUT/big.out.mcap"
  echo "== big file, sidecar"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.sidecar.mcap" --sidecar --force -q
  ls -l "$OUT/big.sidecar.mcap"
  echo "== big file, annotated copy of its first second (--end 1: the rest is copied, not decoded)"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.end.mcap" --end 1 --force -q
  echo "== big file, sidecar of its first second"
  $TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.end.mcap" --end 1 --sidecar --force -q
  if [ "${KEEP:-0}" != 1 ]; then
    rm -f "$OUT/big.mcap" "$OUT/big.out.mcap" "$OUT/big.sidecar.mcap" "$OUT/big.end.mcap"
  fi
}

case $MODE in
  scaling) scaling ;;
  memory) memory ;;
  all) scaling; memory ;;
esac
