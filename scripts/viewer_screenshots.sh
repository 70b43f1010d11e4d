#!/usr/bin/env bash
# The viewer's pictures in README.md and docs/viewer.md: `mcslam view` on the demo's run (the rendered paper scene,
# with its ground truth and map file) and on a KITTI 06 run (its ground truth), each page opened in headless
# Chromium and its screenshot written to docs/viewer_demo.png and docs/viewer_kitti06.png.
# Usage: scripts/viewer_screenshots.sh [path/to/mcslam] [data-dir]   (about a minute on 2 cores)
set -euo pipefail
MCSLAM=${1:-build/mcslam}
DATA=${2:-${MCSLAM_DATA:-../shared/data}}
CHROMIUM=$(command -v chromium || command -v chromium-browser) || { echo "viewer_screenshots: no chromium" >&2; exit 1; }
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
shot() {  # page, png
  "$CHROMIUM" --headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader --use-angle=swiftshader \
    --hide-scrollbars --window-size=1024,768 --virtual-time-budget=5000 --screenshot="$2" "file://$1" >/dev/null 2>&1
  echo "viewer_screenshots: $2"
}
"$MCSLAM" synth --scenario paper --seed 1 --render --out "$OUT/scene" >/dev/null
"$MCSLAM" run "$OUT/scene" --dataset synthetic --out "$OUT/demo" --save-map "$OUT/demo/map.cbor" >/dev/null 2>&1
"$MCSLAM" view "$OUT/demo" --gt "$OUT/scene/groundtruth.txt" --map "$OUT/demo/map.cbor" >/dev/null
shot "$OUT/demo/viewer.html" docs/viewer_demo.png
KITTI="$DATA/kitti_odometry_06_frames000-050"
if [[ -d "$KITTI" ]]; then
  "$MCSLAM" run "$KITTI" --out "$OUT/kitti" --save-map "$OUT/kitti/map.cbor" >/dev/null 2>&1
  "$MCSLAM" view "$OUT/kitti" --gt "$KITTI/poses.txt" --map "$OUT/kitti/map.cbor" >/dev/null
  shot "$OUT/kitti/viewer.html" docs/viewer_kitti06.png
else
  echo "viewer_screenshots: $KITTI not found, KITTI picture left as it is"
fi
