#!/usr/bin/env python3
"""KISS-ICP (PyPI `kiss-icp`) on a folder of scans as minemap reads them: an optional bench peer.

usage: bench/kiss_icp_peer.py SCANS --out DIR [--threads 2] [--deskew auto|on|off]
                              [--kitti-deskew none|azimuth] [--no-kitti-correction] [--max-range M]
       bench/kiss_icp_peer.py --setup        (only make the venv)

Never needed by the tests. On first use it makes its own venv, bench/.venv-kiss (git-ignored: bench/
.gitignore), with /usr/bin/python3 -m venv and pip installs kiss-icp==KISS_ICP_VERSION from PyPI into
it, then runs itself there (KISS_ICP_PYTHON=/path/to/python picks another interpreter that has it).
Exit 3 when that venv cannot be made (no network, no venv module): bench/moving_lidar.py then
reports KISS-ICP as skipped.

Scans, in minemap's order (natural sort of the names):
  *.pcd            PCD v0.7, DATA binary, ascii or binary_compressed; x y z, and per-point times
                   from a field named time, t or timestamp (any numeric type) when there is one
  NNNNNN.bin       KITTI Velodyne: float32 x y z intensity
  NNNNNN/points.bin  float32 x y z (gtsam_points' kitti_07_dump, shared/data/kitti07_sequence)

KISS-ICP is run through its Python API (kiss_icp.kiss_icp.KissICP, register_frame per scan), with the
config its pipeline builds (kiss_icp.config.parser.load_config without a YAML file: KISSConfig's
defaults, then voxel_size = max_range / 100 as load_config derives it; max_range 100 m -> 1 m
voxels), except:
  * registration.max_num_threads = --threads (its TBB core: Preprocessor and Registration each
    install a process-wide tbb::global_control(max_allowed_parallelism) with it, as the C++ source
    of 1.2.3 shows; the 1.3.0 wheel ships none); numpy's BLAS threads are capped to the same number
    through the environment.
  * data.deskew: on when the scans carry per-point times (PCD time field; --deskew auto), off
    otherwise. KISS-ICP 1.x normalises the times itself ((t - min) / (max - min), checked here on
    1.3.0) and deskews each sweep into the frame of its LAST point with its constant-velocity model
    (exp((s - 1) * log(last_delta))), so its pose is the end-of-sweep pose. The peer writes that to
    poses_end_of_sweep.tum, and to poses.tum the pose at the middle of the sweep ((t_min + t_max) / 2,
    the stamp of the simulator's truth.tum) from the same model: P_mid = P_end exp(-0.5 log(delta)),
    delta the motion the deskew used. Without times both files hold the same poses.
  * KITTI .bin and points.bin: KISS-ICP's two KITTI dataloaders both apply its
    _correct_kitti_scan (the HDL-64's 0.205 deg vertical-angle correction; --no-kitti-correction
    turns it off). The odometry loader (datasets/kitti.py, KITTI odometry's already deskewed scans)
    passes no times, so no deskew; the raw loader (datasets/kitti_raw.py) deskews with times from the
    azimuth, s = 0.5 (1 - atan2(y, x) / pi). --kitti-deskew azimuth does the latter; the default is
    the odometry loader's (none), right for shared/data/kitti07_sequence, whose five scans are
    KITTI odometry scans 3-12 m apart (a constant-velocity deskew from such steps would be wrong).

Writes DIR/poses.tum (T_world_sensor of each scan, metres, the first scan's frame; stamps the middle
of each sweep in the PCD's own seconds when it carries times, else 0, 1, 2, ...),
DIR/poses_end_of_sweep.tum, and DIR/kiss_icp.json (version, the whole config, per-scan times,
wall clock of the registration alone (the register_frame calls, as KISS-ICP's pipeline times
them), of reading the scans and of the whole process, CPU time).
"""
import os
import sys
import time

PROCESS_START = time.perf_counter()
PROCESS_CPU_START = time.process_time()

import argparse  # noqa: E402
import json  # noqa: E402
import pathlib  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
VENV = HERE / ".venv-kiss"
KISS_ICP_VERSION = "1.3.0"
EXIT_NO_VENV = 3


# ---- the venv -------------------------------------------------------------------------------------

def venv_python():
    return VENV / "bin" / "python"


def has_kiss(python):
    if not pathlib.Path(python).exists():
        return False
    probe = f"import kiss_icp, numpy; assert kiss_icp.__version__ == '{KISS_ICP_VERSION}'"
    return subprocess.run([str(python), "-c", probe], capture_output=True, cwd="/").returncode == 0


def ensure_venv(quiet=False):
    """The python that has kiss-icp; makes bench/.venv-kiss on first use. None when it cannot."""
    chosen = os.environ.get("KISS_ICP_PYTHON")
    if chosen:
        return pathlib.Path(chosen) if has_kiss(chosen) else None
    if has_kiss(venv_python()):
        return venv_python()
    log = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr))
    log(f"kiss_icp_peer: making {VENV} (kiss-icp=={KISS_ICP_VERSION} from PyPI)")
    try:
        subprocess.run(["/usr/bin/python3", "-m", "venv", str(VENV)], check=True, capture_output=True)
        subprocess.run([str(venv_python()), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                        f"kiss-icp=={KISS_ICP_VERSION}"], check=True, capture_output=True, timeout=900)
    except (OSError, subprocess.SubprocessError) as error:
        detail = getattr(error, "stderr", b"") or b""
        log(f"kiss_icp_peer: cannot make the venv: {error}\n{detail.decode(errors='replace')[-2000:]}")
        return None
    return venv_python() if has_kiss(venv_python()) else None


def in_kiss_python():
    try:
        import kiss_icp  # noqa: F401
    except ImportError:
        return False
    return kiss_icp.__version__ == KISS_ICP_VERSION or bool(os.environ.get("KISS_ICP_PYTHON"))


# ---- reading scans (numpy) -------------------------------------------------------------------------

def natural_key(name):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def list_scans(folder):
    """[(name, path, kind)] in minemap's order; kind 'pcd', 'kitti4' or 'kitti3'."""
    folder = pathlib.Path(folder)
    pcd = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".pcd"]
    bins = [p for p in folder.iterdir() if p.is_file() and re.fullmatch(r"\d+\.bin", p.name)]
    dirs = [p for p in folder.iterdir() if p.is_dir() and re.fullmatch(r"\d+", p.name) and (p / "points.bin").is_file()]
    kinds = [k for k, v in (("pcd", pcd), ("kitti4", bins), ("kitti3", dirs)) if v]
    if len(kinds) != 1:
        raise SystemExit(f"kiss_icp_peer: {folder}: expected one layout of scans (*.pcd, NNNNNN.bin or "
                         f"NNNNNN/points.bin), found {kinds or 'none'}")
    kind = kinds[0]
    items = {"pcd": pcd, "kitti4": bins, "kitti3": dirs}[kind]
    items.sort(key=lambda p: natural_key(p.name))
    return [(p.stem if kind != "kitti3" else p.name, p / "points.bin" if kind == "kitti3" else p, kind) for p in items]


def lzf_decompress(data, size):
    """LZF (liblzf's format, as PCL's binary_compressed uses it), pure Python."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        ctrl = data[i]
        i += 1
        if ctrl < 32:
            out += data[i:i + ctrl + 1]
            i += ctrl + 1
        else:
            length = ctrl >> 5
            back = ((ctrl & 0x1F) << 8) + 1
            if length == 7:
                length += data[i]
                i += 1
            back += data[i]
            i += 1
            start = len(out) - back
            for k in range(length + 2):
                out.append(out[start + k])
    if len(out) != size:
        raise ValueError(f"LZF: {len(out)} bytes decompressed, the header says {size}")
    return bytes(out)


def read_pcd(path):
    """(points N x 3 float64, times N float64 or None): x y z and the time/t/timestamp field."""
    import numpy as np

    raw = pathlib.Path(path).read_bytes()
    header, pos = {}, 0
    while True:
        end = raw.index(b"\n", pos)
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    fields = header["FIELDS"]
    sizes = [int(s) for s in header["SIZE"]]
    types = header["TYPE"]
    counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    npoints = int(header["POINTS"][0]) if "POINTS" in header else int(header["WIDTH"][0]) * int(header["HEIGHT"][0])
    kind = header["DATA"][0].lower()
    names = []
    for i, name in enumerate(fields):
        names.append(name if name != "_" and name not in names else f"_pad{i}")
    dtype = np.dtype([(name, "<" + {"F": "f", "I": "i", "U": "u"}[t] + str(s), (c,) if c > 1 else ())
                      for name, s, t, c in zip(names, sizes, types, counts)])
    if kind == "binary":
        cloud = np.frombuffer(raw, dtype=dtype, count=npoints, offset=pos)
    elif kind == "binary_compressed":
        compressed, size = np.frombuffer(raw, "<u4", 2, pos)
        data = lzf_decompress(raw[pos + 8:pos + 8 + int(compressed)], int(size))
        cloud = np.empty(npoints, dtype=dtype)
        offset = 0
        for name in names:  # PCL stores binary_compressed field by field
            width = dtype[name].itemsize * npoints
            values = npoints * max(1, int(np.prod(dtype[name].shape)))
            cloud[name] = np.frombuffer(data[offset:offset + width], dtype=dtype[name].base,
                                        count=values).reshape(cloud[name].shape)
            offset += width
    elif kind == "ascii":
        table = np.loadtxt(raw[pos:].decode("ascii").splitlines(), ndmin=2)[:npoints]
        cloud = np.empty(len(table), dtype=dtype)
        column = 0
        for name, c in zip(names, counts):
            cloud[name] = table[:, column:column + c].reshape(cloud[name].shape)
            column += c
    else:
        raise ValueError(f"{path}: DATA {kind} is not read here")
    points = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(np.float64)
    time_field = next((f for f in ("time", "t", "timestamp") if f in names), None)
    times = cloud[time_field].astype(np.float64).ravel() if time_field else None
    keep = np.all(np.isfinite(points), axis=1)
    if times is not None:
        keep &= np.isfinite(times)
    return points[keep], (times[keep] if times is not None else None)


def read_kitti(path, floats):
    import numpy as np

    data = np.fromfile(path, dtype="<f4")
    if data.size % floats:
        raise ValueError(f"{path}: {data.size} floats, not a multiple of {floats}")
    points = data.reshape(-1, floats)[:, :3].astype(np.float64)
    return points[np.all(np.isfinite(points), axis=1)]


# ---- SE(3) ----------------------------------------------------------------------------------------

def _hat(w):
    import numpy as np

    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def se3_log(pose):
    """(rho, omega) with pose = exp(rho, omega), as Sophus::SE3d::log."""
    import numpy as np

    r, t = pose[:3, :3], pose[:3, 3]
    cos = np.clip(0.5 * (np.trace(r) - 1.0), -1.0, 1.0)
    theta = np.arccos(cos)
    if theta < 1e-8:
        omega = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    else:
        omega = theta / (2 * np.sin(theta)) * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    w = _hat(omega)
    if theta < 1e-8:
        v_inv = np.eye(3) - 0.5 * w + w @ w / 12.0
    else:
        v_inv = np.eye(3) - 0.5 * w + (1 - theta * np.sin(theta) / (2 * (1 - np.cos(theta)))) / theta ** 2 * (w @ w)
    return v_inv @ t, omega


def se3_exp(rho, omega):
    import numpy as np

    theta = np.linalg.norm(omega)
    w = _hat(omega)
    if theta < 1e-8:
        r = np.eye(3) + w + 0.5 * w @ w
        v = np.eye(3) + 0.5 * w + w @ w / 6.0
    else:
        r = np.eye(3) + np.sin(theta) / theta * w + (1 - np.cos(theta)) / theta ** 2 * (w @ w)
        v = np.eye(3) + (1 - np.cos(theta)) / theta ** 2 * w + (theta - np.sin(theta)) / theta ** 3 * (w @ w)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = r, v @ rho
    return pose


# ---- the run --------------------------------------------------------------------------------------

def kiss_config(threads, deskew, max_range=None, voxel_size=None):
    """KISS-ICP's config as load_config(None) builds it, with the thread count and deskew set."""
    from kiss_icp.config.parser import KISSConfig

    config = KISSConfig()
    if max_range is not None:
        config.data.max_range = float(max_range)
    if voxel_size is not None:
        config.mapping.voxel_size = float(voxel_size)
    config.data.deskew = bool(deskew)
    config.registration.max_num_threads = int(threads)
    # load_config's two steps after reading the (absent) YAML file:
    if config.data.max_range < config.data.min_range:
        config.data.min_range = 0.0
    if config.mapping.voxel_size is None:
        config.mapping.voxel_size = float(config.data.max_range / 100.0)
    return config


def run(args):
    import numpy as np

    import kiss_icp
    from kiss_icp.kiss_icp import KissICP
    from kiss_icp.pybind import kiss_icp_pybind

    sys.path.insert(0, str(HERE))
    from trajectory_errors import write_tum

    scans = list_scans(args.scans)
    if args.scans_limit:
        scans = scans[:args.scans_limit]
    kind = scans[0][2]
    kitti = kind in ("kitti3", "kitti4")
    read_s = 0.0

    def load(path):
        nonlocal read_s
        start = time.perf_counter()
        if kind == "pcd":
            points, times = read_pcd(path)
        else:
            points = read_kitti(path, 3 if kind == "kitti3" else 4)
            if not args.no_kitti_correction:
                points = np.asarray(kiss_icp_pybind._correct_kitti_scan(kiss_icp_pybind._Vector3dVector(points)))
            times = None
            if args.kitti_deskew == "azimuth":  # KISS-ICP's kitti_raw.py get_timestamps
                times = 0.5 * (-np.arctan2(points[:, 1], points[:, 0]) / np.pi + 1.0)
        read_s += time.perf_counter() - start
        return points, times

    first_points, first_times = load(scans[0][1])
    has_times = first_times is not None
    deskew = {"on": True, "off": False, "auto": has_times}[args.deskew]
    config = kiss_config(args.threads, deskew, args.max_range, args.voxel_size)
    odometry = KissICP(config=config)

    poses_end, poses_mid, stamps, per_scan = [], [], [], []
    registration_s = 0.0
    for index, (name, path, _) in enumerate(scans):
        points, times = (first_points, first_times) if index == 0 else load(path)
        stamp_times = times if times is not None else np.array([])
        if times is not None and times.size and float(times.max() - times.min()) <= 0.0:
            stamp_times = np.array([])  # one instant: nothing to deskew (and no range to normalise)
        delta_used = odometry.last_delta.copy()
        start = time.perf_counter()
        odometry.register_frame(points, stamp_times if deskew else np.array([]))
        elapsed = time.perf_counter() - start
        registration_s += elapsed
        pose = odometry.last_pose.copy()
        poses_end.append(pose)
        if deskew and stamp_times.size:
            rho, omega = se3_log(delta_used)
            poses_mid.append(pose @ se3_exp(-0.5 * rho, -0.5 * omega))
        else:
            poses_mid.append(pose)
        if kind == "pcd" and times is not None and times.size:  # the PCD's own (absolute) seconds
            stamps.append(0.5 * float(times.min() + times.max()))
            end_stamp = float(times.max())
        else:
            stamps.append(float(index))
            end_stamp = float(index)
        per_scan.append({"name": name, "points": int(len(points)), "registration_s": elapsed, "end_stamp_s": end_stamp})
        if not args.quiet:
            print(f"\r{index + 1}/{len(scans)} {name}: {elapsed * 1000:.0f} ms", end="", file=sys.stderr, flush=True)
    if not args.quiet:
        print(file=sys.stderr)

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_tum(out / "poses.tum", np.array(poses_mid), np.array(stamps))
    write_tum(out / "poses_end_of_sweep.tum", np.array(poses_end), np.array([s["end_stamp_s"] for s in per_scan]))
    summary = {
        "method": "KISS-ICP",
        "kiss_icp_version": kiss_icp.__version__,
        "python": sys.executable,
        "scans_folder": str(pathlib.Path(args.scans).resolve()),
        "scan_layout": kind,
        "scans": len(scans),
        "threads": args.threads,
        "per_point_times": has_times,
        "deskew": deskew,
        "kitti_correction": kitti and not args.no_kitti_correction,
        "kitti_deskew": args.kitti_deskew if kitti else None,
        "poses_tum_stamp": ("mid-sweep, (t_min + t_max) / 2 of each scan's point times" if has_times and kind == "pcd"
                            else "scan index"),
        "config": config.model_dump(),
        "wall_registration_s": registration_s,
        "wall_read_s": read_s,
        "wall_process_s": time.perf_counter() - PROCESS_START,
        "cpu_process_s": time.process_time() - PROCESS_CPU_START,
        "per_scan": per_scan,
    }
    (out / "kiss_icp.json").write_text(json.dumps(summary, indent=2) + "\n")
    if not args.quiet:
        print(f"kiss_icp_peer: {len(scans)} scans, registration {registration_s:.2f} s, "
              f"process {summary['wall_process_s']:.2f} s; wrote {out}/poses.tum", file=sys.stderr)
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scans", nargs="?", help="folder of scans")
    parser.add_argument("--out", help="output folder")
    parser.add_argument("--threads", type=int, default=2, help="KISS-ICP's max_num_threads (TBB) and BLAS threads")
    parser.add_argument("--deskew", choices=["auto", "on", "off"], default="auto",
                        help="auto: on when the scans carry per-point times")
    parser.add_argument("--kitti-deskew", choices=["none", "azimuth"], default="none",
                        help="KITTI scans: none (KISS-ICP's odometry loader) or azimuth times (its raw loader)")
    parser.add_argument("--no-kitti-correction", action="store_true", help="KITTI scans: skip _correct_kitti_scan")
    parser.add_argument("--max-range", type=float, help="data.max_range (m); voxel_size follows as max_range / 100")
    parser.add_argument("--voxel-size", type=float,
                        help="mapping.voxel_size (m) instead of max_range / 100: KISS-ICP's map and registration "
                             "sampling (its frames are voxelised at 0.5x and 1.5x this), for its speed against accuracy")
    parser.add_argument("--scans-limit", type=int, default=0, help="only the first N scans")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--setup", action="store_true", help="only make the venv, then exit")
    args = parser.parse_args()
    if args.threads < 1:
        parser.error("--threads must be >= 1")

    if not in_kiss_python():
        python = ensure_venv(args.quiet)
        if python is None:
            print("kiss_icp_peer: no python with kiss-icp (bench/.venv-kiss could not be made)", file=sys.stderr)
            return EXIT_NO_VENV
        if args.setup:
            print(python)
            return 0
        env = dict(os.environ)
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = str(args.threads)
        os.execve(str(python), [str(python), str(pathlib.Path(__file__).resolve()), *sys.argv[1:]], env)
    if args.setup:
        print(sys.executable)
        return 0
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)  # numpy is first imported in run()
    if not args.scans or not args.out:
        parser.error("SCANS and --out are needed")
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
