#!/usr/bin/env python3
"""Writes docs/robustness.md from the cells scripts/robustness.sh ran (cells.tsv: name, seed, ground truth,
run folder, exit code), reading each run's report.json.

Success of a cell (issue #16): initialised within the first 30 % of the frames from the first one in which the
camera has moved (no monocular system can start before: the still-start scenario keeps the camera still for
2 s), at least 95 % of the frames after the initialisation tracked, ATE (Sim(3)) at most 1 % of the ground-truth path length, map not mirrored.
"""
import json
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import machine_info  # noqa: E402

INIT_WITHIN = 0.30
# The real sequences of the data folder (scripts/robustness.sh), as opposed to the rendered scenarios.
REAL_NAMES = ("kitti06", "7scenes_redkitchen")
TRACKED_AFTER = 0.95
ATE_REL = 0.01


def first_moving_frame(gt_path):
    """Index (line order) of the first ground-truth pose that differs from the first one; 0 when unreadable."""
    try:
        poses = []
        with open(gt_path) as f:
            for line in f:
                c = line.split()
                if not c or c[0].startswith("#"):
                    continue
                poses.append([float(x) for x in c[1:8]])
    except (OSError, ValueError):
        return 0
    for i, p in enumerate(poses):
        if max(abs(a - b) for a, b in zip(p, poses[0])) > 1e-9:
            return i
    return 0


def cell_row(name, seed, gt_path, run, code):
    r = {"name": name, "seed": int(seed), "exit": int(code)}
    path = os.path.join(run, "report.json")
    if not os.path.exists(path):
        r.update(ok=False, why="no report.json (exit %s)" % code)
        return r
    with open(path) as f:
        j = json.load(f)
    frames = j.get("frames", 0)
    init = (j.get("initialisation") or {}).get("frame")
    r["frames"] = frames
    r["init"] = init
    r["tracked"] = j.get("tracked", 0)
    r["rejections"] = len(j.get("initialisation_rejections", []))
    gt = j.get("ground_truth") or {}
    ate = (gt.get("ate_m") or {}).get("rmse")
    # The orientation error after the positions' alignment, or, where the positions do not fix its rotation
    # about the path (a straight road: eval's rotation_ambiguous), after the orientations' own best rotation.
    rot_key = "rot_orient_deg" if gt.get("rotation_ambiguous") else "rot_deg"
    rot = (gt.get(rot_key) or {}).get("mean")
    path_len = gt.get("path_length_m")
    r["ate"] = ate
    r["rot"] = rot
    r["path"] = path_len
    r["mirrored"] = bool(gt.get("mirrored", False))
    r["rel"] = ate / path_len if ate is not None and path_len else None
    # The lens' k1 measured when the first map settled (report.json's self_calibration): kept or taken.
    cal = j.get("self_calibration")
    r["cal"] = None if not cal else "%s %.3f, %.1f sigma, %.1f px" % (
        "**taken**" if cal.get("accepted") else "kept", cal.get("k1_measured", 0), cal.get("z", 0),
        cal.get("corner_shift_px", 0))
    r["cal_taken"] = bool(cal and cal.get("accepted"))
    why = []
    if init is None:
        why.append("never initialised")
    else:
        moving = first_moving_frame(gt_path)
        r["moving"] = moving
        if init > moving + INIT_WITHIN * (frames - moving):
            why.append("initialised late")
        after = frames - init
        # Frames from the initialisation's frame on that have a pose (tracked counts every posed frame, the
        # window before the initialisation's frame included, so count those from it on from the CSV instead).
        tracked_after = tracked_from(run, init)
        r["tracked_after"] = tracked_after
        if after > 0 and tracked_after < TRACKED_AFTER * after:
            why.append("tracked %d of %d after init" % (tracked_after, after))
    if r["rel"] is None:
        if init is not None:
            why.append("no evaluation")
    elif r["rel"] > ATE_REL:
        why.append("ATE %.2f %% of the path" % (100 * r["rel"]))
    if r["mirrored"]:
        why.append("mirrored")
    r["ok"] = not why
    r["why"] = ", ".join(why)
    return r


def tracked_from(run, init):
    path = os.path.join(run, "frames.csv")
    n = 0
    with open(path) as f:
        header = f.readline().strip().split(",")
        idx, st = header.index("index"), header.index("status")
        for line in f:
            c = line.rstrip("\n").split(",")
            if int(c[idx]) >= init and c[st] == "tracked":
                n += 1
    return n


def fmt(v, spec, none="-"):
    return none if v is None else format(v, spec)


def main():
    cells_path, doc, seeds = sys.argv[1], sys.argv[2], sys.argv[3]
    rows = []
    with open(cells_path) as f:
        for line in f:
            name, seed, gt, run, code = line.rstrip("\n").split("\t")
            rows.append(cell_row(name, seed, gt, run, code))
    names = []
    for r in rows:
        if r["name"] not in names:
            names.append(r["name"])
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = "?"
    out = []
    flags = os.environ.get("SYNTH_FLAGS", "").strip()
    run_flags = os.environ.get("RUN_FLAGS", "").strip()
    # SCENARIOS: a subset of the scenarios was run (robustness.sh's own variable), named in the command.
    scenarios = " ".join(os.environ.get("SCENARIOS", "").split())
    out.append("# Robustness matrix%s%s\n" % (": rendered with `%s`" % flags if flags else "",
                                            ", run with `%s`" % run_flags if run_flags else ""))
    if flags:
        # A variant of the matrix: every scenario rendered another way (another resolution, a lens, noise), and
        # perhaps run with other options (RUN_FLAGS: a default turned off, for comparison).
        real = [n for n in names if n in REAL_NAMES]
        settings = ("the options of `%s` (not the defaults: a comparison)" % run_flags if run_flags else
                    "**default settings only** (nothing but the camera given)")
        out.append("Every synthetic scenario rendered with `%s` (`mcslam synth --scenario NAME --seed K --render %s`, "
                   "then `mcslam run` on the rendered images: front end and back end), each over %s seeds, with "
                   "%s%s. Regenerated by `%s%sSYNTH_FLAGS=\"%s\" "
                   "scripts/robustness.sh build/mcslam OUT %s DATA %s` (commit %s, on %s); the matrix as designed is "
                   "[robustness.md](robustness.md).\n"
                   % (flags, flags, seeds, settings, "" if real else "; the real sequences, which this does not change, are "
                      "left out (DATA: a folder without them)", "SCENARIOS=\"%s\" " % scenarios if scenarios else "",
                      "RUN_FLAGS=\"%s\" " % run_flags if run_flags else "",
                      flags, seeds, doc, commit, machine_info.describe()))
    else:
        out.append("Every synthetic scenario (`mcslam synth --scenario NAME --seed K --render`, then `mcslam run` on the "
                   "rendered images: front end and back end) and the real video sequences of `../shared/data` (KITTI 06, "
                   "7-Scenes RedKitchen; the TUM excerpt at 1 Hz is too sparse a video to track and is left out), each over "
                   "%s seeds, with **default settings only** (nothing but the camera given). Regenerated by "
                   "`scripts/robustness.sh build/mcslam out/robustness %s` (commit %s, on %s).\n"
                   % (seeds, seeds, commit, machine_info.describe()))
    out.append("A cell succeeds when the run initialised within the first %d %% of its frames from the first one "
               "in which the camera has moved (still-start keeps it still for its first 60 frames), tracked at least "
               "%d %% of the frames from the initialisation on, its ATE after Sim(3) alignment is at most %d %% of "
               "the ground-truth path length, and the map is not mirrored (`mcslam eval`'s `mirrored=1`: a "
               "similarity with a reflection fits the estimated positions to the true ones with at most half the "
               "rms residual of the best Sim(3), or the Sim(3) fits them and the orientations are still more than "
               "90 degrees off after it). The rotation error is the mean over the frames of "
               "the angle between the estimated and true orientations after the Sim(3) alignment, or, where the "
               "positions leave that alignment's rotation about the path undetermined (`rotation_ambiguous` in "
               "report.json: a near-straight path such as KITTI 06 or 7-Scenes' excerpt), after the rotation that "
               "best aligns the orientations themselves (`rot_orient_deg`).\n"
               % (100 * INIT_WITHIN, 100 * TRACKED_AFTER, 100 * ATE_REL))
    total = sum(1 for r in rows)
    ok = sum(1 for r in rows if r["ok"])
    mirrored = sum(1 for r in rows if r.get("mirrored"))
    out.append("## Summary\n")
    out.append("**%d of %d cells succeed (%.0f %%); %d mirrored.**\n" % (ok, total, 100.0 * ok / max(total, 1), mirrored))
    out.append("| scenario | seeds ok | initialised at frame (median) | tracked after init (median) | ATE / path (median, max) | rotation error deg (median) |")
    out.append("|---|---|---|---|---|---|")
    for n in names:
        rs = [r for r in rows if r["name"] == n]
        inits = [r["init"] for r in rs if r.get("init") is not None]
        rels = [r["rel"] for r in rs if r.get("rel") is not None]
        rots = [r["rot"] for r in rs if r.get("rot") is not None]
        tra = [r["tracked_after"] / max(r["frames"] - r["init"], 1) for r in rs if r.get("tracked_after") is not None]
        out.append("| %s | %d / %d | %s | %s | %s | %s |" % (
            n, sum(r["ok"] for r in rs), len(rs),
            fmt(statistics.median(inits) if inits else None, ".0f"),
            fmt(100 * statistics.median(tra) if tra else None, ".1f") + (" %" if tra else ""),
            ("%.2f %%, %.2f %%" % (100 * statistics.median(rels), 100 * max(rels))) if rels else "-",
            fmt(statistics.median(rots) if rots else None, ".2f")))
    taken = [r for r in rows if r.get("cal_taken")]
    out.append("\nThe lens' first radial distortion coefficient, measured when the first map settles "
               "([self_calibration.md](self_calibration.md)), was taken in %d of %d cells%s; the others kept the "
               "given camera (the rendered scenarios' cameras are exact).\n" % (
                   len(taken), total,
                   (" (" + ", ".join("%s seed %d" % (r["name"], r["seed"]) for r in taken) + ")") if taken else ""))
    out.append("\n## Every cell\n")
    out.append("| scenario | seed | frames | initialised at | tracked | tracked after init | ATE m | path m | ATE / path | rotation deg | rejected inits | mirrored | lens k1 (self-calibration) | ok | why not |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        out.append("| %s | %d | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["name"], r["seed"], r.get("frames", "-"), fmt(r.get("init"), "d"), r.get("tracked", "-"),
            fmt(r.get("tracked_after"), "d"), fmt(r.get("ate"), ".4f"), fmt(r.get("path"), ".2f"),
            fmt(100 * r["rel"] if r.get("rel") is not None else None, ".2f") + (" %" if r.get("rel") is not None else ""),
            fmt(r.get("rot"), ".2f"), r.get("rejections", "-"), "yes" if r.get("mirrored") else "no",
            r.get("cal") or "-", "yes" if r["ok"] else "no", r.get("why", "")))
    os.makedirs(os.path.dirname(doc) or ".", exist_ok=True)
    with open(doc, "w") as f:
        f.write("\n".join(out) + "\n")
    print("robustness: %d of %d cells succeed; %d mirrored; written to %s" % (ok, total, mirrored, doc))


if __name__ == "__main__":
    main()
