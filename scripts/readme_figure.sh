#!/usr/bin/env bash
# The picture at the top of README.md: mcslam on 7-Scenes RedKitchen (300 frames) with default settings and
# nothing but the camera, its trajectory from above against the ground truth (the run's own --plot).
# Usage: scripts/readme_figure.sh [path/to/mcslam] [data-dir]   (about a minute on 2 cores)
set -euo pipefail
MCSLAM=${1:-build/mcslam}
DATA=${2:-${MCSLAM_DATA:-../shared/data}}
SEQ="$DATA/7scenes_redkitchen_frames000-299"
[[ -d "$SEQ" ]] || { echo "readme_figure: $SEQ not found" >&2; exit 1; }
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
# 7-Scenes does not calibrate its colour camera; its SOURCE.md recommends fx = fy = 525, cx = 320, cy = 240.
"$MCSLAM" run "$SEQ" --camera "525 525 320 240" --out "$OUT/run" --plot "$OUT/plot.png" 2>/dev/null
cp "$OUT/plot.png" docs/trajectory_7scenes.png
echo "readme_figure: docs/trajectory_7scenes.png"
