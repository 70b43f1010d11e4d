#!/usr/bin/python3
"""Tables and plots of the paper's comparison (§8, Figs. 5 and 8) from `mcslam run` output folders.
Usage: plot_compare.py WORK_DIR OUT_DIR
WORK_DIR holds one folder per run, named <pose>_<structure>[_<knob>] with frames.csv and summary.txt."""
import csv
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(run_dir):
    rows = [r for r in csv.DictReader(open(os.path.join(run_dir, "frames.csv"))) if r["status"] == "tracked"]
    summary = open(os.path.join(run_dir, "summary.txt")).read()
    values = dict(re.findall(r"(\w+)=([^\s]+)", summary))
    return rows, values


def mean(v):
    return sum(v) / len(v) if v else float("nan")


def stats(rows, values):
    post = [r for r in rows if r["init"] == "0"]
    kf = [r for r in post if r["keyframe"] == "1"]
    return {
        "tracked": int(values.get("tracked", 0)),
        "pose_ms": mean([float(r["track_ms"]) for r in post]),
        "structure_ms": mean([float(r["adjust_ms"]) for r in kf]),
        "frame_ms": mean([float(r["track_ms"]) + float(r["map_ms"]) + float(r["adjust_ms"]) for r in post]),
        "reproj_last30": mean([float(r["reproj_mean_px"]) for r in post[-30:]]),
        "ate_cm": 100 * float(values.get("trans_mean_m", "nan")),
        "rot_deg": float(values.get("rot_mean_deg", "nan")),
    }


def main():
    work, out = sys.argv[1], sys.argv[2]
    names = {"mc_mc": "Monte Carlo pose + Monte Carlo structure (the paper)",
             "mc_ba": "Monte Carlo pose + bundle adjustment",
             "pnp_mc": "PnP pose + Monte Carlo structure",
             "pnp_ba": "PnP pose + bundle adjustment"}
    runs = {k: load(os.path.join(work, k)) for k in names}
    with open(os.path.join(out, "comparison_table.md"), "w") as f:
        f.write("| pose + structure | frames tracked | pose step (ms/frame) | structure step (ms/keyframe) | "
                "total (ms/frame) | reprojection, last 30 frames (px) | mean translation error (cm) | "
                "mean rotation error (deg) |\n|---|---|---|---|---|---|---|---|\n")
        for k, title in names.items():
            s = stats(*runs[k])
            f.write(f"| {title} | {s['tracked']} | {s['pose_ms']:.2f} | {s['structure_ms']:.2f} | {s['frame_ms']:.2f} | "
                    f"{s['reproj_last30']:.3f} | {s['ate_cm']:.2f} | {s['rot_deg']:.3f} |\n")

    def per_frame(rows, key):
        post = [r for r in rows if r["init"] == "0"]
        return [int(r["index"]) for r in post], [float(r[key]) for r in post]

    for fname, key, a, b, label in [
        ("fig5_structure_time.png", "adjust_ms", "mc_mc", "mc_ba", "structure step (ms)"),
        ("fig8_pose_time.png", "track_ms", "mc_mc", "pnp_mc", "pose step (ms)"),
    ]:
        fig, ax = plt.subplots(figsize=(7, 3.2), dpi=110)
        for run, colour in ((a, "tab:blue"), (b, "tab:red")):
            x, y = per_frame(runs[run][0], key)
            ax.plot(x, y, lw=0.9, color=colour, label=names[run])
        ax.set_xlabel("frame")
        ax.set_ylabel(label)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(out, fname))
        plt.close(fig)

    # Accuracy against time: Monte Carlo with several sample counts, bundle adjustment with several caps.
    curve = {"mc": [], "ba": []}
    for d in sorted(os.listdir(work)):
        m = re.match(r"(mc|ba)_curve_(\d+)$", d)
        if m:
            s = stats(*load(os.path.join(work, d)))
            curve[m.group(1)].append((s["structure_ms"], s["ate_cm"], int(m.group(2))))
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=110)
    for k, colour, lab in (("mc", "tab:blue", "Monte Carlo, samples per point"), ("ba", "tab:red", "bundle adjustment, iterations")):
        pts = sorted(curve[k])
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=colour, label=lab)
        for t, e, n in pts:
            ax.annotate(str(n), (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("structure step (ms per keyframe)")
    ax.set_ylabel("mean translation error (cm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "accuracy_vs_time.png"))
    plt.close(fig)
    with open(os.path.join(out, "comparison_curve.md"), "w") as f:
        f.write("| method | knob | structure step (ms/keyframe) | mean translation error (cm) |\n|---|---|---|---|\n")
        for k, lab in (("mc", "samples"), ("ba", "iterations")):
            for t, e, n in sorted(curve[k], key=lambda p: p[2]):
                f.write(f"| {'Monte Carlo' if k == 'mc' else 'bundle adjustment'} | {lab} = {n} | {t:.2f} | {e:.2f} |\n")


if __name__ == "__main__":
    main()
