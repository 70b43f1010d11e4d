#!/usr/bin/env bash
# The main job on the built-in default: the paper's synthetic scenario (§8.1), noisy (1 px, 10 % wrong
# matches), run through the full SLAM back end from its feature observations alone (two-view
# initialisation, Monte Carlo tracking with 2^18 hypotheses a frame, triangulation, Monte Carlo point
# adjustment), then evaluated against the ground truth.
set -euo pipefail
MCSLAM=${1:-build/mcslam}
OUT=${2:-out/demo}
mkdir -p "$OUT"
"$MCSLAM" synth --scenario paper --noise 1 --outliers 0.1 --seed 1 --out "$OUT/scenario"
"$MCSLAM" run "$OUT/scenario" --gt-scale --out "$OUT/run"
echo "evaluation (mcslam eval, Sim(3) alignment):"
"$MCSLAM" eval "$OUT/scenario/groundtruth.txt" "$OUT/run/trajectory.txt" --csv "$OUT/run/errors.csv"
echo "outputs in $OUT/run: trajectory.txt trajectory_smoothed.txt map.ply frames.csv errors.csv"
