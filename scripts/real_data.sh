#!/usr/bin/env bash
# `mcslam run` on the real sequences of ../shared/data (issue #5): KITTI 06 (51 frames), 7-Scenes RedKitchen
# (300 frames) and TUM fr3 long office (17 frames at 1 Hz), each with its trajectory plot and AR overlay.
# Prints the summary line of each run; everything else (report.json, frames.csv, plot.png, overlay.mp4) is in
# OUT/<sequence>/. A sequence that is missing is skipped with a message.
# Usage: scripts/real_data.sh [path/to/mcslam] [data-dir] [out-dir] [extra flags for every run...]
#   (about 30 s on 2 cores with the default 2^18 hypotheses)
set -uo pipefail
MCSLAM=${1:-build/mcslam}
DATA=${2:-../shared/data}
OUT=${3:-out/real_data}
shift $(( $# < 3 ? $# : 3 ))
mkdir -p "$OUT"

run() {  # name, folder, flags...
  local name=$1 folder=$2
  shift 2
  if [[ ! -d "$DATA/$folder" ]]; then
    echo "$name: $DATA/$folder not found, skipped"
    return
  fi
  local summary
  summary=$("$MCSLAM" run "$DATA/$folder" --out "$OUT/$name" --plot "$OUT/$name/plot.png" \
    --overlay "$OUT/$name/overlay.mp4" "$@" 2> "$OUT/$name.log" | tail -1)
  echo "$name: $summary"
}

# Default settings only, nothing but the camera (one configuration for every input: docs/tuning.md says what
# the system measures instead of being told).
run kitti06 kitti_odometry_06_frames000-050 "$@"
# 7-Scenes does not calibrate its colour camera; its camera-intrinsics.txt is the depth camera's (SOURCE.md).
mkdir -p "$OUT"
echo "525 525 320 240" > "$OUT/7scenes_camera.txt"
run 7scenes_redkitchen 7scenes_redkitchen_frames000-299 --camera "$OUT/7scenes_camera.txt" "$@"
run tum_fr3_1hz tum_rgbd_fr3_long_office_household_1hz "$@"
