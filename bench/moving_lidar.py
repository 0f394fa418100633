#!/usr/bin/env python3
"""Moving LiDAR side by side: minemap and KISS-ICP on the same scans, scored by the same code.

usage: bench/moving_lidar.py [--sequences kitti07,sim-spinning,sim-handheld] [--sequence NAME=SCANS,REFERENCE]
                             [--threads 2] [--no-kiss] [--out bench/out/moving_lidar.json] [--md FILE]
                             [--workdir bench/out/moving_lidar] [--minemap build/minemap] [--minemap-arg ARG]
                             [--sim-scans 200] [--sim-speed-mps V] [--sim-loop-m M] [--sim-seed 1]

For each sequence (a folder of scans and a reference trajectory) it runs, one after the other,
  minemap   build/minemap map SCANS --out WORK/minemap --threads T --quiet --write-unregistered
            (the defaults: no initial poses; --write-unregistered only writes the outputs of a run
            with an unregistered scan, it changes no pose; the exit code is kept), and reads
            WORK/minemap/trajectory.tum: metres, right-handed, z up, the first scan's frame, one pose
            per scan in scan order (report.json's unit and frame, the survey's own, are recorded:
            for PCD and KITTI surveys metres, z up, so trajectory.tum is the files' own frame);
  KISS-ICP  bench/kiss_icp_peer.py SCANS --out WORK/kiss --threads T (its own venv,
            bench/.venv-kiss, made on first use; a sequence is scored without it when the venv
            cannot be made, and --no-kiss skips it), poses.tum: the same frame and order;
then scores both with bench/trajectory_errors.py against the reference, poses paired by order
(one per scan): ATE after aligning the first pose (evo_ape --align_origin, translation part) and
RPE per step (evo_rpe --delta 1 --delta_unit f), and writes JSON (--out) and a Markdown table
(--md, default the JSON's path with .md).

Sequences (--sequences, comma-separated):
  kitti07          shared/data/kitti07_sequence: 5 real KITTI 07 HDL-64 scans (NNNNNN/points.bin,
                   downsampled, 3-12 m apart), reference graph.txt
  kitti07-pcd      the same scans written as binary PCD (x y z intensity time ring; every point of a
                   scan at its scan's stamp, so nothing to deskew) with truth.tum from graph.txt:
                   checks the PCD path of both methods on real data
  sim-spinning     `minemap simulate --sensor spinning --out WORK/scans --scans N [--speed-mps V]
  sim-handheld      [--loop M] --seed S`: DIR/scanNNN.pcd (metres, per-point absolute times, each sweep
                   stamped at its middle) and DIR/truth.tum (mid-sweep stamps), the reference
  NAME=SCANS,REF   (--sequence, repeatable) any folder of PCD or KITTI scans and a reference
                   trajectory in a format trajectory_errors.py reads, one pose per scan

Exit status 0 when every method that ran was scored (a method's own exit code, e.g. minemap's 13
for a doubtful match, is reported, not fatal), 1 otherwise.
"""
import argparse
import datetime
import json
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
# The shared data folder as python/tests finds it: $MINEMAP_SHARED_DATA, ../shared/data, /work/shared/data.
SHARED_DATA = next((p for p in [os.environ.get("MINEMAP_SHARED_DATA"), ROOT.parent / "shared" / "data",
                                "/work/shared/data"] if p and pathlib.Path(p).is_dir()), "/work/shared/data")
KITTI07 = pathlib.Path(SHARED_DATA) / "kitti07_sequence"
REEXEC = "MOVING_LIDAR_REEXEC"


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", default="kitti07,sim-spinning,sim-handheld",
                        help="built-in sequences, comma-separated (kitti07, kitti07-pcd, sim-spinning, "
                             "sim-handheld); '' for none")
    parser.add_argument("--sequence", action="append", default=[], metavar="NAME=SCANS,REFERENCE",
                        help="a sequence of your own (repeatable)")
    parser.add_argument("--threads", type=int, default=2, help="threads for both methods (default 2)")
    parser.add_argument("--no-kiss", action="store_true", help="skip KISS-ICP")
    parser.add_argument("--no-minemap", action="store_true", help="skip minemap")
    parser.add_argument("--kiss-arg", action="append", default=[], metavar="ARG",
                        help="extra argument for kiss_icp_peer.py (repeatable, e.g. --kiss-arg=--max-range=50)")
    parser.add_argument("--minemap", default=str(ROOT / "build" / "minemap"), help="minemap binary")
    parser.add_argument("--minemap-arg", action="append", default=[], metavar="ARG",
                        help="extra argument for minemap map (repeatable)")
    parser.add_argument("--out", default=str(HERE / "out" / "moving_lidar.json"), help="JSON results")
    parser.add_argument("--md", help="Markdown table (default: --out with .md)")
    parser.add_argument("--workdir", default=str(HERE / "out" / "moving_lidar"),
                        help="scans made here (simulated, kitti07-pcd) and each method's outputs")
    parser.add_argument("--sim-scans", type=int, default=200, help="sweeps per simulated sequence")
    parser.add_argument("--sim-speed-mps", type=float, help="simulated speed (default: the simulator's)")
    parser.add_argument("--sim-loop-m", type=float, default=0.0, help="simulated loop length (0: straight)")
    parser.add_argument("--sim-seed", type=int, default=1)
    parser.add_argument("--regenerate", action="store_true", help="simulate again even when WORK holds the scans")
    parser.add_argument("--timeout-s", type=float, default=3600.0, help="per method and sequence")
    args = parser.parse_args(argv)
    args.md = args.md or str(pathlib.Path(args.out).with_suffix(".md"))
    return args


def ensure_numpy(args):
    """trajectory_errors needs numpy: run in a python that has it (the KISS venv's, else build/venv's)."""
    try:
        import numpy  # noqa: F401
        return
    except ImportError:
        pass
    if os.environ.get(REEXEC):
        sys.exit("moving_lidar: no numpy in " + sys.executable)
    candidates = []
    if not args.no_kiss:
        sys.path.insert(0, str(HERE))
        import kiss_icp_peer

        python = kiss_icp_peer.ensure_venv()
        if python:
            candidates.append(str(python))
    candidates.append(str(ROOT / "build" / "venv" / "bin" / "python"))
    for python in candidates:
        has_numpy = pathlib.Path(python).exists() and subprocess.run(
            [python, "-c", "import numpy"], capture_output=True).returncode == 0
        if has_numpy:
            env = dict(os.environ, **{REEXEC: "1"})
            os.execve(python, [python, str(pathlib.Path(__file__).resolve()), *sys.argv[1:]], env)
    sys.exit("moving_lidar: needs numpy (pip install numpy), or the KISS venv (drop --no-kiss) or build/venv")


# ---- sequences ------------------------------------------------------------------------------------

def simulate_supports_sensor(minemap):
    try:
        text = subprocess.run([minemap, "simulate", "--help"], capture_output=True, text=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return "--sensor" in text


def make_sim(args, name, sensor, folder):
    scans = folder / "scans"
    if scans.exists() and (scans / "truth.tum").exists() and not args.regenerate:
        return scans, scans / "truth.tum", None
    if scans.exists():
        shutil.rmtree(scans)
    command = [args.minemap, "simulate", "--sensor", sensor, "--out", str(scans), "--scans", str(args.sim_scans),
               "--seed", str(args.sim_seed)]
    if args.sim_speed_mps is not None:
        command += ["--speed-mps", str(args.sim_speed_mps)]
    if args.sim_loop_m:
        command += ["--loop", str(args.sim_loop_m)]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        return None, None, f"simulate failed ({done.returncode}): {(done.stderr or done.stdout)[-500:]}"
    return scans, scans / "truth.tum", " ".join(command[1:])


def make_kitti07_pcd(folder):
    """KITTI 07's five scans as binary PCD (x y z intensity time ring) and truth.tum from graph.txt."""
    import numpy as np

    import trajectory_errors as te

    scans = folder / "scans"
    scans.mkdir(parents=True, exist_ok=True)
    poses, _, _ = te.read_trajectory(KITTI07 / "graph.txt")
    stamps = np.arange(len(poses)) * 0.1  # a 10 Hz sensor's stamps
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("time", "<f8"), ("ring", "<u2")])
    for i, stamp in enumerate(stamps):
        xyz = np.fromfile(KITTI07 / f"{i:06d}" / "points.bin", dtype="<f4").reshape(-1, 3)
        cloud = np.zeros(len(xyz), dtype=dtype)
        cloud["x"], cloud["y"], cloud["z"] = xyz.T
        cloud["time"] = stamp
        header = ("# .PCD v0.7 - KITTI 07 sample (gtsam_points kitti_07_dump) rewritten by bench/moving_lidar.py\n"
                  "VERSION 0.7\nFIELDS x y z intensity time ring\nSIZE 4 4 4 4 8 2\nTYPE F F F F F U\n"
                  f"COUNT 1 1 1 1 1 1\nWIDTH {len(cloud)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
                  f"POINTS {len(cloud)}\nDATA binary\n")
        (scans / f"scan{i:03d}.pcd").write_bytes(header.encode() + cloud.tobytes())
    te.write_tum(scans / "truth.tum", poses, stamps)
    return scans, scans / "truth.tum", "kitti07 as PCD"


def sequences(args, work):
    """[(name, scans folder or None, reference or None, note)]"""
    out = []
    names = [n.strip() for n in args.sequences.split(",") if n.strip()]
    sim_ok = None
    for name in names:
        if name == "kitti07":
            out.append((name, KITTI07, KITTI07 / "graph.txt", "real KITTI 07, 5 downsampled HDL-64 scans 3-12 m apart"))
        elif name == "kitti07-pcd":
            scans, ref, note = make_kitti07_pcd(work / name)
            out.append((name, scans, ref, note))
        elif name.startswith("sim-"):
            sensor = name[4:]
            if sensor not in ("spinning", "handheld"):
                sys.exit(f"moving_lidar: unknown sequence {name}")
            if sim_ok is None:
                sim_ok = simulate_supports_sensor(args.minemap)
            if not sim_ok:
                out.append((name, None, None, "skipped: this minemap's simulate has no --sensor"))
                continue
            scans, ref, note = make_sim(args, name, sensor, work / name)
            out.append((name, scans, ref, note))
        else:
            sys.exit(f"moving_lidar: unknown sequence {name} (kitti07, kitti07-pcd, sim-spinning, sim-handheld)")
    for spec in args.sequence:
        try:
            name, rest = spec.split("=", 1)
            scans, ref = rest.rsplit(",", 1)
        except ValueError:
            sys.exit(f"moving_lidar: --sequence {spec}: expected NAME=SCANS,REFERENCE")
        out.append((name, pathlib.Path(scans), pathlib.Path(ref), "given"))
    return out


# ---- the methods ----------------------------------------------------------------------------------

def run_timed(command, timeout_s):
    start = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
        rc, stdout, stderr = done.returncode, done.stdout, done.stderr
    except subprocess.TimeoutExpired as expired:
        rc, stdout, stderr = "timeout", expired.stdout or "", expired.stderr or ""
    text = (lambda x: x if isinstance(x, str) else "")
    return rc, time.perf_counter() - start, text(stdout), text(stderr)


def run_minemap(args, scans, out):
    if out.exists():
        shutil.rmtree(out)
    command = [args.minemap, "map", str(scans), "--out", str(out), "--threads", str(args.threads), "--quiet",
               "--write-unregistered", *args.minemap_arg]
    rc, wall, _, stderr = run_timed(command, args.timeout_s)
    result = {"method": "minemap", "command": " ".join(command[1:]), "exit_code": rc, "wall_process_s": wall,
              "stderr_tail": stderr[-1500:], "poses_file": str(out / "trajectory.tum")}
    report = out / "report.json"
    if report.exists():
        data = json.loads(report.read_text())
        result["version"] = data.get("version")
        result["doubtful_scans"] = data.get("doubtful_scans")
        result["report_unit"], result["report_frame"] = data.get("unit"), data.get("frame")
        times = data.get("timings_s")
        if isinstance(times, dict):
            # report.json's stage times; the registration is every stage but reading and writing.
            result["timings_s"] = {k: v for k, v in times.items() if k != "per_scan"}
            result["wall_registration_s"] = float(sum(v for k, v in times.items()
                                                      if isinstance(v, (int, float)) and k not in ("load", "write")))
    return result


def run_kiss(args, scans, out):
    if out.exists():
        shutil.rmtree(out)
    command = [sys.executable, str(HERE / "kiss_icp_peer.py"), str(scans), "--out", str(out),
               "--threads", str(args.threads), "--quiet", *args.kiss_arg]
    rc, wall, _, stderr = run_timed(command, args.timeout_s)
    result = {"method": "KISS-ICP", "command": " ".join(command[1:]), "exit_code": rc, "wall_process_s": wall,
              "stderr_tail": stderr[-1500:], "poses_file": str(out / "poses.tum")}
    if rc == 3:
        result["skipped"] = "no venv with kiss-icp (bench/.venv-kiss could not be made)"
    summary = out / "kiss_icp.json"
    if summary.exists():
        data = json.loads(summary.read_text())
        result["version"] = data["kiss_icp_version"]
        result["wall_registration_s"] = data["wall_registration_s"]
        result["config"] = data["config"]
        result["deskew"] = data["deskew"]
        result["kitti_correction"] = data["kitti_correction"]
        result["cpu_process_s"] = data["cpu_process_s"]
    return result


def score(result, reference):
    import trajectory_errors as te

    poses = pathlib.Path(result["poses_file"])
    if not poses.exists():
        result["errors"] = None
        result.setdefault("note", "no poses written")
        return False
    try:
        p, ps, _ = te.read_trajectory(poses)
        q, qs, _ = te.read_trajectory(reference)
        est, ref = te.associate((p, ps), (q, qs), "index")
        result["errors"] = te.errors(est, ref)
    except ValueError as error:
        result["errors"] = None
        result["note"] = f"not scored: {error}"
        return False
    return True


# ---- output ---------------------------------------------------------------------------------------

def fmt(value, digits=1):
    return "-" if value is None else f"{value:.{digits}f}"


def markdown(results):
    lines = ["| sequence | scans | path m | method | wall s (registration s) | ATE mean cm | ATE mean % of path "
             "| RPE mean cm / deg | exit |",
             "|---|---|---|---|---|---|---|---|---|"]
    for seq in results["sequences"]:
        if not seq["methods"]:
            lines.append(f"| {seq['name']} | - | - | - | - | - | - | - | {seq.get('note', '')} |")
        for m in seq["methods"]:
            e = m.get("errors") or {}
            wall = fmt(m.get("wall_process_s"), 2)
            if m.get("wall_registration_s") is not None:
                wall += f" ({m['wall_registration_s']:.2f})"
            exit_code = m.get("skipped") and "skipped" or str(m.get("exit_code"))
            lines.append(
                f"| {seq['name']} | {seq.get('scans', '-')} | {fmt(e.get('path_length_m'))} | {m['method']} | {wall} "
                f"| {fmt(e.get('ate_trans_mean_cm'))} | {fmt(e.get('ate_trans_mean_pct_of_path'), 2)} "
                f"| {fmt(e.get('rpe_trans_mean_cm'))} / {fmt(e.get('rpe_rot_mean_deg'), 2)} | {exit_code} |")
    return "\n".join(lines) + "\n"


def count_scans(folder):
    folder = pathlib.Path(folder)
    return sum(1 for p in folder.iterdir() if p.suffix.lower() in (".pcd", ".bin") or (p / "points.bin").is_file())


def main():
    args = parse_args()
    ensure_numpy(args)
    sys.path.insert(0, str(HERE))
    work = pathlib.Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    if not args.no_minemap and not pathlib.Path(args.minemap).exists():
        sys.exit(f"moving_lidar: no minemap binary at {args.minemap} (build it, or --minemap PATH, or --no-minemap)")
    results = {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": platform.processor()},
        "threads": args.threads,
        "errors_computed_by": "bench/trajectory_errors.py (ATE: evo_ape --align_origin, translation part; "
                              "RPE: evo_rpe --delta 1 --delta_unit f; poses paired by order)",
        "sequences": [],
    }
    ok = True
    for name, scans, reference, note in sequences(args, work):
        seq = {"name": name, "scans_folder": str(scans) if scans else None,
               "reference": str(reference) if reference else None, "note": note, "methods": []}
        results["sequences"].append(seq)
        if scans is None:
            print(f"{name}: {note}", file=sys.stderr)
            continue
        seq["scans"] = count_scans(scans)
        runs = []
        if not args.no_minemap:
            runs.append(("minemap", lambda: run_minemap(args, scans, work / name / "minemap")))
        if not args.no_kiss:
            runs.append(("KISS-ICP", lambda: run_kiss(args, scans, work / name / "kiss")))
        for method, runner in runs:
            print(f"{name}: {method} ...", file=sys.stderr, flush=True)
            result = runner()
            seq["methods"].append(result)
            if result.get("skipped"):
                print(f"{name}: {method} skipped: {result['skipped']}", file=sys.stderr)
                continue
            if not score(result, reference):
                ok = False
            e = result.get("errors") or {}
            print(f"{name}: {method}: exit {result['exit_code']}, {result['wall_process_s']:.2f} s, "
                  f"ATE mean {fmt(e.get('ate_trans_mean_cm'))} cm, RPE mean {fmt(e.get('rpe_trans_mean_cm'))} cm / "
                  f"{fmt(e.get('rpe_rot_mean_deg'), 2)} deg {result.get('note', '')}", file=sys.stderr)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    table = markdown(results)
    pathlib.Path(args.md).write_text(table)
    print(table)
    print(f"wrote {out} and {args.md}", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
