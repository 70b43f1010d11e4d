#!/usr/bin/env bash
# Regenerates docs/comparison.md and its PNG files: the paper's comparison (§8, Figs. 5 and 8) of the Monte
# Carlo estimators with the baselines (PnP for the pose step, Ceres local bundle adjustment over the same
# Fibonacci keyframe window for the structure step), every combination from the same input and the same
# initialisation, on three inputs: the noisy synthetic scenario (observations straight into the back end)
# and two real sequences through the front end (KITTI odometry 06, frames 0-50; 7-Scenes RedKitchen,
# frames 0-299); and accuracy against time for several sample counts / iteration caps (synthetic).
# The findings are computed from these runs (scripts/plot_compare.py), so the page stays true when rerun.
#
# Usage: scripts/compare.sh [--data DIR] [path/to/mcslam] [docs-dir]
#   DIR: the real sequences; default $MCSLAM_DATA, else ../shared/data beside this repository. A sequence
#   that is missing there is left out, with a message on stderr and a visible note in the page.
#   SEEDS (environment, default "1 2 3"): the seeds every combination runs with.
#   (About 20 minutes on 2 cores with three seeds.)
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
DATA=${MCSLAM_DATA:-}
if [[ ${1:-} == --data ]]; then
  [[ $# -ge 2 ]] || { echo "compare.sh: --data needs a folder" >&2; exit 2; }
  DATA=$2
  shift 2
fi
DATA_LABEL=${DATA:-../shared/data}
DATA=${DATA:-$HERE/../../shared/data}
MCSLAM=${1:-build/mcslam}
DOCS=${2:-docs}
[[ -x "$MCSLAM" ]] || { echo "compare.sh: $MCSLAM is not an executable (build first, or give its path)" >&2; exit 2; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
START_S=$(date +%s)
echo "$(nproc) cores; load average at the start $(cut -d' ' -f1-3 /proc/loadavg)" > "$WORK/machine.txt"

COMBOS=("mc mc" "mc ba" "pnp mc" "pnp ba")
# Every combination runs with each of these seeds (Monte Carlo samples and the initialisation's RANSAC): one
# seed's difference between two methods can be the seed's doing; the page counts a method better on a
# measure only when its range over the seeds lies wholly on the better side of the other's.
SEEDS=${SEEDS:-1 2 3}

# run INPUT NAME FLAGS...: one `mcslam run`; its outputs in $WORK/INPUT/NAME, the summary line in summary.txt,
# the exit status in rc.txt and the end of stderr in stderr.txt (a failed run is reported, not fatal).
run() {
  local input=$1 name=$2
  shift 2
  local dir="$WORK/$input/$name" rc=0
  mkdir -p "$dir"
  "$MCSLAM" run "$@" --out "$dir" 2> "$dir/stderr.log" | tail -1 > "$dir/summary.txt" || rc=$?
  echo "$rc" > "$dir/rc.txt"
  tail -3 "$dir/stderr.log" > "$dir/stderr.txt"
  echo "$input/$name (exit $rc): $(cat "$dir/summary.txt")"
}

# every_combination INPUT TITLE ABOUT LABEL PATH FLAGS...: the four pose x structure runs of one input (PATH,
# shown in the page as LABEL; flags shown without the scratch folder's path).
every_combination() {
  local input=$1 title=$2 about=$3 label=$4 path=$5
  shift 5
  mkdir -p "$WORK/$input"
  echo "$title" > "$WORK/$input/title.txt"
  local flags="$*"
  printf '%s\n`mcslam run %s %s --seed %s --pose mc|pnp --structure mc|ba`\n' "$about" "$label" "${flags//$WORK\//}" \
    "${SEEDS// /|}" \
    > "$WORK/$input/about.md"
  local c seed
  for seed in $SEEDS; do
    for c in "${COMBOS[@]}"; do
      run "$input" "${c// /_}_s$seed" "$path" "$@" --seed "$seed" --pose "${c% *}" --structure "${c#* }"
    done
  done
}

# real_sequence INPUT FOLDER TITLE ABOUT FLAGS...: every combination on DATA/FOLDER, or a note that it is missing.
real_sequence() {
  local input=$1 folder=$2 title=$3 about=$4
  shift 4
  if [[ ! -d "$DATA/$folder" ]]; then
    mkdir -p "$WORK/$input"
    echo "$title" > "$WORK/$input/title.txt"
    echo "\`$DATA_LABEL/$folder\` was not found when this page was generated: not run (give the data folder with \`scripts/compare.sh --data DIR\` or \`MCSLAM_DATA\`)." \
      > "$WORK/$input/missing.txt"
    echo "compare.sh: $DATA/$folder not found: $title is left out of $DOCS/comparison.md (give --data DIR or set MCSLAM_DATA)" >&2
    return
  fi
  every_combination "$input" "$title" "$about" "$DATA_LABEL/$folder" "$DATA/$folder" "$@"
}

# ---- synthetic: the noisy paper scenario, observations straight into the back end ----
"$MCSLAM" synth --scenario paper --seed 1 --noise 1 --outliers 0.1 --out "$WORK/scenario" > /dev/null
every_combination synthetic "Synthetic: the noisy paper scenario" \
  "The paper's scenario (§8.1; σ = 1 px, 10 % wrong matches, 300 frames, seed 1: \`mcslam synth --scenario paper --seed 1 --noise 1 --outliers 0.1 --out scenario\`) as observations, without image processing; the first baseline's length from the ground truth (\`--gt-scale\`), 2^18 pose hypotheses." \
  scenario "$WORK/scenario" --gt-scale
for s in 256 1024 4096 16384; do run synthetic "mc_curve_$s" "$WORK/scenario" --gt-scale --structure mc --samples "$s"; done
for i in 1 3 10 30; do run synthetic "ba_curve_$i" "$WORK/scenario" --gt-scale --structure ba --ba-iterations "$i"; done

# ---- the real sequences, through the front end (flags as in scripts/real_data.sh and the tests) ----
real_sequence kitti06 kitti_odometry_06_frames000-050 "KITTI odometry 06, frames 0-50" \
  "A car on a straight 60 m suburban road, 51 grey frames of 1226x370 at 10 Hz, rectified; KITTI's ground-truth poses. 2^16 pose hypotheses (as in \`scripts/real_data.sh\`). The road is nearly straight, so the positions fix the alignment's rotation about it only through a few centimetres of sideways motion: the rotation error column there says more about that alignment than about the orientations; the RPE rotation column needs no alignment. A track that no longer matches its birth patch takes a new one instead of being dropped (decided by the front end from the share of tracks that mismatch in a frame: at 10 Hz forward, dropping them starves the initialisation)." \
  --hypotheses 65536
echo "525 525 320 240" > "$WORK/7scenes_camera.txt"
real_sequence 7scenes 7scenes_redkitchen_frames000-299 "7-Scenes RedKitchen, frames 0-299" \
  "A hand-held Kinect surveying a kitchen table, 300 colour frames of 640x480 at 30 Hz; KinectFusion's poses as ground truth; the colour camera taken as f = 525 px, centre (320, 240) (SOURCE.md: the folder's camera-intrinsics.txt is the depth camera's), the line \`525 525 320 240\` in 7scenes_camera.txt; 2^16 pose hypotheses; otherwise default settings." \
  --camera "$WORK/7scenes_camera.txt" --hypotheses 65536

echo "the runs took $(( $(date +%s) - START_S )) s; load average at the end $(cut -d' ' -f1-3 /proc/loadavg)" >> "$WORK/machine.txt"
mkdir -p "$DOCS"
/usr/bin/python3 "$HERE/plot_compare.py" "$WORK" "$DOCS" synthetic kitti06 7scenes
{
  echo "# Monte Carlo estimators against the baselines (the paper's §8)"
  echo
  echo "Generated by \`scripts/compare.sh\` ($(date -u +%Y-%m-%d); $(head -1 "$WORK/machine.txt"), $(tail -1 "$WORK/machine.txt"));"
  echo "every figure below, the findings included, is computed from that run. Each input is run with the four"
  echo "combinations of pose step and structure step, from the same input and the same initialisation (the"
  echo "initialisation does not depend on either step; each section checks that it came out the same)."
  echo "Pose step: Monte Carlo (2^18 or 2^16 hypotheses, 3 rounds) or OpenCV RANSAC EPnP + Levenberg-Marquardt."
  echo "Structure step, on every keyframe: Monte Carlo point adjustment (4096 samples per point, Fibonacci window"
  echo "of 12 keyframes) or Ceres bundle adjustment of the same window's poses and points (Cauchy loss, Schur"
  echo "solver, 10 iterations, oldest two keyframes and the keyframes between the window's held fixed)."
  echo "Errors after a Sim(3) alignment of the positions onto the ground truth (\`mcslam eval\`'s); times are"
  echo "wall-clock on the CPU backend. Columns: pose step and back end (track + map + adjust) per tracked frame after"
  echo "the initialisation, structure step per keyframe (means); run time of the whole \`mcslam run\` (real"
  echo "sequences: decoding and front end included); reprojection: mean inlier residual in the last tracked frame"
  echo "and over the last 30; ATE: RMSE of the camera positions; rotation: mean absolute orientation error after"
  echo "the alignment; RPE rotation: mean frame-to-frame rotation error, which needs no alignment. Trajectories are"
  echo "the online estimates: each frame's pose as it was output when the frame was processed (a keyframe's after its"
  echo "own structure step); where a later bundle adjustment moves a past keyframe, that is not written back."
  echo
  cat "$DOCS/comparison_sections.md"
  echo
  echo "## Accuracy against time (structure step, synthetic)"
  echo
  cat "$DOCS/comparison_curve.md"
  echo
  echo "![accuracy against time](accuracy_vs_time.png)"
  echo
  cat "$DOCS/comparison_findings.md"
  echo
  echo "Run summaries (the last line each \`mcslam run\` printed):"
  echo '```'
  for d in "$WORK"/{synthetic,kitti06,7scenes}/*/; do
    [[ -f "$d/summary.txt" ]] || continue
    echo "$(basename "$(dirname "$d")")/$(basename "$d"): $(cat "$d/summary.txt")"
  done
  echo '```'
} > "$DOCS/comparison.md"
rm -f "$DOCS/comparison_sections.md" "$DOCS/comparison_curve.md" "$DOCS/comparison_findings.md"
echo "wrote $DOCS/comparison.md and its PNG files ($(( $(date +%s) - START_S )) s)"
