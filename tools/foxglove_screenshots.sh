#!/usr/bin/env bash
# Screenshots of foxglove/occmask-layout.json in a real Foxglove app, as in foxglove/screenshots/.
# NOT part of .ci/run: it needs Debian's chromium and a ~40 MB npm install.
#
# Foxglove Studio 1.48 is the newest Foxglove web app on the npm registry: @foxglove/studio-base
# ships its prebuilt webpack bundle (assets/index.js, UMD with react/react-dom external), which
# tools/foxglove_check/studio/www/ hosts like Foxglove's own web app. Headless Chromium
# (playwright-core, SwiftShader WebGL) opens the file through Foxglove's "remote file" data source
# and the layout, seeks to each time and takes a screenshot. Studio 1.48's Image panel (then
# experimental) ignores annotations and colour maps, so the Image panels run as 1.48's default
# image panel (`--compat`, see www/main.js): colour with the outlines, depth in grey over the
# layout's 0-30000 range (not the colour map), the mask; the 3D panel and the plot run unchanged.
# demo-points: the demo with --points in the layout's 3D panel alone, its view moved back and
# below the start camera (the demo's world is that camera's optical frame, z forward: the scene
# lies along +z) to face the scene as the camera does.
#
# Usage: bash tools/foxglove_screenshots.sh [OUT_DIR]   (default foxglove/screenshots)
# Needs: apt-get install -y chromium pngquant. Real data: the TUM excerpt in fixtures/.
set -euo pipefail
cd "$(dirname "$0")/.."
out_dir="${1:-foxglove/screenshots}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
command -v chromium >/dev/null || { echo "needs chromium: apt-get install -y chromium" >&2; exit 2; }

nice -n 19 npm ci --prefix tools/foxglove_check --no-audit --no-fund >/dev/null
nice -n 19 npm ci --prefix tools/foxglove_check/studio --no-audit --no-fund >/dev/null
cargo build --release --quiet
bin=target/release/occmask

# The demo (moving object, ground truth) and real data (TUM fr2 desk through convert + process).
(cd "$work" && "$OLDPWD/$bin" demo --quiet --output demo.mcap)
(cd "$work" && "$OLDPWD/$bin" demo --quiet --points --output demo-points.mcap)
"$bin" convert tum fixtures/tum_fr2_desk_10 -o "$work/desk.mcap" --quiet
"$bin" process "$work/desk.mcap" -o "$work/desk.out.mcap" --quiet

# Both files pass the Foxglove check first (what the screenshots show is what it checks).
node tools/foxglove_check/check.js "$work/demo.mcap" | tail -1
node tools/foxglove_check/check.js "$work/demo-points.mcap" | tail -1
node tools/foxglove_check/check.js "$work/desk.out.mcap" | tail -1

shoot() { # FILE NAME TIMES [SCREENSHOTS.JS OPTIONS]
  node tools/foxglove_check/studio/screenshots.js --mcap "$1" --layout foxglove/occmask-layout.json \
    --out "$work/$2" --times "$3" --compat --width 1280 --height 800 --wait-ms 30000 "${@:4}"
}
shoot "$work/demo.mcap" demo 0.3,4.5
shoot "$work/desk.out.mcap" tum-desk 0.25
shoot "$work/demo-points.mcap" demo-points 2.5 --panel '3D!occmask-scene' \
  --camera '{"distance":6.5,"phi":128,"thetaOffset":30,"targetOffset":[0,0,1.7]}'

mkdir -p "$out_dir"
for png in "$work"/*.png; do
  # 256-colour PNGs: a third of the size, the panels stay readable.
  if command -v pngquant >/dev/null; then
    pngquant --force --quality 60-90 --output "$out_dir/$(basename "$png")" "$png"
  else
    cp "$png" "$out_dir/"
  fi
done
ls -l "$out_dir"
