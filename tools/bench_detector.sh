#!/usr/bin/env bash
# The detector's speed beside the machine's: rounds of the DVO benchmark (whose code does not
# change, so it says how fast the machine runs right now) and the detector benchmarks.
#
#   bash tools/bench_detector.sh [ROUNDS]
#   BASELINE=/path/to/an/older/occlusion-bench-binary bash tools/bench_detector.sh 10
#
# Per round: DVO (`whole`), `occlusion_update/640x480` (default) and `occlusion_update_paper`,
# the baseline's default when BASELINE is set, DVO again. Each is one criterion `--quick` run.
# The summary gives medians and how many default runs met the 3 ms target. On a shared machine
# whose speed swings, compare builds only within the same rounds, and read the detector beside
# DVO.
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${1:-10}
TARGET_MS=3

# The benchmark executables (criterion harness = false binaries), built once.
bench_binary() {
  cargo bench --bench "$1" --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == sys.argv[1]:
        print(m["executable"])' "$1" | tail -1
}
DVO=$(bench_binary dvo)
OCCLUSION=$(bench_binary occlusion)
[[ -x "$DVO" && -x "$OCCLUSION" ]] || { echo "could not build the benchmarks" >&2; exit 1; }

# The point estimate (middle figure, in ms) of every "time:" line of one criterion run.
estimates_ms() {
  "$@" 2>&1 | awk '/time:/ && !/%/ {
      v = $4; u = $5
      if (u == "µs") v /= 1000; else if (u == "s") v *= 1000; else if (u == "ns") v /= 1e6
      printf "%.3f ", v }
    END { print "" }'
}

LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
printf '%-8s %7s %7s %9s %7s %9s\n' time dvo dvo default paper baseline
for _ in $(seq "$ROUNDS"); do
  now=$(date -u +%H:%M:%S)
  dvo1=$(estimates_ms "$DVO" --bench --quick whole | awk '{print $1}')
  read -r default paper < <(estimates_ms "$OCCLUSION" --bench --quick 'occlusion_update(_paper)?/640')
  baseline=-
  if [[ -n "${BASELINE:-}" ]]; then
    baseline=$(estimates_ms "$BASELINE" --bench --quick 'occlusion_update/640' | awk '{print $1}')
  fi
  dvo2=$(estimates_ms "$DVO" --bench --quick whole | awk '{print $1}')
  printf '%-8s %7s %7s %9s %7s %9s\n' "$now" "$dvo1" "$dvo2" "$default" "$paper" "$baseline" | tee -a "$LOG"
done

python3 - "$LOG" "$TARGET_MS" <<'EOF'
import statistics, sys
rows = [line.split() for line in open(sys.argv[1])]
target = float(sys.argv[2])
dvo = [float(v) for r in rows for v in r[1:3]]
default = [float(r[3]) for r in rows]
paper = [float(r[4]) for r in rows]
def span(values):
    return f"median {statistics.median(values):.2f} ms ({min(values):.2f}–{max(values):.2f})"
print(f"rounds {len(rows)}; DVO {span(dvo)}")
print(f"default {span(default)}; ≤ {target:g} ms in {sum(v <= target for v in default)} of {len(default)}")
print(f"paper   {span(paper)}; ≤ {target:g} ms in {sum(v <= target for v in paper)} of {len(paper)}")
if rows[0][5] != "-":
    baseline = [float(r[5]) for r in rows]
    faster = sum(d < b for d, b in zip(default, baseline))
    print(f"baseline default {span(baseline)}; this build faster in {faster} of {len(rows)} rounds")
# The detector against the mean of the two DVO probes around it, round by round.
ratios = [d / ((float(r[1]) + float(r[2])) / 2) for d, r in zip(default, rows)]
print(f"default / DVO, median ratio {statistics.median(ratios):.2f}")
EOF
