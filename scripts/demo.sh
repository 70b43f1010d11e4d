#!/usr/bin/env bash
# The main job on the built-in default: the paper's synthetic precision test (§8.1). A noisy sequence
# (1 px noise, 10 % wrong matches) is generated, every frame's pose is found by Monte Carlo estimation
# with 2^18 hypotheses against the known map, and the trajectory is evaluated against the ground truth.
# (The full SLAM run, which builds its own map, replaces the known map when the back end lands.)
set -euo pipefail
MCSLAM=${1:-build/mcslam}
OUT=${2:-out/demo}
mkdir -p "$OUT"
"$MCSLAM" synth --scenario paper --noise 1 --outliers 0.1 --seed 1 --out "$OUT/scenario"
"$MCSLAM" run "$OUT/scenario" --known-map --hypotheses 262144 --out "$OUT/run"
echo "evaluation (mcslam eval, Sim(3) alignment):"
"$MCSLAM" eval "$OUT/scenario/groundtruth.txt" "$OUT/run/trajectory.txt" --csv "$OUT/run/errors.csv"
echo "outputs in $OUT/run: trajectory.txt trajectory_smoothed.txt frames.csv errors.csv"
