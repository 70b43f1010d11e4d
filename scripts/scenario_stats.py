#!/usr/bin/env python3
"""Measures the scenarios of `mcslam synth` (docs/scenarios.md): per scenario, the summary line of
`mcslam synth --scenario NAME --seed SEED`, the camera, and motion statistics from the files it writes:
inter-frame image displacement of the points seen in both frames (median over all pairs, and the median of
the per-pair medians' 10th/90th percentiles), camera-centre baseline and rotation per frame, the total
heading change, and the visible points per frame.

    python3 scripts/scenario_stats.py [--mcslam build/mcslam] [--seed 1] [--markdown]

Plain Python (no numpy), so that it runs wherever mcslam builds.
"""
import argparse
import math
import os
import subprocess
import sys
import tempfile

SCENARIOS = ["paper", "forward", "rotation", "planar", "fast", "still-start", "stop-and-go", "sparse"]


def read_observations(path):
    frames = {}
    with open(path) as f:
        for line in f:
            if not line.strip() or line.startswith("#"):
                continue
            parts = line.split()
            frame = frames.setdefault(int(parts[0]), {})
            if len(parts) >= 5:
                frame[int(parts[2])] = (float(parts[3]), float(parts[4]))
    return [frames.get(i, {}) for i in range(max(frames) + 1)] if frames else []


def read_tum(path):
    poses = []
    with open(path) as f:
        for line in f:
            if not line.strip() or line.startswith("#"):
                continue
            v = [float(x) for x in line.split()]
            poses.append((v[1:4], v[4:8]))  # centre, (qx, qy, qz, qw) world_from_cam
    return poses


def read_camera(path):
    values = {}
    with open(path) as f:
        for line in f:
            if ":" in line and not line.lstrip().startswith("#"):
                key, _, value = line.partition(":")
                values[key.strip()] = value.strip()
    return values


def quat_angle_deg(a, b):
    dot = abs(sum(x * y for x, y in zip(a, b)))
    return math.degrees(2 * math.acos(min(1.0, dot)))


def forward_axis(q):
    # Third column of the rotation of (qx, qy, qz, qw): the camera's z axis in the world.
    x, y, z, w = q
    return (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))


def percentile(values, p):
    if not values:
        return float("nan")
    s = sorted(values)
    k = (len(s) - 1) * p
    lo, hi = math.floor(k), math.ceil(k)
    return s[lo] + (s[hi] - s[lo]) * (k - lo)


def measure(mcslam, name, seed):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, name)
        summary = subprocess.run([mcslam, "synth", "--scenario", name, "--seed", str(seed), "--out", out],
                                 check=True, capture_output=True, text=True).stdout.strip()
        summary = summary.replace(out, "out/" + name)  # the temporary folder, as a stable name
        frames = read_observations(os.path.join(out, "observations.txt"))
        poses = read_tum(os.path.join(out, "groundtruth.txt"))
        cam = read_camera(os.path.join(out, "camera.yaml"))
    pair_medians, all_disp, baselines, rotations = [], [], [], []
    for i in range(1, len(poses)):
        common = frames[i].keys() & frames[i - 1].keys() if i < len(frames) else set()
        d = [math.dist(frames[i][k], frames[i - 1][k]) for k in common]
        if d:
            pair_medians.append(percentile(d, 0.5))
            all_disp.extend(d)
        baselines.append(math.dist(poses[i][0], poses[i - 1][0]))
        rotations.append(quat_angle_deg(poses[i][1], poses[i - 1][1]))
    f0, f1 = forward_axis(poses[0][1]), forward_axis(poses[-1][1])
    heading = math.degrees(math.atan2(f1[1], f1[0]) - math.atan2(f0[1], f0[0]))
    heading = (heading + 180) % 360 - 180
    visible = [len(f) for f in frames]
    return {
        "name": name,
        "summary": summary,
        "camera": "{}x{} f={}".format(cam.get("Camera.width", "?"), cam.get("Camera.height", "?"),
                                       cam.get("Camera.fx", "?")),
        "fps": cam.get("Camera.fps", "?"),
        "frames": len(poses),
        "disp_median": percentile(all_disp, 0.5),
        "disp_p10": percentile(pair_medians, 0.1),
        "disp_p90": percentile(pair_medians, 0.9),
        "baseline_median_cm": 100 * percentile(baselines, 0.5),
        "baseline_max_cm": 100 * max(baselines),
        "rotation_median_deg": percentile(rotations, 0.5),
        "rotation_max_deg": max(rotations),
        "heading_deg": heading,
        "visible": (min(visible), sum(visible) / len(visible), max(visible)),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mcslam", default="build/mcslam")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--markdown", action="store_true", help="a markdown table for docs/scenarios.md")
    parser.add_argument("scenarios", nargs="*", default=SCENARIOS)
    args = parser.parse_args()
    rows = [measure(args.mcslam, s, args.seed) for s in args.scenarios]
    if args.markdown:
        print("| scenario | camera | fps | frames | image displacement px: median (per-frame median p10-p90) "
              "| baseline cm/frame: median (max) | rotation deg/frame: median (max) | heading change deg "
              "| visible points min / mean / max |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            v = r["visible"]
            print(f"| {r['name']} | {r['camera']} | {r['fps']} | {r['frames']} | {r['disp_median']:.1f} "
                  f"({r['disp_p10']:.1f}-{r['disp_p90']:.1f}) | {r['baseline_median_cm']:.2f} "
                  f"({r['baseline_max_cm']:.2f}) | {r['rotation_median_deg']:.2f} ({r['rotation_max_deg']:.2f}) "
                  f"| {r['heading_deg']:.0f} | {v[0]} / {v[1]:.0f} / {v[2]} |")
        print()
        for r in rows:
            print(f"    {r['summary']}")
    else:
        for r in rows:
            print(r)
    return 0


if __name__ == "__main__":
    sys.exit(main())
