#!/usr/bin/env bash
# The main job on the built-in default: the paper's synthetic scenario (§8.1), noisy (1 px, 10 % outliers).
set -euo pipefail
MCSLAM=${1:-build/mcslam}
OUT=${2:-out/demo}
mkdir -p "$OUT"
"$MCSLAM" synth --scenario paper --noise 1 --outliers 0.1 --seed 1 --out "$OUT/scenario"
# Until the estimator lands the demo evaluates the ground truth against itself (ATE 0 by construction).
"$MCSLAM" eval "$OUT/scenario/groundtruth.txt" "$OUT/scenario/groundtruth.txt" --csv "$OUT/errors.csv"
