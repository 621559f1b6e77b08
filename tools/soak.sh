#!/usr/bin/env bash
# Soak benchmark of `occmask process`: a 30-minute recording at 30 Hz (54 000 VGA
# frames) through the default pipeline (DVO closed loop + detector), checking that memory does
# not grow with the length of the run and measuring frames per second.
#
# The recording is generated (examples/make_soak_mcap.rs): the frames of a TUM folder (TUM, default
# the excerpt fixtures/tum_fr2_desk_10) replayed forwards and backwards with fresh 30 Hz stamps, colour
# re-encoded as JPEG and depth as compressedDepth PNG (≈ 0.25 MB per frame: 13 GB for 54 000
# frames; check `df -h` first). The output is a sidecar (`--sidecar`: only the new channels), so
# the disk holds one copy of the recording; the annotated copy's memory is bounded the same way
# (tools/bench_process.sh measures it on a 2 GB file).
#
# RSS (VmRSS, and the peak VmHWM) is sampled from /proc every INTERVAL seconds into
# $OUT/soak.rss.tsv; the summary prints the peak RSS after ~1 minute and at the end, and
# `/usr/bin/time -v` gives the overall peak and CPU time.
#
# Usage: [FRAMES=54000] [INTERVAL=5] [NICE=19] [KEEP=0] [TUM=DIR] bash tools/soak.sh
#   FRAMES=3000 bash tools/soak.sh   # a 100-second recording, a few minutes
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-54000}
TUM=${TUM:-fixtures/tum_fr2_desk_10}
INTERVAL=${INTERVAL:-5}
NICE=${NICE:-19}
OUT=bench-out/soak
mkdir -p "$OUT"
cleanup() {
  if [ "${KEEP:-0}" != 1 ]; then
    rm -f "$OUT/soak.mcap" "$OUT/soak.out.mcap"
  fi
}
trap cleanup EXIT
cargo build --release --quiet --bin occmask --example make_soak_mcap
BIN=target/release/occmask

$BIN convert tum "$TUM" -o "$OUT/desk.mcap" --force -q
echo "== generating $FRAMES frames"
target/release/examples/make_soak_mcap "$OUT/desk.mcap" "$OUT/soak.mcap" "$FRAMES"
ls -l "$OUT/soak.mcap"
df -h "$OUT" | tail -1

echo "== occmask process (nice -n $NICE), load before: $(cut -d' ' -f1-3 /proc/loadavg)"
START=$(date +%s.%N)
nice -n "$NICE" /usr/bin/time -v -o "$OUT/soak.time.txt" \
  "$BIN" process "$OUT/soak.mcap" -o "$OUT/soak.out.mcap" --sidecar --force -q &
TIME_PID=$!
# The process is the child of /usr/bin/time.
PID=""
for _ in $(seq 50); do
  PID=$(pgrep -P "$TIME_PID" || true)
  [ -n "$PID" ] && break
  sleep 0.1
done
printf 'elapsed_s\tvm_rss_kb\tvm_hwm_kb\tload1\tcpu_s\n' > "$OUT/soak.rss.tsv"
TICKS=$(getconf CLK_TCK)
while [ -n "$PID" ] && kill -0 "$PID" 2>/dev/null; do
  NOW=$(date +%s.%N)
  RSS=$(awk '/^VmRSS/{print $2}' "/proc/$PID/status" 2>/dev/null || true)
  HWM=$(awk '/^VmHWM/{print $2}' "/proc/$PID/status" 2>/dev/null || true)
  # utime + stime of the process (fields 14, 15 of /proc/PID/stat), seconds.
  CPU=$(awk -v t="$TICKS" '{printf "%.1f", ($14 + $15) / t}' "/proc/$PID/stat" 2>/dev/null || true)
  [ -n "$RSS" ] && printf '%.0f\t%s\t%s\t%s\t%s\n' "$(echo "$NOW - $START" | bc)" "$RSS" "$HWM" \
    "$(cut -d' ' -f1 /proc/loadavg)" "$CPU" >> "$OUT/soak.rss.tsv"
  sleep "$INTERVAL"
done
# Interrupting the process (kill -INT <occmask pid>) still prints the summary of the samples.
STATUS=0
wait "$TIME_PID" || STATUS=$?
END=$(date +%s.%N)
WALL=$(echo "$END - $START" | bc)
echo "== summary"
awk -F'\t' 'NR > 1 && $1 <= 60 { rss = $2; hwm = $3 } NR > 1 { last_rss = $2; last_hwm = $3; n++; load += $4 }
  END { printf "RSS at ~1 min: %d KB (peak so far %d KB); at the end: %d KB (peak %d KB); mean load %.1f over %d samples\n",
        rss, hwm, last_rss, last_hwm, load / n, n }' "$OUT/soak.rss.tsv"
grep -E "Maximum resident|Elapsed|User time|System time" "$OUT/soak.time.txt"
if [ "$STATUS" = 0 ]; then
  echo "frames $FRAMES, wall $WALL s, $(echo "scale=1; $FRAMES / $WALL" | bc) frames/s"
  ls -l "$OUT/soak.out.mcap"
else
  echo "process exited with status $STATUS after $WALL s (interrupted: see its message for the items done)"
fi
