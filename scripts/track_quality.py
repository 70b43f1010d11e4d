#!/usr/bin/env python3
"""How well a front end's tracks agree with the true camera motion.

Usage: track_quality.py FOLDER [--min-obs N] [--json]

FOLDER is a folder of observations with its ground truth: what `mcslam run --save-tracks FOLDER` writes
(observations.txt, camera.yaml, groundtruth.txt), or what `mcslam synth` writes. Each track seen in at least
--min-obs frames that have a true pose is triangulated from the true poses (linear, then Gauss-Newton on its
pixel residuals, distortion included), and its residual is the rms distance, in pixels, between where it was
tracked and where that best static point projects. A track that follows one point of the scene has the tracker's
noise as its residual (a tenth of a pixel on clean renders); one that slides (along an edge, on a T-junction
where two surfaces at different depths meet, on smooth shading) or jumps has pixels. The measure needs a ground
truth as exact as the tracks: rendered scenarios, or poses of a precise reference system.

Prints one line: tracks measured, the quantiles of their residuals, and the fractions of tracks and of
observations in tracks whose residual exceeds 1 px and 3 px (--json: the same as a JSON object).
"""
import argparse
import json
import math
import os
import sys

import numpy as np


def read_camera(path):
    cam = {}
    with open(path) as f:
        for line in f:
            line = line.split('#', 1)[0].strip()
            if ':' not in line or not line.startswith('Camera.'):
                continue
            key, value = line.split(':', 1)
            try:
                cam[key[len('Camera.'):].strip()] = float(value)
            except ValueError:
                pass
    for k in ('fx', 'fy', 'cx', 'cy'):
        if k not in cam:
            sys.exit(f'{path}: Camera.{k} missing')
    for k in ('k1', 'k2', 'p1', 'p2', 'k3'):
        cam.setdefault(k, 0.0)
    return cam


def distort(cam, x, y):
    r2 = x * x + y * y
    radial = 1 + cam['k1'] * r2 + cam['k2'] * r2 * r2 + cam['k3'] * r2 * r2 * r2
    xd = x * radial + 2 * cam['p1'] * x * y + cam['p2'] * (r2 + 2 * x * x)
    yd = y * radial + cam['p1'] * (r2 + 2 * y * y) + 2 * cam['p2'] * x * y
    return xd, yd


def undistort(cam, u, v):
    xd, yd = (u - cam['cx']) / cam['fx'], (v - cam['cy']) / cam['fy']
    x, y = xd, yd
    for _ in range(20):  # fixed point: x = xd - (distort(x) - x)
        dx, dy = distort(cam, x, y)
        x, y = x - (dx - xd), y - (dy - yd)
    return x, y


def quat_to_matrix(qx, qy, qz, qw):
    return np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                     [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                     [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def read_groundtruth(path):
    """stamp -> (R cam_from_world, t cam_from_world) from a TUM file (world_from_cam)."""
    poses = {}
    with open(path) as f:
        for line in f:
            if line.startswith('#') or not line.strip():
                continue
            v = [float(x) for x in line.split()]
            r_wc = quat_to_matrix(*v[4:8])
            c = np.array(v[1:4])
            poses[v[0]] = (r_wc.T, -r_wc.T @ c)
    return poses


def read_tracks(path):
    """frame stamp per frame index, and per track its (stamp, u, v) observations."""
    tracks = {}
    with open(path) as f:
        for line in f:
            if line.startswith('#') or not line.strip():
                continue
            tok = line.split()
            if len(tok) != 5:
                continue
            stamp, fid, u, v = float(tok[1]), int(tok[2]), float(tok[3]), float(tok[4])
            tracks.setdefault(fid, []).append((stamp, u, v))
    return tracks


def nearest_pose(poses, stamps, t):
    i = np.searchsorted(stamps, t)
    best = None
    for j in (i - 1, i):
        if 0 <= j < len(stamps) and (best is None or abs(stamps[j] - t) < abs(stamps[best] - t)):
            best = j
    if best is None or abs(stamps[best] - t) > 1e-3:
        return None
    return poses[stamps[best]]


def project(cam, r, t, point):
    pc = r @ point + t
    if pc[2] <= 1e-9:
        return None
    xd, yd = distort(cam, pc[0] / pc[2], pc[1] / pc[2])
    return np.array([cam['fx'] * xd + cam['cx'], cam['fy'] * yd + cam['cy']])


def track_residual(cam, views):
    """views: list of (R, t, u, v). The rms pixel residual of the best static point, or None."""
    rows = []
    for r, t, u, v in views:
        x, y = undistort(cam, u, v)
        p = np.hstack([r, t[:, None]])
        rows.append(x * p[2] - p[0])
        rows.append(y * p[2] - p[1])
    _, s, vt = np.linalg.svd(np.array(rows))
    h = vt[-1]
    if abs(h[3]) < 1e-12:
        return None
    point = h[:3] / h[3]
    for _ in range(10):  # Gauss-Newton on the pixel residuals, numeric Jacobian
        res, jac = [], []
        for r, t, u, v in views:
            uv = project(cam, r, t, point)
            if uv is None:
                return None
            res.extend(uv - (u, v))
            cols = []
            for k in range(3):
                step = np.zeros(3)
                step[k] = 1e-6 * max(1.0, abs(point[k]))
                uv2 = project(cam, r, t, point + step)
                if uv2 is None:
                    return None
                cols.append((uv2 - uv) / step[k])
            jac.extend(np.array(cols).T)
        jac, res = np.array(jac), np.array(res)
        delta, *_ = np.linalg.lstsq(jac, -res, rcond=None)
        point = point + delta
        if np.linalg.norm(delta) < 1e-9 * max(1.0, np.linalg.norm(point)):
            break
    errs = []
    for r, t, u, v in views:
        uv = project(cam, r, t, point)
        if uv is None:
            return None
        errs.append(np.sum((uv - (u, v)) ** 2))
    return math.sqrt(np.mean(errs))


def measure(folder, min_obs=5):
    cam = read_camera(os.path.join(folder, 'camera.yaml'))
    poses = read_groundtruth(os.path.join(folder, 'groundtruth.txt'))
    stamps = np.array(sorted(poses))
    tracks = read_tracks(os.path.join(folder, 'observations.txt'))
    residuals, lengths = [], []
    for obs in tracks.values():
        views = []
        for stamp, u, v in obs:
            pose = nearest_pose(poses, stamps, stamp)
            if pose is not None:
                views.append((pose[0], pose[1], u, v))
        if len(views) < min_obs:
            continue
        r = track_residual(cam, views)
        if r is not None:
            residuals.append(r)
            lengths.append(len(views))
    if not residuals:
        return {'tracks': 0}
    res, n = np.array(residuals), np.array(lengths)
    q = np.percentile(res, [25, 50, 75, 90])
    return {'tracks': int(len(res)), 'observations': int(n.sum()),
            'residual_px_q25': float(q[0]), 'residual_px_median': float(q[1]), 'residual_px_q75': float(q[2]),
            'residual_px_q90': float(q[3]),
            'tracks_over_1px': float((res > 1).mean()), 'tracks_over_3px': float((res > 3).mean()),
            'observations_over_1px': float(n[res > 1].sum() / n.sum()),
            'observations_over_3px': float(n[res > 3].sum() / n.sum())}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('folder')
    ap.add_argument('--min-obs', type=int, default=5)
    ap.add_argument('--json', action='store_true')
    a = ap.parse_args()
    for name in ('observations.txt', 'camera.yaml', 'groundtruth.txt'):
        if not os.path.isfile(os.path.join(a.folder, name)):
            sys.exit(f'{a.folder}: {name} not found (a folder written by mcslam run --save-tracks or mcslam synth)')
    m = measure(a.folder, a.min_obs)
    if a.json:
        print(json.dumps(m))
    elif m['tracks'] == 0:
        print(f'{a.folder}: no track seen in {a.min_obs} frames with a true pose')
    else:
        print(f"{a.folder}: {m['tracks']} tracks, residual px q25/median/q75/q90 {m['residual_px_q25']:.3f}/"
              f"{m['residual_px_median']:.3f}/{m['residual_px_q75']:.3f}/{m['residual_px_q90']:.3f}; over 1 px: "
              f"{100 * m['tracks_over_1px']:.0f} % of tracks ({100 * m['observations_over_1px']:.0f} % of observations); "
              f"over 3 px: {100 * m['tracks_over_3px']:.0f} % ({100 * m['observations_over_3px']:.0f} %)")


if __name__ == '__main__':
    main()
