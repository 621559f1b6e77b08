#!/usr/bin/env bash
# End-to-end conversion benchmark of the release binary against `cat` of the same files.
#
#   bash tools/bench_convert.sh [DATASET_DIR] [extra convert args...]
#   RUNS=5 bash tools/bench_convert.sh fixtures/tum_fr2_desk_10 --compression lz4
#
# Reports frames/s, MB/s (image bytes read), peak RSS (/usr/bin/time -v), output size and the
# ratio of the best conversion time to the best `cat` time. Files are read once first, so both
# run from the page cache (this measures our code, not the disk).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-fixtures/tum_fr2_desk_10}
shift || true
RUNS=${RUNS:-5}

cargo build --release --quiet
BIN=target/release/occmask
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

mapfile -t FILES < <(find "$DATA/rgb" "$DATA/depth" -type f | sort)
frames=$(grep -vc '^#' "$DATA/rgb.txt")
input_bytes=$(cat "${FILES[@]}" | wc -c)
cat "${FILES[@]}" > /dev/null   # warm the page cache

now_ns() { date +%s%N; }
best() { sort -n | head -1; }

cat_times=()
for _ in $(seq "$RUNS"); do
  t0=$(now_ns); cat "${FILES[@]}" > /dev/null; t1=$(now_ns)
  cat_times+=($((t1 - t0)))
done
cat_best=$(printf '%s\n' "${cat_times[@]}" | best)

conv_times=(); cpu_times=(); rss_kb=0
for _ in $(seq "$RUNS"); do
  t0=$(now_ns)
  /usr/bin/time -v -o "$OUT/time.txt" "$BIN" convert tum "$DATA" -o "$OUT/out.mcap" --force -q "$@"
  t1=$(now_ns)
  conv_times+=($((t1 - t0)))
  r=$(awk -F: '/Maximum resident set size/ {gsub(/ /, "", $2); print $2}' "$OUT/time.txt")
  (( r > rss_kb )) && rss_kb=$r
  cpu_times+=("$(awk -F: '/User time|System time/ {s += $2} END {printf "%.3f", s}' "$OUT/time.txt")")
done
cpu_best=$(printf '%s\n' "${cpu_times[@]}" | best)
conv_best=$(printf '%s\n' "${conv_times[@]}" | best)
out_bytes=$(stat -c %s "$OUT/out.mcap")

awk -v f="$frames" -v ib="$input_bytes" -v ob="$out_bytes" -v cb="$conv_best" -v kb="$cat_best" \
    -v rss="$rss_kb" -v runs="$RUNS" -v args="$*" -v cpu="$cpu_best" 'BEGIN {
  s = cb / 1e9; k = kb / 1e9;
  printf "dataset frames       %d (best of %d runs, args: %s)\n", f, runs, (args == "" ? "default" : args);
  printf "input image bytes    %.1f MB\n", ib / 1e6;
  printf "output file          %.1f MB (%.0f %% of input)\n", ob / 1e6, 100 * ob / ib;
  printf "convert wall time    %.3f s  -> %.1f frames/s, %.1f MB/s\n", s, f / s, ib / 1e6 / s;
  printf "CPU time (user+sys)  %.3f s (best run)\n", cpu;
  printf "peak RSS             %.1f MB\n", rss / 1024;
  printf "cat of same files    %.3f s  -> %.1f MB/s\n", k, ib / 1e6 / k;
  printf "ratio convert / cat  %.1f x\n", s / k;
}'
