#!/usr/bin/env bash
# Runs occmask's cargo-fuzz targets (fuzz/README.md).
#
#   fuzz/run.sh [SECONDS_PER_TARGET] [TARGET...]      default: 600 s, every target
#
# Seeds fuzz/corpus/<target>/ from the library's own writers, builds the targets (stable
# toolchain through RUSTC_BOOTSTRAP=1, AddressSanitizer), then runs each target in turn under
# `nice -n 19`, keeping the corpus in fuzz/corpus/<target>/ and crashes in fuzz/artifacts/<target>/.
# A log per target goes to fuzz/logs/<target>.log (the last lines hold libFuzzer's final stats).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-600}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(proto_image proto_calibration json_messages ros2_image ros2_camera_info ros1_messages field_pixels poses text_parsers mcap_file)
fi
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz
cargo run --quiet --example fuzz_seeds -- fuzz/corpus
export RUSTC_BOOTSTRAP=1
nice -n 19 cargo fuzz build -O
mkdir -p fuzz/logs
for target in "${targets[@]}"; do
    # -timeout: a single input running longer than 10 s is a hang; -malloc_limit_mb: one
    # allocation above 512 MB from a message of a few KB is a finding (the decoders must check
    # declared sizes against the data first).
    # mcap_file: 4096, see fuzz/known-issues/README.md (an upstream virtual reservation).
    malloc_limit=512
    [ "$target" = mcap_file ] && malloc_limit=4096
    nice -n 19 cargo fuzz run -O "$target" -- \
        -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb="$malloc_limit" \
        -print_final_stats=1 >"fuzz/logs/$target.log" 2>&1 || echo "$target: finding, see fuzz/logs/$target.log"
    grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb|cov: .* ft:" "fuzz/logs/$target.log" | tail -3
done
