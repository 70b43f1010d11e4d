#!/usr/bin/python3
"""Tables, plots and findings of the paper's comparison (§8, Figs. 5 and 8) from `mcslam run` output folders.

Usage: plot_compare.py WORK_DIR OUT_DIR INPUT...
Each WORK_DIR/INPUT holds title.txt and either missing.txt (the input was not found: a note in the page) or
about.md and one folder per run: <pose>_<structure>_s<seed> (pose and structure mc, pnp / mc, ba) and, for the
accuracy curve, mc_curve_<samples> / ba_curve_<iterations>; each with summary.txt (the run's last stdout line),
rc.txt, stderr.txt and, when the run got that far, frames.csv and report.json (image input only).
WORK_DIR/machine.txt says where the runs were timed.
Writes OUT_DIR/comparison_sections.md, comparison_curve.md and comparison_findings.md (pieces of
comparison.md, which scripts/compare.sh assembles) and the PNG files. Every figure in them comes from the runs."""
import csv
import json
import math
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

NAN = float("nan")
COMBOS = {"mc_mc": "Monte Carlo pose + Monte Carlo structure (the paper)",
          "mc_ba": "Monte Carlo pose + bundle adjustment",
          "pnp_mc": "PnP pose + Monte Carlo structure",
          "pnp_ba": "PnP pose + bundle adjustment"}
COLOURS = {"mc_mc": "tab:blue", "mc_ba": "tab:red", "pnp_mc": "tab:green", "pnp_ba": "tab:orange"}
# The rule of keyframes in both pose steps (slam::PoseTrackerOptions::keyframe_min_inlier_ratio's default).
KEYFRAME_RATIO = 0.6


def read(path, default=""):
    return open(path).read().strip() if os.path.exists(path) else default


def mean(v):
    v = [x for x in v if not math.isnan(x)]
    return sum(v) / len(v) if v else NAN


def num(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return NAN


def fmt(v, digits=2):
    return "–" if v is None or math.isnan(v) else f"{v:.{digits}f}"


def load(run_dir):
    """One run: what it measured, or why it has nothing to show."""
    summary = read(os.path.join(run_dir, "summary.txt"))
    values = dict(re.findall(r"(\w+)=([^\s]+)", summary))
    rc = int(read(os.path.join(run_dir, "rc.txt"), "-1"))
    rows = []
    if os.path.exists(os.path.join(run_dir, "frames.csv")):
        with open(os.path.join(run_dir, "frames.csv")) as f:
            rows = list(csv.DictReader(f))
    report = None
    if os.path.exists(os.path.join(run_dir, "report.json")):
        with open(os.path.join(run_dir, "report.json")) as f:
            report = json.load(f)
    tracked_rows = [r for r in rows if r["status"] == "tracked"]
    post = [r for r in tracked_rows if r["init"] == "0"]  # after the initialisation: what the two steps did
    init_rows = [r for r in rows if r["init"] == "1"]
    run = {
        "rc": rc,
        "error": (read(os.path.join(run_dir, "stderr.txt")).splitlines() or ["no message"])[-1] if rc else "",
        "post": post,
        "tracked_rows": tracked_rows,
        "frames": len(rows),
        "tracked": len(tracked_rows),
        "lost": sum(r["status"] == "lost" for r in rows),
        "keyframes": sum(r["keyframe"] == "1" for r in rows),
        "lost_notes": sorted({r["note"].replace(";", ",") for r in rows if r["status"] == "lost"}),
        "pose_ms": mean([num(r["track_ms"]) for r in post]),
        "structure_ms": mean([num(r["adjust_ms"]) for r in post if r["keyframe"] == "1"]),
        "backend_ms": mean([num(r["track_ms"]) + num(r["map_ms"]) + num(r["adjust_ms"]) for r in post]),
        "reproj_final": num(tracked_rows[-1]["reproj_mean_px"]) if tracked_rows else NAN,
        "reproj_last30": mean([num(r["reproj_mean_px"]) for r in post[-30:]]),
        "init": [(r["index"], r["reproj_mean_px"]) for r in init_rows],
        "init_note": next((r["note"].replace(";", ",") for r in init_rows if r["note"].startswith("initialised")), ""),
        "ok": rc == 0 and bool(rows),
    }
    # The image job's report.json holds the errors as {"ate_m": {...}, ...}; the observation job's holds flat
    # fields: its summary line has what is needed.
    if report and isinstance((report.get("ground_truth") or {}).get("ate_m"), dict):
        gt = report.get("ground_truth") or {}
        run["wall_s"] = num(report.get("wall_s"))
        run["ate_cm"] = 100 * num((gt.get("ate_m") or {}).get("rmse"))
        run["rot_deg"] = num((gt.get("rot_deg") or {}).get("mean"))
        run["rpe_rot_deg"] = num((gt.get("rpe_rot_deg") or {}).get("mean"))
    else:
        run["wall_s"] = num(values.get("wall_s"))
        run["ate_cm"] = 100 * num(values.get("ate_rmse"))
        run["rot_deg"] = num(values.get("rot_mean_deg"))
        run["rpe_rot_deg"] = num(values.get("rpe_rot_mean_deg"))
    return run


def load_input(d):
    """{combo: {seed: run}} of one input's folder."""
    runs = {}
    for name in sorted(os.listdir(d)):
        m = re.match(r"(mc_mc|mc_ba|pnp_mc|pnp_ba)_s(\d+)$", name)
        if m and os.path.isdir(os.path.join(d, name)):
            runs.setdefault(m.group(1), {})[int(m.group(2))] = load(os.path.join(d, name))
    return {k: dict(sorted(runs[k].items())) for k in COMBOS if k in runs}


def values_of(seeds, key):
    return [r[key] for r in seeds.values() if r["ok"] and not math.isnan(r[key])]


def span(seeds, key, digits=2):
    """'mean [min-max]' over the seeds, or the one value."""
    v = values_of(seeds, key)
    if not v:
        return "–"
    if len(v) == 1 or round(min(v), digits) == round(max(v), digits):
        return fmt(mean(v), digits)
    return f"{fmt(mean(v), digits)} [{fmt(min(v), digits)}–{fmt(max(v), digits)}]"


def int_span(v):
    return "–" if not v else str(min(v)) if min(v) == max(v) else f"{min(v)}–{max(v)}"


def per_frame(run, key, keyframes_only=False, scale=1.0, with_init=False):
    rows = run["tracked_rows"] if with_init else run["post"]
    rows = [r for r in rows if (not keyframes_only or r["keyframe"] == "1") and r[key] != ""]
    return [int(r["index"]) for r in rows], [scale * num(r[key]) for r in rows]


def plot(path, runs, series, ylabel, title, log, **kw):
    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=110)
    drawn = False
    for name in series:
        seeds = runs.get(name)
        if seeds and next(iter(seeds.values()))["post"]:
            x, y = per_frame(next(iter(seeds.values())), **kw)
            ax.plot(x, y, lw=0.9, color=COLOURS[name], label=COMBOS[name])
            drawn = True
    ax.set_xlabel("frame")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    if log and drawn:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    if drawn:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def table(runs):
    out = ["| pose + structure | tracked / frames (keyframes) | pose step (ms/frame) | structure step (ms/keyframe) | "
           "back end (ms/frame) | run time (s) | reprojection, final frame (px) | reprojection, last 30 frames (px) | "
           "ATE RMSE (cm) | rotation error (deg) | RPE rotation (deg/frame) |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    notes = []
    for name, title in COMBOS.items():
        seeds = runs.get(name)
        if not seeds:
            out.append(f"| {title} | not run |" + " – |" * 9)
            continue
        tracked = (f"{int_span([r['tracked'] for r in seeds.values()])} / {int_span([r['frames'] for r in seeds.values()])} "
                   f"({int_span([r['keyframes'] for r in seeds.values()])})")
        failed = {s: r for s, r in seeds.items() if r["rc"] != 0}
        if failed:
            tracked = f"**failed with seed {', '.join(map(str, failed))}**, " + tracked
        for s, r in failed.items():
            notes.append(f"{title}, seed {s}: exit {r['rc']}: {r['error']}")
        for s, r in seeds.items():
            if r["lost"]:
                notes.append(f"{title}, seed {s}: {r['lost']} frames lost ({'; '.join(r['lost_notes'])})")
        cells = [span(seeds, "pose_ms"), span(seeds, "structure_ms"), span(seeds, "backend_ms"),
                 fmt(mean(values_of(seeds, "wall_s")), 1), fmt(mean(values_of(seeds, "reproj_final")), 3),
                 fmt(mean(values_of(seeds, "reproj_last30")), 3), span(seeds, "ate_cm"), span(seeds, "rot_deg"),
                 span(seeds, "rpe_rot_deg", 3)]
        out.append(f"| {title} | {tracked} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n" + "".join(f"\n- {n}" for n in notes) + ("\n" if notes else "")


def init_check(runs):
    """The initialisation does not depend on the pose or structure step: check, seed by seed. Compared: the
    frames it used and its own report (two-view inliers, points, parallax, the refined window's residual). Not
    the init frames' residual columns: the settling that follows re-estimates those frames together with the
    ones the pose step tracked meanwhile, and writes their refined residuals back."""
    seeds = sorted({s for v in runs.values() for s in v})
    lines = []
    for s in seeds:
        by_combo = {k: v[s] for k, v in runs.items() if s in v}
        inits = [([i for i, _ in r["init"]], r["init_note"]) for r in by_combo.values()]
        if all(i[0] and i[1] for i in inits) and all(i == inits[0] for i in inits) and len(by_combo) == len(COMBOS):
            first = next(iter(by_combo.values()))
            lines.append(f"- seed {s}: the same in all four runs (frames {first['init'][0][0]}-{first['init'][-1][0]}): "
                         f"{first['init_note']}.")
        else:
            lines.append(f"- seed {s}: **not the same in all four runs**: " +
                         "; ".join(f"{COMBOS[k]}: {r['init_note'] or 'none'}" for k, r in by_combo.items()) + ".")
    return "Initialisation:\n\n" + "\n".join(lines) + "\n"


def ratio(a, b):
    return a / b if b and not math.isnan(a) and not math.isnan(b) else NAN


# A side counts as better on a measure only when its range over the seeds lies wholly below the other's and
# its mean is lower by more than this fraction: a difference of a few per cent is not one a user would see.
MIN_RELATIVE_DIFFERENCE = 0.05


def compare(a_name, a_seeds, b_name, b_seeds, key, unit, digits=2):
    """How A compares with B on one measure (lower is better) over the seeds: (text, winner or None)."""
    a, b = values_of(a_seeds, key), values_of(b_seeds, key)
    text = f"{a_name} {span(a_seeds, key, digits)} against {b_name} {span(b_seeds, key, digits)} {unit}"
    if not a or not b:
        return text, None
    for lo, hi, name in ((a, b, a_name), (b, a, b_name)):
        if max(lo) < min(hi) and mean(lo) < (1 - MIN_RELATIVE_DIFFERENCE) * mean(hi):
            return f"{text}: {name} better", name
    return f"{text}: level", None


def findings(inputs, machine, seeds_note):
    lines = ["## Findings (computed from the runs above)", "",
             f"Timings: {machine}; they move with the machine's load, the ratios much less. {seeds_note}", ""]
    baseline_wins, mc_wins, notes = [], [], []

    def tally(where, baseline, b, m, measures):
        for what, key, unit, d in measures:
            text, winner = compare(baseline, b, "Monte Carlo", m, key, unit, d)
            if winner:
                (baseline_wins if winner == baseline else mc_wins).append(f"{where}: {what}, {text.rsplit(':', 1)[0]}")

    for key, (title, runs) in inputs.items():
        if runs is None:
            lines.append(f"- **{title}**: not run (the sequence was not found), so nothing is said about it here.")
            continue
        failed = [f"{COMBOS[k]} (seed {s})" for k, v in runs.items() for s, r in v.items() if not r["ok"]]
        incomplete = [f"{COMBOS[k]} (seed {s}: {r['tracked']} of {r['frames']} frames tracked)"
                      for k, v in runs.items() for s, r in v.items() if r["ok"] and r["tracked"] < r["frames"]]
        missing = [COMBOS[k] for k in COMBOS if k not in runs]
        text = f"- **{title}**: " + ("every combination ran end to end with every seed" if not failed + missing
                                     else "**failed or not run: " + ", ".join(failed + missing) + "**")
        text += "; every frame tracked" if not incomplete else "; not every frame tracked: " + ", ".join(incomplete)
        ates = {k: mean(values_of(v, "ate_cm")) for k, v in runs.items() if values_of(v, "ate_cm")}
        if ates:
            best = min(ates, key=ates.get)
            text += f". Lowest mean ATE: {COMBOS[best]} ({fmt(ates[best])} cm)"
        times = []
        for pose in ("mc", "pnp"):
            mc, ba = runs.get(f"{pose}_mc"), runs.get(f"{pose}_ba")
            if mc and ba:
                t = ratio(mean(values_of(ba, "structure_ms")), mean(values_of(mc, "structure_ms")))
                times.append(f"bundle adjustment takes {fmt(t, 0)}x the time of the Monte Carlo structure step "
                             f"(with the {'Monte Carlo' if pose == 'mc' else 'PnP'} pose)")
                tally(f"{title}, structure step (with the {'Monte Carlo' if pose == 'mc' else 'PnP'} pose)",
                      "bundle adjustment", ba, mc,
                      (("time", "structure_ms", "ms per keyframe", 2), ("ATE", "ate_cm", "cm", 2),
                       ("frame-to-frame rotation", "rpe_rot_deg", "deg", 3),
                       ("reprojection (last 30 frames)", "reproj_last30", "px", 3)))
        for structure in ("mc", "ba"):
            mc, pnp = runs.get(f"mc_{structure}"), runs.get(f"pnp_{structure}")
            if not (mc and pnp):
                continue
            structure_name = "Monte Carlo" if structure == "mc" else "bundle-adjustment"
            t = ratio(mean(values_of(pnp, "pose_ms")), mean(values_of(mc, "pose_ms")))
            times.append(f"PnP takes {fmt(t, 2)}x the time of the Monte Carlo pose step (with the {structure_name} "
                         f"structure)")
            tally(f"{title}, pose step (with the {structure_name} structure)", "PnP", pnp, mc,
                  (("time", "pose_ms", "ms per frame", 2), ("ATE", "ate_cm", "cm", 2),
                   ("frame-to-frame rotation", "rpe_rot_deg", "deg", 3)))
            fewer = [(s, r["keyframes"], mc[s]["keyframes"]) for s, r in pnp.items()
                     if s in mc and r["ok"] and mc[s]["ok"] and r["keyframes"] < mc[s]["keyframes"]]
            if fewer:
                notes.append(
                    f"{title}, {structure_name} structure: the PnP pose step made fewer keyframes than the Monte Carlo "
                    f"one (" + ", ".join(f"seed {s}: {a} against {b}" for s, a, b in fewer) + "). A frame is a keyframe "
                    f"when its inliers are at least {KEYFRAME_RATIO} x its scored points, and the PnP step "
                    f"(slam/frame_tracker.cc, FrameTracker::EstimatePosePnp) counts every observed map point as scored where the "
                    f"Monte Carlo step counts only the points that were inliers in the previous frame; with fewer "
                    f"keyframes no new points are made in between, and the map thins out.")
        lines.append(text + (". Time: " + "; ".join(times) if times else "") + ".")
        for k, v in runs.items():
            rot, ate, rpe = values_of(v, "rot_deg"), values_of(v, "ate_cm"), values_of(v, "rpe_rot_deg")
            if rot and ate and rpe and max(rot) > 3 * min(rot) and max(rot) - min(rot) > 10:
                notes.append(
                    f"{title}, {COMBOS[k]}: the rotation error after the alignment ranges from {fmt(min(rot))} to "
                    f"{fmt(max(rot))} degrees over the seeds, while the ATE ranges from {fmt(min(ate))} to "
                    f"{fmt(max(ate))} cm and the frame-to-frame rotation error from {fmt(min(rpe), 3)} to "
                    f"{fmt(max(rpe), 3)} degrees: the alignment's rotation, fitted to the positions, makes that "
                    f"spread, not the orientations; compare orientations by the RPE column there.")
    lines += ["", "Where a baseline (bundle adjustment for the structure step, PnP for the pose step) does better:", ""]
    lines += [f"- {w}" for w in baseline_wins] or ["- nowhere in these runs"]
    lines += ["- on exact observations (not measured here): the least-squares baselines solve exactly, where Monte "
              "Carlo sampling stops at the resolution of its samples (tests/slam/test_system.cc, "
              "`BaselinesRunEndToEndAndAreExactOnCleanData`, asserts an ATE under 1e-5 m with the PnP pose step "
              "and under 5 mm with the Monte Carlo one)."]
    lines += ["", "Where the Monte Carlo step does better:", ""]
    lines += [f"- {w}" for w in mc_wins] or ["- nowhere in these runs"]
    if notes:
        lines += ["", "Notes:", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def curve(work_input, out):
    """Accuracy against time on the synthetic input: Monte Carlo sample counts, bundle-adjustment iteration caps."""
    pts = {"mc": [], "ba": []}
    for d in sorted(os.listdir(work_input)):
        m = re.match(r"(mc|ba)_curve_(\d+)$", d)
        if m:
            r = load(os.path.join(work_input, d))
            if r["ok"]:
                pts[m.group(1)].append((r["structure_ms"], r["ate_cm"], int(m.group(2))))
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=110)
    for k, colour, lab in (("mc", "tab:blue", "Monte Carlo, samples per point"),
                           ("ba", "tab:red", "bundle adjustment, iterations")):
        p = sorted(pts[k])
        ax.plot([q[0] for q in p], [q[1] for q in p], "o-", color=colour, label=lab)
        for t, e, n in p:
            ax.annotate(str(n), (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("structure step (ms per keyframe)")
    ax.set_ylabel("ATE RMSE (cm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "accuracy_vs_time.png"))
    plt.close(fig)
    md = ["| method | knob | structure step (ms/keyframe) | ATE RMSE (cm) |", "|---|---|---|---|"]
    for k, lab in (("mc", "samples"), ("ba", "iterations")):
        for t, e, n in sorted(pts[k], key=lambda p: p[2]):
            md.append(f"| {'Monte Carlo' if k == 'mc' else 'bundle adjustment'} | {lab} = {n} | {fmt(t)} | {fmt(e)} |")
    finding = ""
    if pts["mc"] and pts["ba"]:
        best_ba = min(pts["ba"], key=lambda p: p[1])
        beating = sorted((p for p in pts["mc"] if p[1] < best_ba[1]), key=lambda p: p[2])
        if beating:
            n = beating[0]
            finding = (f"Accuracy against time (synthetic, seed 1 only): {n[2]} samples per point ({fmt(n[0])} ms per "
                       f"keyframe, {fmt(n[1])} cm) already beat every bundle-adjustment iteration cap tried (at best "
                       f"{fmt(best_ba[1])} cm with {best_ba[2]} iterations, {fmt(best_ba[0])} ms per keyframe).")
        else:
            best_mc = min(pts["mc"], key=lambda p: p[1])
            finding = (f"Accuracy against time (synthetic, seed 1 only): no Monte Carlo sample count tried reaches the "
                       f"best bundle adjustment ({fmt(best_ba[1])} cm with {best_ba[2]} iterations); the best Monte "
                       f"Carlo run has {fmt(best_mc[1])} cm with {best_mc[2]} samples.")
    return "\n".join(md) + "\n", finding


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    work, out, names = sys.argv[1], sys.argv[2], sys.argv[3:]
    sections, inputs, all_seeds = [], {}, set()
    curve_md, curve_finding = "", ""
    for key in names:
        d = os.path.join(work, key)
        title = read(os.path.join(d, "title.txt"), key)
        sections.append(f"## {title}\n")
        if os.path.exists(os.path.join(d, "missing.txt")):
            sections.append(f"**Not run**: {read(os.path.join(d, 'missing.txt'))}\n")
            inputs[key] = (title, None)
            continue
        runs = load_input(d)
        inputs[key] = (title, runs)
        all_seeds |= {s for v in runs.values() for s in v}
        sections.append(read(os.path.join(d, "about.md")) + "\n")
        sections.append(table(runs))
        sections.append(init_check(runs))
        first = min((s for v in runs.values() for s in v), default=None)
        figs = [(f"fig5_structure_time_{key}.png", ("mc_mc", "mc_ba", "pnp_mc", "pnp_ba"), "structure step (ms)",
                 "Fig. 5: structure step per keyframe", True, dict(key="adjust_ms", keyframes_only=True)),
                (f"fig8_pose_time_{key}.png", ("mc_mc", "pnp_mc", "mc_ba", "pnp_ba"), "pose step (ms)",
                 "Fig. 8: pose step per frame", True, dict(key="track_ms")),
                (f"errors_{key}.png", tuple(COMBOS), "position error (cm)",
                 "position error per frame after the Sim(3) alignment", False, dict(key="trans_err_m", scale=100.0, with_init=True))]
        sections.append(f"Per-frame plots, seed {first}:\n")
        for fname, series, ylabel, ftitle, log, kw in figs:
            plot(os.path.join(out, fname), runs, series, ylabel, f"{title}: {ftitle} (seed {first})", log, **kw)
            sections.append(f"![{ftitle}]({fname})")
        sections.append("")
        if any(n.startswith("mc_curve_") for n in os.listdir(d)):
            curve_md, curve_finding = curve(d, out)
    machine = read(os.path.join(work, "machine.txt")).replace("\n", "; ")
    seeds_note = (f"Every combination ran with seeds {', '.join(map(str, sorted(all_seeds)))}: cells give the mean "
                  f"[lowest-highest] over them, and a method counts as better on a measure only when its range lies "
                  f"wholly below the other's and its mean is more than {MIN_RELATIVE_DIFFERENCE:.0%} lower." if len(all_seeds) > 1 else
                  "One seed only: a difference below the seed-to-seed spread cannot be told from chance.")
    with open(os.path.join(out, "comparison_sections.md"), "w") as f:
        f.write("\n".join(sections) + "\n")
    with open(os.path.join(out, "comparison_curve.md"), "w") as f:
        f.write(curve_md or "Not run.\n")
    with open(os.path.join(out, "comparison_findings.md"), "w") as f:
        f.write(findings(inputs, machine, seeds_note))
        if curve_finding:
            f.write("\n" + curve_finding + "\n")


if __name__ == "__main__":
    main()
