#!/usr/bin/env bash
# Regenerates docs/accuracy.md: every accuracy table of occmask, from commands that exist in the
# repository (occmask demo / convert / process / eval, examples/detector_accuracy.rs,
# examples/scenario_accuracy.rs, examples/dvo_tum.rs, examples/synthetic_mcap.rs,
# tests/integration/dvo_synthetic.rs).
#
# Usage: bash tools/accuracy.sh [SECTION...]     (default: every section, in the order below)
#        OUT=/tmp/accuracy.md bash tools/accuracy.sh   (write elsewhere; default docs/accuracy.md)
#
# Real sequences are read from $OCCMASK_DATA (default ../shared/data beside the repository); a
# section whose data is missing says so in the output instead of a table. Accuracy figures do
# not depend on the machine's speed, so the script runs fine beside other work (~35 min on 2
# cores, release build first; the failure_classes section alone ~15 min).
#
# To add a dataset: write a function `section_<name>` that prints markdown (a `## ` heading, one
# sentence on the data, the command lines, a table), add <name> to SECTIONS, and run
# `bash tools/accuracy.sh` (or `bash tools/accuracy.sh <name>` to try it; that writes only the
# named sections).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${OCCMASK_DATA:-../shared/data}
OUT=${OUT:-docs/accuracy.md}
SECTIONS=(synthetic failure_classes demo dvo_synthetic tum_fixture tum_fr2_desk_50 redkitchen_300 bonn_crowd_200)
if [ $# -gt 0 ]; then SECTIONS=("$@"); fi

cargo build --release --quiet --bin occmask --example detector_accuracy --example dvo_tum \
  --example synthetic_mcap --example scenario_accuracy
BIN=target/release/occmask
EX=target/release/examples
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# TUM fr2 intrinsics (the fixture and tum_fr2_desk_50), 7-Scenes depth camera.
FR2="520.9 521.0 325.1 249.7"
KITCHEN="585 585 320 240"

# Field N (1-based, after splitting on spaces) of the first line matching a pattern.
field() { awk -v pat="$1" -v n="$2" '$0 ~ pat { print $n; exit }'; }
# "missing" note for a section whose data is absent.
missing() { printf '_Not measured: %s is missing (set OCCMASK_DATA)._\n\n' "$1"; }

# Mask F1 per synthetic scenario: the paper's detector and the default, true pose and closed loop.
section_synthetic() {
  echo "## Synthetic scenarios: mask F1"
  echo
  echo "\`occmask::synthetic\`, 640×480, seed 1: ray-cast rooms with Kinect-like depth noise"
  echo "(σ = 1.425·10⁻³·Z²), disparity quantisation, shadows behind depth edges and a 4 px invalid"
  echo "border; exact ground-truth masks and poses. Mean F1 over the frames with a moving object."
  echo "Commands: \`cargo run --release --example detector_accuracy -- synthetic all true|dvo\`,"
  echo "with \`OCC_GROWTH=1\` for appearance-gated completion (off by default, D8 of"
  echo "[method.md](method.md); the default adds the slow-change evidence of D16 to the paper's detector). The causal pipeline, one pass."
  echo "Targets: F1 ≥ 0.90 with the true pose, ≥ 0.85 closed loop."
  echo
  local mode growth
  for mode in true dvo; do
    for growth in 0 1; do
      OCC_GROWTH=$growth "$EX/detector_accuracy" synthetic all "$mode" > "$WORK/syn_${mode}_$growth.txt"
    done
  done
  echo "| scenario | F1 true pose: default / growth on | F1 closed loop: default / growth on | max FP on static frames (default, closed loop) |"
  echo "|---|---|---|---|"
  local s
  for s in $(awk '{print $1}' "$WORK/syn_true_1.txt"); do
    local tp td cp cd fp
    # "<name> true pose  : F1 x …" and "<name> closed loop: F1 x …"
    tp=$(field "^$s " 6 < "$WORK/syn_true_0.txt")
    td=$(field "^$s " 6 < "$WORK/syn_true_1.txt")
    cp=$(field "^$s " 5 < "$WORK/syn_dvo_0.txt")
    cd=$(field "^$s " 5 < "$WORK/syn_dvo_1.txt")
    fp=$(sed -n "s/^$s .*max FP on empty frames after 5: \([0-9.]*\) %.*/\1 %/p" "$WORK/syn_dvo_0.txt")
    # A scenario without moving objects has no F1 (its "F1" is NaN): show the FP fraction only.
    [ "$s" = static_scene ] && { tp=–; td=–; cp=–; cd=–; }
    echo "| $s | $tp / $td | $cp / $cd | $fp |"
  done
  echo
}

# The failure-class scenarios and the held-out set through the whole pipeline, every mode.
section_failure_classes() {
  echo "## Synthetic failure classes"
  echo
  echo "Scenarios built for what the occlusion detector finds late or not at all (\`Scenario::FAILURE_CLASSES\`"
  echo "in \`occmask::synthetic\`): an object in view and moving at the first frame, one that rests"
  echo "and then moves slowly, one that stops and goes, a head-on approach, a box sliding on a"
  echo "desk (near its background), an object dominating the view from the first frame, and a"
  echo "static desk as the false-positive control. Each runs through the whole pipeline"
  echo "(\`occmask::scenario_eval\`) with the default \`ProcessorConfig\`, offline (the default) or"
  echo "causal (\`--causal\`), with the DVO closed loop or the true camera poses; seed 1."
  echo "F1 (P / R): means over the frames with a moving object. Onset: per object and run of frames in"
  echo "which it is seen and moving, frames from the run's first frame (it starts to move or enters)"
  echo "until its own recall first reaches 0.5; the worst run; _never_ when a run never reaches it."
  echo "FP∅: the largest false-positive fraction of the image on a frame without a moving object,"
  echo "from frame 5 on (on the static controls every frame; elsewhere the frames where every object"
  echo "rests, so an offline mask that starts before the motion counts here). Targets, checked in the"
  echo "default mode at 320×240: F1 ≥ 0.85 and onset ≤ 5 frames, FP∅ ≤ 0.5 % on the static controls."
  echo "Commands:"
  echo "\`cargo run --release --example scenario_accuracy -- --size 320x240 --scenarios failure,held_out --json F\`"
  echo "and \`… --size 640x480 --modes dvo_offline --scenarios failure,held_out --json G\`; the preset"
  echo "column: \`… --size 320x240 --modes dvo_offline --scenarios failure,held_out --no-default"
  echo "--config far_layer=tools/detector_configs/far_layer.json\` (opt-in, method.md D21);"
  echo "\`tests/integration/detector_synthetic.rs\` holds bounds on the default mode at 320×240. At"
  echo "640×480 the offline mode works at 320×240 and enlarges its masks (method.md D24)."
  echo
  "$EX/scenario_accuracy" --size 320x240 --scenarios failure,held_out --json "$WORK/fc_qvga.json" \
    > /dev/null 2>&1
  "$EX/scenario_accuracy" --size 640x480 --modes dvo_offline --scenarios failure,held_out \
    --json "$WORK/fc_vga.json" > /dev/null 2>&1
  "$EX/scenario_accuracy" --size 320x240 --modes dvo_offline --scenarios failure,held_out \
    --no-default --config far_layer=tools/detector_configs/far_layer.json \
    --json "$WORK/fc_far.json" > /dev/null 2>&1
  "$EX/scenario_accuracy" --size 640x480 --modes dvo_offline --scenarios held_out_wide_on_floor \
    --no-default --config full_resolution=tools/detector_configs/full_resolution.json \
    --json "$WORK/fc_wide_full.json" > /dev/null 2>&1
  local seed
  for seed in 2 3 4 5; do
    "$EX/scenario_accuracy" --size 320x240 --modes dvo_offline --scenarios failure,held_out \
      --seed "$seed" --json "$WORK/fc_seed$seed.json" > /dev/null 2>&1
  done
  python3 - "$WORK/fc_qvga.json" "$WORK/fc_vga.json" "$WORK/fc_far.json" "$WORK/fc_wide_full.json" \
    "$WORK"/fc_seed[2-5].json <<'PY'
import json, sys
qvga_data = json.load(open(sys.argv[1]))
qvga = qvga_data["runs"]
vga = json.load(open(sys.argv[2]))["runs"]
far = json.load(open(sys.argv[3]))["runs"]
runs = {(r["scenario"], r["mode"], "q"): r for r in qvga}
runs.update({(r["scenario"], r["mode"], "v"): r for r in vga})
runs.update({(r["scenario"], r["mode"], "f"): r for r in far})
order = list(dict.fromkeys(r["scenario"] for r in qvga))
wide_full = json.load(open(sys.argv[4]))["runs"][0]

def onset(r):
    if r["onset_never"]:
        return "never"
    return "–" if r["worst_onset_frames"] is None else str(r["worst_onset_frames"])

def static(r):
    return r["segmentation"]["frames_with_truth"] == 0

def f1_onset(r):
    return "–" if static(r) else "%.3f · %s" % (r["segmentation"]["mean_f1"], onset(r))

def fp(r):
    return "%.3f %%" % (100 * r["max_fp_fraction_without_objects"]) if r["frames_without_objects"] else "–"

def target(r):
    if static(r):
        return "met" if r["max_fp_fraction_without_objects"] <= 0.005 else "**not met**"
    f1_ok = r["segmentation"]["mean_f1"] >= 0.85
    onset_ok = not r["onset_never"] and r["worst_onset_frames"] is not None and r["worst_onset_frames"] <= 5
    if f1_ok and onset_ok:
        return "met"
    return "**not met** (%s)" % " and ".join(w for w, ok in (("F1", f1_ok), ("onset", onset_ok)) if not ok)

def table(held_out):
    print("| scenario (class) | offline, DVO (default): F1 (P / R) · onset | same at 640×480: F1 · onset | same, far_layer.json: F1 · onset | causal, DVO: F1 · onset | offline, true pose: F1 · onset | causal, true pose: F1 · onset | FP∅ default | ATE default / causal DVO | targets |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in order:
        d = runs[(name, "dvo_offline", "q")]
        if (d["set"] == "held_out") != held_out:
            continue
        seg = d["segmentation"]
        default = "–" if static(d) else "%.3f (%.3f / %.3f) · %s" % (seg["mean_f1"], seg["mean_precision"], seg["mean_recall"], onset(d))
        print("| %s (%s) | %s | %s | %s | %s | %s | %s | %s | %.1f / %.1f cm | %s |" % (
            name, d["failure_class"], default, f1_onset(runs[(name, "dvo_offline", "v")]),
            f1_onset(runs[(name, "dvo_offline", "f")]),
            f1_onset(runs[(name, "dvo_causal", "q")]), f1_onset(runs[(name, "true_pose_offline", "q")]),
            f1_onset(runs[(name, "true_pose_causal", "q")]), fp(d), 100 * d["ate_m"],
            100 * runs[(name, "dvo_causal", "q")]["ate_m"], target(d)))
    print()

table(False)

# Why the sliding box's onset stays above 5 frames: what is in view by then.
d = runs[("sliding_on_desk", "dvo_offline", "q")]
frames, start = d["per_frame"], d["onset_runs"][0]["first_frame"]
config = dict(qvga_data["configs"])["default"]
size = (qvga_data["width"], qvga_data["height"])
min_px = config["occlusion"]["min_object_pixels_vga"] * size[0] * size[1] / (640 * 480)
at_target = frames[start + 5]["truth_pixels"]
big_enough = next(i for i, f in enumerate(frames) if f["truth_pixels"] >= min_px)
found = next(i for i, f in enumerate(frames) if f["truth_pixels"] and f["recall"] >= 0.5)
without_depth = frames[start + 5]["truth_pixels_without_depth"]
print("sliding_on_desk enters at the image corner: its first pixel is in view at frame %d. Five" % start)
print("frames later it shows %d px, %d of them without depth (the sensor's invalid border ring)," % (at_target, without_depth))
print("fewer than the %d-px minimum object size at %d×%d; it lies close in front of the desk, so" % (min_px, *size))
print("its measured pixels occlude little. It reaches that size at frame %d and a recall of 0.5" % big_enough)
later = found - big_enough
measured = next(i for i, f in enumerate(frames) if f["truth_pixels"] > f["truth_pixels_without_depth"])
print("at frame %d (%d frame%s later). Its first pixel with depth is in view at frame %d: counted" % (found, later, "" if later == 1 else "s", measured))
print("from there, the onset would be %d (the table's onset counts from the first pixel in view)." % (found - measured))
print("Onset 5 means half the box at frame 7: its 21 pixels with depth lie on 11 rows, and all of")
print("them with the band beside them on those rows would be 0.62 of it. The default marks 12 of them")
print("(through the hysteresis), 0.11; closing the band beside those too (a gap fill on the published")
print("mask after the hysteresis; tried, not kept) gave 0.34 at frame 7 and F1 0.908.")
print()
print("Held out: the same classes with other seeds, room textures, sizes, speeds, depths and camera")
print("paths (`Scenario::HELD_OUT`). No default was tuned on these; they are reported apart, same")
print("columns. Some were looked at while a rule was built, and are held out no longer for it:")
print("held_out_dominant_from_start for the body completion's gates (method.md D26),")
print("held_out_dominant_on_floor for passing over a body's own faces (D27),")
print("held_out_wide_on_floor for the thin-structure filter's advance rule (D6), and the frames")
print("at which the closed loop first masks held_out_dominant_from_start, held_out_dominant_on_floor")
print("and held_out_close_on_floor for the motion prior's startup window (D13).")
print("held_out_close_on_floor and held_out_wide_on_floor were added after D27 and run once as")
print("defined (the latter then scored F1 0.012, never half found); held_out_slow_cart was added")
print("after the advance rule and run once as defined.")
print()
table(True)

# The wide block: what the advance rule finds, and why the closed loop finds it late.
wide = runs[("held_out_wide_on_floor", "dvo_offline", "q")]
wide_true = runs[("held_out_wide_on_floor", "true_pose_offline", "q")]
print("held_out_wide_on_floor: the block's edges advance about 1.5 px a frame at 320×240, and the")
print("thin-structure opening (method.md D6) erases every strip narrower than 3 px with no thicker")
print("part near it, as each frame's leading strip alone is. The advance rule (D6) keeps such a")
print("strip where it lies beside the pixels erased a frame before; without it F1 stays below 0.1")
print("(`detector_synthetic::a_slowly_advancing_edge_is_found_by_the_advance_rule`). With the true")
print("poses the block is found from the first frame (F1 %.3f, onset %s). With the closed loop:" % (wide_true["segmentation"]["mean_f1"], onset(wide_true)))
print("F1 %.3f, onset %s, ATE %.1f cm. The block, more than half of the first frame, pulls the" % (wide["segmentation"]["mean_f1"], onset(wide), 100 * wide["ate_m"]))
print("first pass's DVO before any of it is masked; on those poses the backward pass marks too")
print("little of it to seed the body completion (method.md D26) until frame %s." % onset(wide))
print("`--full-resolution` (640×480 offline, no reduction; the column \"same at 640×480\" works at")
print("320×240): F1 %.3f, onset %s, ATE %.1f cm." % (wide_full["segmentation"]["mean_f1"], onset(wide_full), 100 * wide_full["ate_m"]))
print()

# The slow cart: lost over the last frames of the file.
cart = runs[("held_out_slow_cart", "dvo_offline", "q")]
cart_causal = runs[("held_out_slow_cart", "true_pose_causal", "q")]
frames = cart["per_frame"]
last_found = max(i for i, f in enumerate(frames) if f["truth_pixels"] and f["recall"] >= 0.5)
found_min = min(f["recall"] for f in frames[:last_found + 1] if f["truth_pixels"])
lost_max = max(f["recall"] for f in frames[last_found + 1:] if f["truth_pixels"])
print("held_out_slow_cart: a cart rolls sideways 2.2 m away, its leading edge advancing about 1 px")
print("a frame, against the far wall for a few dozen rows and against the floor just behind it")
print("below. Its recall is %.2f or more up to frame %d and at most %.2f over the last %d frames:" % (found_min, last_found, lost_max, len(frames) - last_found - 1))
print("there the backward pass, which starts at the file's last frame, has marked only a strip of")
print("the cart, which the body completion (method.md D26) does not complete, and the forward pass")
print("hardly finds it (causal, true poses: F1 %.3f): a strip of 1 px a frame is thin together" % cart_causal["segmentation"]["mean_f1"])
print("with the one erased a frame before too. Without the advance rule F1 stays below 0.15")
print("(`detector_synthetic::a_slow_cart_is_lost_in_the_last_frames`).")
print()

# Every scenario again under other seeds: is a figure above a draw of the noise?
seeds = [runs] + [{(r["scenario"], r["mode"], "q"): r for r in json.load(open(p))["runs"]} for p in sys.argv[5:]]
print("Other seeds: the seed draws the rooms' textures and the depth noise; the scenes, the objects")
print("and the motions stay as defined. The default mode (offline, DVO, 320×240), seeds 1–%d:" % len(seeds))
print("per scenario the lowest and highest F1, the worst onset, the largest FP∅ and ATE over the")
print("seeds (command: the first one above with `--modes dvo_offline --seed N`).")
print()
print("| scenario | F1, lowest – highest | worst onset | FP∅, largest | ATE, largest | targets on every seed |")
print("|---|---|---|---|---|---|")
for name in order:
    rs = [s[(name, "dvo_offline", "q")] for s in seeds]
    if static(rs[0]):
        f1s, worst = "–", "–"
    else:
        f1 = [r["segmentation"]["mean_f1"] for r in rs]
        f1s = "%.3f – %.3f" % (min(f1), max(f1))
        worst = "never" if any(r["onset_never"] for r in rs) else str(max(r["worst_onset_frames"] for r in rs))
    fps = [r["max_fp_fraction_without_objects"] for r in rs if r["frames_without_objects"]]
    missed = sorted({t for t in (target(r) for r in rs) if t != "met"})
    print("| %s%s | %s | %s | %s | %.1f cm | %s |" % (
        name, " (held out)" if rs[0]["set"] == "held_out" else "", f1s, worst,
        "%.3f %%" % (100 * max(fps)) if fps else "–", 100 * max(r["ate_m"] for r in rs),
        "met" if not missed else ", ".join(missed)))
print()
PY
}

# The paper's central claim on the dominant-object scenario, through the binary.
section_demo() {
  echo "## Dominant moving object: closed loop against unmasked DVO"
  echo
  echo "The paper's claim: feeding the mask back into DVO keeps the odometry on the background"
  echo "when a moving object fills most of the view (here 50–93 %). Commands:"
  echo "\`cargo run --release --example synthetic_mcap -- DIR dominant_object\`, then"
  echo "\`occmask process DIR/dominant_object.mcap -o OUT.mcap [--pose dvo-unmasked | --pose-topic /groundtruth/pose]\`"
  echo "and \`occmask eval OUT.mcap --json\`; \`occmask demo\` runs the first row end to end."
  echo
  "$EX/synthetic_mcap" "$WORK/syn" dominant_object > /dev/null
  echo "| pose source | mask F1 | RPE Δ=1 | RPE Δ=148 | ATE RMSE |"
  echo "|---|---|---|---|---|"
  local label args
  while IFS='|' read -r label args; do
    # shellcheck disable=SC2086 # args is a word list
    $BIN process "$WORK/syn/dominant_object.mcap" -o "$WORK/dom.mcap" --force -q $args
    $BIN eval "$WORK/dom.mcap" --json | python3 -c '
import json, sys
r = json.load(sys.stdin); s = r["segmentation"]; o = r["odometry"]
rpe = {e["delta_frames"]: e for e in o["rpe"]}; short, long = rpe[min(rpe)], rpe[max(rpe)]
print("| %s | %.3f | %.1f mm, %.3f° | %.3f m, %.2f° | %.3f m |" % (sys.argv[1], s["mean_f1"],
      1000 * short["translation_rmse_m"], short["rotation_rmse_deg"], long["translation_rmse_m"],
      long["rotation_rmse_deg"], o["ate"]["rmse_m"]))' "$label"
  done <<EOF
DVO closed loop (default)|
DVO without the mask (the paper's "Robust DVO")|--pose dvo-unmasked
ground-truth poses|--pose-topic /groundtruth/pose
EOF
  echo
}

# DVO alone on the synthetic pairs: the multi-seed test's worst cases.
section_dvo_synthetic() {
  echo "## DVO on synthetic frame pairs"
  echo
  echo "\`tests/integration/dvo_synthetic.rs\` (\`every_seed_and_motion_converges_within_the_bounds\`): 8 seeds"
  echo "× 6 motions (up to 5 cm and 3°) × {static scene, a box covering 30 % of the view moving"
  echo "5 cm and masked, the same box not masked}, 640×480. Command:"
  echo "\`cargo test --test integration dvo_synthetic::every_seed -- --nocapture\`. Test bounds: 1 mm, 0.05°."
  echo
  cargo test -q --test integration dvo_synthetic::every_seed_and_motion_converges_within_the_bounds -- --nocapture \
    > "$WORK/dvo_syn.txt" 2>&1
  sed -n 's/^\([0-9]*\) cases .*worst static \([0-9.]*\) mm \([0-9.]*\) deg, masked \([0-9.]*\) mm \([0-9.]*\) deg, unmasked (converged ones) \([0-9.]*\) mm \([0-9.]*\) deg.*/| cases | worst static | worst masked | worst unmasked (converged) |\n|---|---|---|---|\n| \1 | \2 mm, \3° | \4 mm, \5° | \6 mm, \7° |/p' "$WORK/dvo_syn.txt"
  echo
}

# One TUM-layout folder: DVO alone (dvo_tum), the detector with ground-truth and DVO poses
# (detector_accuracy real / real-dvo), and convert → process → eval.
tum_tables() { # DIR LABEL
  local dir=$1 label=$2
  "$EX/dvo_tum" "$dir" --csv "$WORK/dvo.csv" 2> "$WORK/dvo.txt" > /dev/null
  "$EX/detector_accuracy" real "$dir" $FR2 > "$WORK/real.txt"
  "$EX/detector_accuracy" real-dvo "$dir" $FR2 > "$WORK/real_dvo.txt"
  $BIN convert tum "$dir" -o "$WORK/tum.mcap" --force -q
  $BIN process "$WORK/tum.mcap" -o "$WORK/tum.out.mcap" --force -q
  echo "| what | result |"
  echo "|---|---|"
  python3 - "$WORK/dvo.csv" "$label" <<'PY'
import csv, math, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if r.get("err_trans_mm")]
t = [float(r["err_trans_mm"]) for r in rows]; a = [float(r["err_rot_deg"]) for r in rows]
rms = lambda v: math.sqrt(sum(x * x for x in v) / len(v))
print("| DVO alone, RPE per consecutive pair (`dvo_tum`) | RMSE %.2f mm, %.3f°; worst pair %.2f mm, %.3f° (%d pairs) |"
      % (rms(t), rms(a), max(t), max(a), len(t)))
PY
  sed -n 's/.*FP after warm-up: mean \([0-9.]*\) %, max \([0-9.]*\) %, \([0-9]*\) frames above 1 %.*motion rejected at \(.*\)/| detector, ground-truth poses: false positives per frame after 5 frames (`detector_accuracy real`) | mean \1 %, max \2 %, \3 frames above 1 %; motion check rejected frames \4 |/p' "$WORK/real.txt"
  sed -n 's/.*(DVO closed loop, \([a-z]*\)).*FP after warm-up: mean \([0-9.]*\) %, max \([0-9.]*\) %, \([0-9]*\) frames above 1 %; \(.*\)/| detector, DVO closed loop, \1: false positives (`detector_accuracy real-dvo`) | mean \2 %, max \3 %, \4 frames above 1 %; \5 |/p' "$WORK/real_dvo.txt"
  $BIN eval "$WORK/tum.out.mcap" --json | python3 -c '
import json, sys
o = json.load(sys.stdin)["odometry"]
parts = ["RPE Δ=%d %.1f mm, %.3f°" % (e["delta_frames"], 1000 * e["translation_rmse_m"], e["rotation_rmse_deg"]) for e in o["rpe"]]
print("| `convert` → `process` (closed loop) → `eval` | %s; ATE %.1f mm |" % ("; ".join(parts), 1000 * o["ate"]["rmse_m"]))'
  echo
}

section_tum_fixture() {
  echo "## TUM fr2_desk, the 10-frame excerpt in fixtures/"
  echo
  echo "A static desk filmed by a hand-held Kinect (nothing moves: every flagged pixel is a false"
  echo "positive), motion-capture ground truth, TUM fr2 intrinsics. Commands, with"
  echo "DIR = fixtures/tum_fr2_desk_10: \`cargo run --release --example dvo_tum -- DIR --csv F\`,"
  echo "\`cargo run --release --example detector_accuracy -- real|real-dvo DIR $FR2\`,"
  echo "\`occmask convert tum DIR -o a.mcap && occmask process a.mcap -o b.mcap && occmask eval b.mcap\`."
  echo
  tum_tables fixtures/tum_fr2_desk_10 tum_fr2_desk_10
}

section_tum_fr2_desk_50() {
  echo "## TUM fr2_desk, 50 frames"
  echo
  echo "The same recording over 1.6 s (\$OCCMASK_DATA/tum_fr2_desk_50), same commands."
  echo "\`tests/integration/dvo_tum.rs\` and \`tests/integration/detector_real.rs\` hold regression bounds on it."
  echo
  if [ -d "$DATA/tum_fr2_desk_50" ]; then tum_tables "$DATA/tum_fr2_desk_50" tum_fr2_desk_50; else missing tum_fr2_desk_50; fi
}

section_redkitchen_300() {
  echo "## 7-Scenes redkitchen, 300 frames"
  echo
  echo "A static kitchen (\$OCCMASK_DATA/7scenes_redkitchen_300; research licence, never copied"
  echo "into the repository), KinectFusion poses, depth-camera intrinsics $KITCHEN. Colour is not"
  echo "registered to depth, so the closed loop's photometric term is misaligned at edges. Commands:"
  echo "\`cargo run --release --example detector_accuracy -- real|real-dvo DIR $KITCHEN\`; the preset's"
  echo "row: \`… real-dvo DIR $KITCHEN --modes offline --config tools/detector_configs/far_layer.json\`."
  echo
  local dir="$DATA/7scenes_redkitchen_300"
  if [ ! -d "$dir" ]; then missing 7scenes_redkitchen_300; return; fi
  "$EX/detector_accuracy" real "$dir" $KITCHEN > "$WORK/k_real.txt"
  "$EX/detector_accuracy" real-dvo "$dir" $KITCHEN > "$WORK/k_dvo.txt"
  "$EX/detector_accuracy" real-dvo "$dir" $KITCHEN --modes offline \
    --config tools/detector_configs/far_layer.json > "$WORK/k_far.txt"
  echo "| poses | false positives per frame after 5 frames | other |"
  echo "|---|---|---|"
  sed -n 's/.*FP after warm-up: mean \([0-9.]*\) %, max \([0-9.]*\) %, \([0-9]*\) frames above 1 %.*motion rejected at \(.*\)/| KinectFusion (ground truth) | mean \1 %, max \2 %, \3 frames above 1 % | motion check rejected frames \4 |/p' "$WORK/k_real.txt"
  sed -n 's/.*(DVO closed loop, \([a-z]*\)).*FP after warm-up: mean \([0-9.]*\) %, max \([0-9.]*\) %, \([0-9]*\) frames above 1 %; \(.*\)/| DVO closed loop, \1 | mean \2 %, max \3 %, \4 frames above 1 % | \5 |/p' "$WORK/k_dvo.txt"
  sed -n 's/.*(DVO closed loop, offline).*FP after warm-up: mean \([0-9.]*\) %, max \([0-9.]*\) %, \([0-9]*\) frames above 1 %; \(.*\)/| DVO closed loop, offline, far_layer.json (D21) | mean \1 %, max \2 %, \3 frames above 1 % | \4 |/p' "$WORK/k_far.txt"
  echo
  echo "The offline mode finds this recording's colour not registered to its depth (D18: registration"
  echo "score 0.87, registered recordings 2.5–2.6) and refines it with the causal closed loop's own DVO"
  echo "(depth term weighted: γ = 30, k_depth = 0.05 m; keyframes while nothing moves) and without the"
  echo "temporal hysteresis. Refined with the paper's weights instead, as registered recordings are,"
  echo "its photometric term is misled at every edge here; the pose errors feed the slow-change"
  echo "evidence and the hysteresis (D17) carries its false marks back: mean 1.347 %, max 2.890 %,"
  echo "182 frames above 1 %. D18 lists the other refinements measured (the check's first one, γ = 10"
  echo "frame to frame: 0.391 %, 33 frames) and what this choice costs on moving scenes."
  echo "\`--config tools/detector_configs/no_registration_check.json\` refines every recording with the"
  echo "paper's weights; \`--config tools/detector_configs/unregistered_colour.json\` refines every one"
  echo "as an unregistered one (on Bonn, by \`occmask eval\` and \`reference_masks --score\`: ATE 0.0670 m instead of 0.0461 m, F1 0.914 instead of 0.911)."
  echo
}

# Real walking people: the offline and causal closed loop and unmasked DVO against the motion
# capture and the free-space reference masks (tests/integration/detector_real.rs prints one line per run).
section_bonn_crowd_200() {
  echo "## Bonn RGB-D Dynamic \"crowd\", 200 frames: people walking past a hand-held camera"
  echo
  echo "\$OCCMASK_DATA/bonn_crowd_200 (research licence, never copied into the repository): three"
  echo "people cross an office for 6.7 s and fill up to half of the view. Ground truth: the motion"
  echo "capture's marker poses, converted to the camera (\`occmask::dataset::bonn\`). There are no"
  echo "ground-truth masks; the reference is built from the depth images and the motion-capture poses"
  echo "alone (\`occmask::metrics::free_space\`, [method.md](method.md#evaluation)): a pixel is"
  echo "moving when other frames up to 3 s before or after see through the point it shows (empty"
  echo "space where it has a surface), grown over its depth-connected body. F1 is the mean over the"
  echo "frames with a reference object, scored where the frame has depth (the reference says nothing"
  echo "elsewhere). Command (the same runs that hold the test's bounds):"
  echo "\`OCCMASK_DATA=DIR cargo test --release --test integration detector_real::bonn -- --nocapture\`;"
  echo "\`cargo run --release --example reference_masks -- DIR --bonn --score MASKDIR\` scores the"
  echo "masks of \`occmask process --export-masks MASKDIR\` against the same reference (on a file from \`occmask convert bonn DIR\`)."
  echo
  if [ ! -d "$DATA/bonn_crowd_200" ]; then missing bonn_crowd_200; return; fi
  # One thread: the runs print in the order of the tests' names, each line whole.
  OCCMASK_DATA="$DATA" cargo test --release --quiet --test integration detector_real::bonn -- --nocapture \
    --test-threads 1 > "$WORK/bonn.txt" 2>&1
  echo "| pose source | mode | ATE RMSE | rotation RPE over 30 frames | mask F1 | precision | recall |"
  echo "|---|---|---|---|---|---|---|"
  sed -n 's/^.*bonn_crowd_200 \([A-Za-z]*\) \([A-Za-z_.,]*\): ATE \([0-9.]*\) m, rotation RPE (30 frames) \([0-9.]*\)°, masks F1 \([0-9.]*\) P \([0-9.]*\) R \([0-9.]*\)$/| \1 | \2 | \3 m | \4° | \5 | \6 | \7 |/p' "$WORK/bonn.txt" \
    | bonn_names
  echo
  echo "The closed loop's ATE is one draw: a camera 1 px different moves it as much as the offline closed-loop"
  echo "rows here differ from one another (method.md, \"Datasets\", has the figures)."
  echo
  echo "How soon each person is masked: the reference's 8-connected regions of at least 0.5 % of the"
  echo "image (1 536 pixels; smaller ones are slivers at the border or limbs cut off from their"
  echo "body) are linked from frame to frame by the pixels they share (\`occmask::metrics::onset::RegionTracker\`)."
  echo "A run starts where a region has no predecessor (a person enters, starts to move, or"
  echo "splits off a region they shared with another) and ends where it has no successor; its onset"
  echo "is the frames until half of it is masked, as for the synthetic classes. Same runs as above."
  echo
  echo "| pose source | mode | runs | half masked in their first frame | within 5 frames | the others: first–last frame, onset |"
  echo "|---|---|---|---|---|---|"
  sed -n 's/^.*bonn_crowd_200 people \([A-Za-z]*\) \([A-Za-z_.,]*\): runs \([0-9]*\), onset 0 in \([0-9]*\), ≤ 5 frames in \([0-9]*\); late: \(.*\)$/| \1 | \2 | \3 | \4 | \5 | \6 |/p' "$WORK/bonn.txt" \
    | bonn_names
  echo
  echo "In the overlays (\`reference_masks --overlay\`), the run of frames 126–129 is a person leaving"
  echo "the view at the right border, no longer masked; the runs of one frame are regions seen for"
  echo "that frame only (at frame 60, a part of a person's region split off from it). The largest"
  echo "share of the false positives is a person who walks in at the right and stands with arms"
  echo "crossed for about a second (frames 92–124): the reference, which marks only the points that"
  echo "other frames within 3 s see through, marks about half of that body; occmask marks all of it."
  echo "It is the same person who leaves at 126–129, standing, as the camera turns away: their"
  echo "accumulation lies on the head and the legs only, the body completion (method.md D26) masks the"
  echo "rest of them from there, and once the camera has turned those parts out of view (the last"
  echo "accumulated pixels at frame 125) nothing is left to complete."
  echo
}

# The Bonn section's run names as the tables show them.
bonn_names() {
  sed 's/| DvoClosedLoop |/| DVO closed loop |/; s/| DvoUnmasked |/| DVO without the mask |/; s/| Offline |/| offline (default) |/; s/| Offline,far_layer.json |/| offline, far_layer.json (D21) |/; s/| Offline,full_resolution |/| offline, `--full-resolution` (D24) |/; s/| Causal |/| causal (`--causal`) |/'
}

{
  cat <<'EOF'
# Accuracy

Every table below is written by `bash tools/accuracy.sh` from the commands it names; re-run it
after a change to the detector or the odometry and commit the result. Accuracy does not depend
on the machine's speed. The method and its deviations from the paper are in
[method.md](method.md); speed is in the README and [benches/README.md](../benches/README.md).
Real sequences other than the committed excerpt are read from `$OCCMASK_DATA`.

EOF
  for s in "${SECTIONS[@]}"; do
    "section_$s"
  done
} > "$WORK/accuracy.md"
mkdir -p "$(dirname "$OUT")"
mv "$WORK/accuracy.md" "$OUT"
echo "wrote $OUT"
