#!/usr/bin/env bash
# End-to-end benchmark of `occmask process` (release build):
#  1. throughput on ../shared/data/tum_fr2_desk_50 (50 VGA frames) converted to MCAP: one file,
#     then two copies in parallel (rayon across files);
#  2. peak RSS on a generated file of at least 2 GiB (the desk frames replayed forwards and
#     backwards, uncompressed; generated here, never stored in the repository), as an
#     annotated copy and as a sidecar.
# Usage: bash tools/bench_process.sh [MIN_BYTES]   (default 2 GiB; files go to bench-out/process,
# the big ones are deleted at the end unless KEEP=1).
set -euo pipefail
cd "$(dirname "$0")/.."
MIN_BYTES=${1:-$((2 * 1024 * 1024 * 1024))}
OUT=bench-out/process
mkdir -p "$OUT"
cargo build --release --quiet --bin occmask --example make_big_rgbd_mcap
BIN=target/release/occmask
TIME=/usr/bin/time

$BIN convert tum ../shared/data/tum_fr2_desk_50 -o "$OUT/desk.mcap" --force -q
cp "$OUT/desk.mcap" "$OUT/desk2.mcap"

echo "== one file, 50 frames (dvo closed loop)"
$TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/desk.mcap" -o "$OUT/desk.out.mcap" --force
echo "== two files in parallel, 2 x 50 frames"
mkdir -p "$OUT/par"
$TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/desk.mcap" "$OUT/desk2.mcap" --out-dir "$OUT/par" --force
echo "== eval of the single-file output"
$BIN eval "$OUT/desk.out.mcap"

echo "== generating a file of at least $MIN_BYTES bytes"
target/release/examples/make_big_rgbd_mcap "$OUT/desk.mcap" "$OUT/big.mcap" "$MIN_BYTES"
ls -l "$OUT/big.mcap"
echo "== big file, annotated copy"
$TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.out.mcap" --force -q
ls -l "$OUT/big.out.mcap"
echo "== big file, sidecar"
$TIME -f "wall %e s, peak RSS %M KB" $BIN process "$OUT/big.mcap" -o "$OUT/big.sidecar.mcap" --sidecar --force -q
ls -l "$OUT/big.sidecar.mcap"
if [ "${KEEP:-0}" != 1 ]; then
  rm -f "$OUT/big.mcap" "$OUT/big.out.mcap" "$OUT/big.sidecar.mcap"
fi
