#!/usr/bin/env python3
"""Trajectory errors as evo computes them: ATE after aligning the first pose, and RPE per step.

usage: bench/trajectory_errors.py ESTIMATE REFERENCE [--associate index|time] [--max-diff-s 0.01]
                                  [--unit m|cm|mm] [--ref-unit m|cm|mm]

Reads two trajectories (each in any of the formats below, told apart by its first data line) and
prints their errors as JSON. numpy only: the same code scores minemap and the KISS-ICP peer
(bench/moving_lidar.py), so the two methods' figures differ by their poses alone.

Formats (T_world_sensor; translations in metres unless --unit says otherwise; '#' comments):
  TUM      "t x y z qx qy qz qw" per line
  KITTI    12 numbers per line, the 3x4 matrix [R | t] row-major
  graph    "vK x y z qx qy qz qw" per line (gtsam_points' graph.txt; ordered by K)
  matrix   4x4 matrices, 4 rows of 4 numbers (blank lines between them optional), or 16 numbers a line;
           commas as blanks; a bottom row 0 0 0 T with T > 1 holds the stamp T (BALM's alidarPose.csv)

The errors (evo's definitions, https://github.com/MichaelGrupp/evo, metrics.py):
  ATE  the estimate is moved so that its first pose lands on the reference's first pose
       (evo_ape --align_origin): P'_i = Q_0 P_0^-1 P_i. The error of pose i is the norm of the
       translation difference |t(P'_i) - t(Q_i)| (evo's translation_part). Reported: mean, median,
       rmse, max (cm), and the mean and rmse as % of the reference path length (the sum of its
       steps' lengths, evo's path_length).
  RPE  delta = 1 frame, every consecutive pair (evo_rpe --delta 1 --delta_unit f):
       E_i = (Q_i^-1 Q_{i+1})^-1 (P_i^-1 P_{i+1}); translation error |t(E_i)| (cm), rotation error
       the angle of R(E_i) (deg). Reported: mean, median, rmse, max of each.

Association: by order (index, the default: both files hold one pose per scan, in scan order, and
must hold as many) or by timestamp (TUM files on both sides; each estimate stamp takes the nearest
reference stamp within --max-diff-s, as evo's sync.associate_trajectories does).
"""
import argparse
import json
import math
import sys

try:
    import numpy as np
except ImportError:  # numpy only; the system python may lack it: run as a script, try the venvs that have it
    if __name__ != "__main__":
        raise
    import os
    import pathlib

    _here = pathlib.Path(__file__).resolve().parent
    for _python in (_here / ".venv-kiss" / "bin" / "python", _here.parent / "build" / "venv" / "bin" / "python"):
        if _python.exists() and not os.environ.get("TRAJECTORY_ERRORS_REEXEC"):
            os.environ["TRAJECTORY_ERRORS_REEXEC"] = "1"
            os.execv(str(_python), [str(_python), str(pathlib.Path(__file__).resolve()), *sys.argv[1:]])
    sys.exit("trajectory_errors: needs numpy: pip install numpy, or make bench/.venv-kiss "
             "(bench/kiss_icp_peer.py --setup)")

UNITS_TO_M = {"m": 1.0, "cm": 0.01, "mm": 0.001}


# ---- reading --------------------------------------------------------------------------------------

def quaternion_to_matrix(qx, qy, qz, qw):
    """Rotation matrix of a unit quaternion (normalised here; Hamilton convention, as TUM and Eigen)."""
    q = np.array([qw, qx, qy, qz], dtype=float)
    n = np.linalg.norm(q)
    if not n > 0.0:
        raise ValueError("zero quaternion")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quaternion(r):
    """(qx, qy, qz, qw) of a rotation matrix, qw >= 0."""
    r = np.asarray(r, dtype=float)
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        w, x, y, z = (r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        w, x, y, z = (r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        w, x, y, z = (r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def pose_from_tq(t, q):
    pose = np.eye(4)
    pose[:3, :3] = quaternion_to_matrix(*q)
    pose[:3, 3] = t
    return pose


def _data_lines(text):
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.split("#", 1)[0].strip()
        if stripped:
            yield number, stripped.replace(",", " ").split()


def detect_format(path):
    """'tum', 'kitti', 'graph' or 'matrix', from the first data line."""
    with open(path) as f:
        for _, tokens in _data_lines(f.read()):
            if tokens[0][:1] in "vV" and tokens[0][1:].isdigit():
                return "graph"
            return {8: "tum", 12: "kitti", 4: "matrix", 16: "matrix"}.get(len(tokens)) or _fail(
                path, f"first data line has {len(tokens)} values: not TUM (8), KITTI (12), graph (vK + 7) "
                      "or a 4x4 matrix (4 a row or 16 a line)")
    _fail(path, "no data lines")


def _fail(path, message):
    raise ValueError(f"{path}: {message}")


def _rigid(pose, path, where):
    r = pose[:3, :3]
    if not np.all(np.isfinite(pose)):
        _fail(path, f"{where}: not finite")
    if np.abs(r.T @ r - np.eye(3)).max() > 1e-3 or abs(np.linalg.det(r) - 1.0) > 1e-3:
        _fail(path, f"{where}: the rotation part is not a rotation")
    if np.abs(pose[3] - [0, 0, 0, 1]).max() > 1e-9:
        _fail(path, f"{where}: last row is not 0 0 0 1")
    return pose


def read_trajectory(path, unit="m", fmt=None):
    """Returns (poses N x 4 x 4 with translations in metres, stamps N or None, format name)."""
    scale = UNITS_TO_M[unit]
    fmt = fmt or detect_format(path)
    with open(path) as f:
        lines = list(_data_lines(f.read()))
    poses, stamps = [], []
    if fmt == "tum":
        for number, tokens in lines:
            if len(tokens) != 8:
                _fail(path, f"line {number}: TUM needs 8 values, not {len(tokens)}")
            v = [float(x) for x in tokens]
            stamps.append(v[0])
            poses.append(pose_from_tq(np.array(v[1:4]) * scale, v[4:8]))
    elif fmt == "graph":
        keyed = []
        for number, tokens in lines:
            if len(tokens) != 8 or not tokens[0][1:].isdigit():
                _fail(path, f"line {number}: graph needs 'vK x y z qx qy qz qw'")
            v = [float(x) for x in tokens[1:]]
            keyed.append((int(tokens[0][1:]), pose_from_tq(np.array(v[0:3]) * scale, v[3:7])))
        keyed.sort(key=lambda kv: kv[0])
        keys = [k for k, _ in keyed]
        if len(set(keys)) != len(keys):
            _fail(path, "a vertex number appears twice")
        poses = [p for _, p in keyed]
        stamps = [float(k) for k in keys]
    elif fmt == "kitti":
        for number, tokens in lines:
            if len(tokens) != 12:
                _fail(path, f"line {number}: KITTI needs 12 values, not {len(tokens)}")
            pose = np.eye(4)
            pose[:3, :4] = np.array([float(x) for x in tokens]).reshape(3, 4)
            pose[:3, 3] *= scale
            poses.append(_rigid(pose, path, f"line {number}"))
        stamps = None
    elif fmt == "matrix":
        values = [float(x) for _, tokens in lines for x in tokens]
        if len(values) % 16:
            _fail(path, f"{len(values)} numbers: not a whole number of 4x4 matrices")
        corner_stamps = []
        for i in range(len(values) // 16):
            pose = np.array(values[16 * i:16 * i + 16]).reshape(4, 4)
            if not pose[3, :3].any() and pose[3, 3] > 1.0:
                # BALM's alidarPose.csv (hku-mars/BALM, benchmark_realworld): the pose's unix stamp
                # where the 1 goes.
                corner_stamps.append(pose[3, 3])
                pose[3, 3] = 1.0
            pose[:3, 3] *= scale
            poses.append(_rigid(pose, path, f"matrix {i}"))
        stamps = corner_stamps if len(corner_stamps) == len(poses) else None
    else:
        raise ValueError(f"unknown format {fmt}")
    if not poses:
        _fail(path, "no poses")
    return np.array(poses), (np.array(stamps) if stamps is not None else None), fmt


def write_tum(path, poses, stamps=None):
    """Writes N x 4 x 4 poses (metres) as TUM; stamps default to 0, 1, 2, ..."""
    stamps = np.arange(len(poses), dtype=float) if stamps is None else stamps
    with open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for t, pose in zip(stamps, poses):
            q = matrix_to_quaternion(pose[:3, :3])
            x, y, z = pose[:3, 3]
            f.write(f"{t:.9f} {x:.9f} {y:.9f} {z:.9f} {q[0]:.12f} {q[1]:.12f} {q[2]:.12f} {q[3]:.12f}\n")


# ---- association ----------------------------------------------------------------------------------

def associate(est, ref, mode="index", max_diff_s=0.01):
    """Pairs the poses: returns (est_poses, ref_poses) of equal length."""
    (p, ps), (q, qs) = est, ref
    if mode == "index":
        if len(p) != len(q):
            raise ValueError(f"association by index: the estimate holds {len(p)} poses, the reference {len(q)}")
        return p, q
    if ps is None or qs is None:
        raise ValueError("association by time needs timestamps on both sides (TUM or graph)")
    order = np.argsort(qs)
    qs_sorted = qs[order]
    pairs_p, pairs_q, used = [], [], set()
    for i, t in enumerate(ps):
        j = int(np.searchsorted(qs_sorted, t))
        best = min((k for k in (j - 1, j) if 0 <= k < len(qs_sorted)), key=lambda k: abs(qs_sorted[k] - t))
        if abs(qs_sorted[best] - t) <= max_diff_s and best not in used:
            used.add(best)
            pairs_p.append(p[i])
            pairs_q.append(q[order[best]])
    if len(pairs_p) < 2:
        raise ValueError(f"association by time: {len(pairs_p)} pairs within {max_diff_s} s")
    return np.array(pairs_p), np.array(pairs_q)


# ---- errors ---------------------------------------------------------------------------------------

def inverse(pose):
    out = np.eye(4)
    r = pose[:3, :3]
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ pose[:3, 3]
    return out


def rotation_angle_deg(r):
    """The angle of a rotation matrix, robust near 0 and 180 deg (atan2 of sin and cos)."""
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return math.degrees(math.atan2(0.5 * np.linalg.norm(axis), 0.5 * (np.trace(r) - 1.0)))


def path_length_m(poses):
    positions = poses[:, :3, 3]
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def _stats(values, name, unit):
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return {f"{name}_{s}_{unit}": None for s in ("mean", "median", "rmse", "max")}
    return {
        f"{name}_mean_{unit}": float(v.mean()),
        f"{name}_median_{unit}": float(np.median(v)),
        f"{name}_rmse_{unit}": float(math.sqrt(np.mean(v * v))),
        f"{name}_max_{unit}": float(v.max()),
    }


def align_origin(est, ref):
    """evo's align_origin: P'_i = Q_0 P_0^-1 P_i."""
    return np.einsum("ij,njk->nik", ref[0] @ inverse(est[0]), est)


def ate(est, ref):
    """ATE (translation part) after aligning the first pose; per-pose errors in metres."""
    aligned = align_origin(est, ref)
    return np.linalg.norm(aligned[:, :3, 3] - ref[:, :3, 3], axis=1)


def rpe(est, ref, delta=1):
    """RPE over pairs (i, i + delta): translation errors (m) and rotation errors (deg)."""
    trans, rot = [], []
    for i in range(len(est) - delta):
        ref_step = inverse(ref[i]) @ ref[i + delta]
        est_step = inverse(est[i]) @ est[i + delta]
        error = inverse(ref_step) @ est_step
        trans.append(float(np.linalg.norm(error[:3, 3])))
        rot.append(rotation_angle_deg(error[:3, :3]))
    return np.array(trans), np.array(rot)


def errors(est, ref):
    """Every figure for one estimate against its reference (poses already associated, metres)."""
    est, ref = np.asarray(est, dtype=float), np.asarray(ref, dtype=float)
    length = path_length_m(ref)
    ate_m = ate(est, ref)
    rpe_m, rpe_deg = rpe(est, ref)
    out = {"poses": int(len(est)), "path_length_m": length}
    out.update(_stats(ate_m * 100.0, "ate_trans", "cm"))
    pct = (lambda x: 100.0 * x / length) if length > 0 else (lambda x: None)
    out["ate_trans_mean_pct_of_path"] = pct(float(ate_m.mean()))
    out["ate_trans_rmse_pct_of_path"] = pct(float(math.sqrt(np.mean(ate_m * ate_m))))
    out["rpe_pairs"] = int(len(rpe_m))
    out.update(_stats(rpe_m * 100.0, "rpe_trans", "cm"))
    out.update(_stats(rpe_deg, "rpe_rot", "deg"))
    return out


def compare_files(estimate, reference, unit="m", ref_unit="m", associate_by="index", max_diff_s=0.01):
    p, ps, _ = read_trajectory(estimate, unit)
    q, qs, _ = read_trajectory(reference, ref_unit)
    est, ref = associate((p, ps), (q, qs), associate_by, max_diff_s)
    return errors(est, ref)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimate")
    parser.add_argument("reference")
    parser.add_argument("--associate", choices=["index", "time"], default="index")
    parser.add_argument("--max-diff-s", type=float, default=0.01, help="association by time: largest stamp gap")
    parser.add_argument("--unit", choices=sorted(UNITS_TO_M), default="m", help="the estimate's length unit")
    parser.add_argument("--ref-unit", choices=sorted(UNITS_TO_M), default="m", help="the reference's length unit")
    args = parser.parse_args(argv)
    try:
        result = compare_files(args.estimate, args.reference, args.unit, args.ref_unit, args.associate, args.max_diff_s)
    except (OSError, ValueError) as error:
        print(f"trajectory_errors: {error}", file=sys.stderr)
        return 2
    result = {"estimate": args.estimate, "reference": args.reference, "association": args.associate, **result}
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
