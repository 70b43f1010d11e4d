#!/usr/bin/python3
"""Plots the paper's Fig. 4 from two `mcslam run` frames.csv files (clean and noisy scenario): rotation
error, translation error and reprojection error per frame, and writes a markdown table of their means.
Usage: plot_fig4.py CLEAN_FRAMES_CSV NOISY_FRAMES_CSV OUT_DIR
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(path):
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["status"] != "tracked" or r["trans_err_m"] == "":
                continue
            rows.append(r)
    if not rows:
        sys.exit(f"plot_fig4: {path} has no tracked frame with ground-truth errors")
    return rows


def column(rows, key, scale=1.0):
    return [float(r[key]) * scale for r in rows]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    clean, noisy, out = load(sys.argv[1]), load(sys.argv[2]), sys.argv[3]
    series = [("clean", clean, "tab:blue"), ("noisy (1 px, 10 % outliers)", noisy, "tab:red")]
    plots = [
        ("fig4_rotation.png", "rot_err_deg", 1.0, "rotation error (deg)"),
        ("fig4_translation.png", "trans_err_m", 100.0, "translation error (cm)"),
        ("fig4_reprojection.png", "reproj_mean_px", 1.0, "mean reprojection error of inliers (px)"),
    ]
    for name, key, scale, label in plots:
        fig, ax = plt.subplots(figsize=(7, 3.2), dpi=110)
        for title, rows, colour in series:
            ax.plot(column(rows, "index"), column(rows, key, scale), color=colour, lw=1.0, label=title)
        ax.set_xlabel("frame")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(f"{out}/{name}")
        plt.close(fig)

    def mean(rows, key, scale=1.0):
        v = column(rows, key, scale)
        return sum(v) / len(v)

    def last(rows, key, n=30):
        v = column(rows, key)[-n:]
        return sum(v) / len(v)

    with open(f"{out}/fig4.md", "w") as f:
        f.write("| scenario | frames tracked | mean rotation error (deg) | mean translation error (cm) | "
                "mean reprojection error (px) | reprojection error, last 30 frames (px) |\n")
        f.write("|---|---|---|---|---|---|\n")
        for title, rows, _ in series:
            f.write(f"| {title} | {len(rows)} | {mean(rows, 'rot_err_deg'):.3f} | "
                    f"{mean(rows, 'trans_err_m', 100):.2f} | {mean(rows, 'reproj_mean_px'):.3f} | "
                    f"{last(rows, 'reproj_mean_px'):.3f} |\n")


if __name__ == "__main__":
    main()
