"""The Python package against the C++ command line: the same results bit for bit, numpy in and
out, clear errors, the GIL released, Ctrl-C honoured, no copy of large inputs."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import laspy
import numpy as np
import pye57
import pytest

import minemap
from conftest import default_sigint, run_cli

# The only report fields that differ between two runs of one survey: wall clocks, and how each run
# was asked for (its command line, and the options that change no pose: threads, backend, quiet).
TIMING_KEYS = ("timings_s", "memory_mb", "command_line", "run_options")


def report_without_timings(path: Path) -> dict:
    report = json.loads(path.read_text())
    for key in TIMING_KEYS:
        report.pop(key)
    return report


def assert_same_outputs(expected: Path, actual: Path):
    """Every file `minemap map` wrote is in `actual`, byte for byte (report.json: but its timings)."""
    names = sorted(p.name for p in expected.iterdir())
    assert names, expected
    for name in names:
        if name == "minemap.log":  # the run's console output: times and paths differ
            continue
        if name == "report.json":
            assert report_without_timings(expected / name) == report_without_timings(actual / name)
        else:
            assert (expected / name).read_bytes() == (actual / name).read_bytes(), name


def report_poses(report: dict) -> np.ndarray:
    return np.array([s["pose"] for s in report["scans"]], dtype=np.float64)


def test_map_survey_and_python_cli_equal_the_program(small_survey, tmp_path):
    run_cli("map", small_survey, "--out", tmp_path / "cli", "--threads", 2, "--quiet")
    result = minemap.map_survey(small_survey, out=tmp_path / "api", threads=2)
    module = subprocess.run([sys.executable, "-m", "minemap", "map", str(small_survey), "--out",
                             str(tmp_path / "module"), "--threads", "2", "--quiet"], capture_output=True, text=True)
    assert module.returncode == 0, module.stderr
    assert_same_outputs(tmp_path / "cli", tmp_path / "api")
    assert_same_outputs(tmp_path / "cli", tmp_path / "module")
    # The poses returned are report.json's, bit for bit (JSON doubles round-trip exactly).
    report = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert np.array_equal(result.poses, report_poses(report))
    assert result.names == [f"scan{i:03d}" for i in range(6)]
    assert result.ok and result.unit == "cm" and result.format == "uos"
    assert result.report["truth"]["registered"]["mean_translation"] < result.report["truth"]["odometry"][
        "mean_translation"]
    # The package's command line says it wrote map.laz too (it writes it beside the C++ outputs).
    loud = subprocess.run([sys.executable, "-m", "minemap", "map", str(small_survey), "--out",
                           str(tmp_path / "loud"), "--threads", "2"], capture_output=True, text=True)
    assert loud.returncode == 0, loud.stderr
    wrote = [line for line in loud.stdout.splitlines() if line.startswith("wrote ")]
    assert wrote and "map.laz" in wrote[0], loud.stdout
    assert (tmp_path / "loud" / "map.laz").exists()
    # Without `out` nothing is written, and the poses are the same.
    again = minemap.map_survey(small_survey, threads=1)
    assert np.array_equal(again.poses, result.poses)


def test_settings_are_the_command_lines(small_survey, tmp_path):
    options = minemap.options()
    assert options["max_pair_dist_cm"]["default"] == "25"
    assert options["no_filter"]["flag"] and not options["voxel_cm"]["flag"]
    assert minemap.options("paper")["reduction"]["default"] == "slices"
    run_cli("map", small_survey, "--out", tmp_path / "cli", "--mode", "pairwise", "--voxel-cm", "20", "--no-retry",
            "--quiet")
    result = minemap.map_survey(small_survey, mode="pairwise", voxel_cm=20, no_retry=True)
    assert np.array_equal(result.poses, report_poses(json.loads((tmp_path / "cli" / "report.json").read_text())))
    with pytest.raises(TypeError, match="unexpected keyword argument 'voxel_size'"):
        minemap.map_survey(small_survey, voxel_size=20)
    with pytest.raises(ValueError, match="mode"):
        minemap.map_survey(small_survey, mode="sideways")
    with pytest.raises(ValueError, match="True or False"):
        minemap.map_survey(small_survey, no_filter="yes")


def test_arrays_in_poses_out(small_survey):
    survey = minemap.read_survey(small_survey)
    assert survey.format == "uos" and len(survey) == 6 and survey.poses.shape == (6, 4, 4)
    assert all(p.shape[1] == 3 and p.dtype == np.float64 for p in survey.points)
    assert all(s is not None for s in survey.slice_offsets)
    by_path = minemap.map_survey(small_survey, mode="pairwise")
    by_arrays = minemap.map_survey(survey.points, poses=survey.poses, names=survey.names, unit="cm", mode="pairwise")
    # The same points and starting poses: the same registration.
    assert np.allclose(by_arrays.poses, by_path.poses, atol=1e-3)
    assert by_arrays.names == survey.names


def _rotation_z(angle_rad):
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _room(rng, n):
    """Points on the walls, floor and ceiling of a 10 m room, metres."""
    p = rng.uniform(-5, 5, (n, 3))
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = rng.choice([-5.0, 5.0], n)
    return p


def test_register_recovers_a_known_motion():
    rng = np.random.default_rng(1)
    target = _room(rng, 20000)
    truth = np.eye(4)
    truth[:3, :3] = _rotation_z(0.05)
    truth[:3, 3] = [0.10, -0.05, 0.02]
    source = (target - truth[:3, 3]) @ truth[:3, :3]  # source = truth^-1 * target
    # Every point (no reduction: arrays have no slices to filter): the motion exactly.
    result = minemap.register(source, target, max_pair_dist_cm=50, reduction="slices")
    assert result.converged and result.stop_reason == "converged" and result.trusted
    assert np.allclose(result.pose, truth, atol=1e-5)
    assert result.pairs == len(source) and result.rms < 1e-4
    # The default reduces both to voxel means, as `minemap map`: within a millimetre.
    reduced = minemap.register(source, target, max_pair_dist_cm=50)
    assert reduced.converged and reduced.trusted and reduced.pairs < len(source)
    assert np.allclose(reduced.pose[:3, 3], truth[:3, 3], atol=2e-3), reduced.pose
    # float32 in, a strided view in, cm: the same motion.
    wide = np.zeros((len(source), 5), np.float32)
    wide[:, 1:4] = source * 100
    view = wide[:, 1:4]
    assert not view.flags.c_contiguous
    in_cm = minemap.register(view, (target * 100).astype(np.float32), unit="cm", max_pair_dist_cm=50,
                             reduction="slices")
    assert np.allclose(in_cm.pose[:3, :3], truth[:3, :3], atol=1e-4)
    assert np.allclose(in_cm.pose[:3, 3], truth[:3, 3] * 100, atol=0.05)
    # Too far apart for the bound: no pairs, the pose is init, said so.
    far = minemap.register(source + 100.0, target)
    assert not far.converged and far.stop_reason.startswith("too few pairs") and np.array_equal(far.pose, np.eye(4))


def test_register_judges_and_retries_as_map_does():
    # The fast_gicp pair from the identity: 0.49 m and 0.6 deg from its reference, twice the 25 cm
    # bound's reach. Before (ICP on the raw points, nothing judged) register returned converged=True
    # at the identity's minimum, 0.5 m off. Now, as `minemap map`: reduced, the match at 25 cm moves
    # the points twice the bound, so it is doubtful ("out of reach") on its own, and the retry from
    # 1 m, coarse to fine, is trusted and lands on the reference.
    shared = Path(os.environ.get("MINEMAP_SHARED_DATA") or Path(__file__).resolve().parents[3] / "shared" / "data")
    if not (shared / "fast_gicp_pair").is_dir():
        shared = Path("/work/shared/data")
    survey = minemap.read_survey(shared / "fast_gicp_pair")
    target, source = survey.points[survey.names.index("251370668")], survey.points[survey.names.index("251371071")]
    reference = np.loadtxt(shared / "fast_gicp_pair" / "relative.txt")
    narrow = minemap.register(source, target, no_retry=True)
    assert narrow.converged and not narrow.trusted and "out of reach" in narrow.doubt, narrow.doubt
    result = minemap.register(source, target)
    assert result.converged and result.trusted and result.doubt == "", result.doubt
    assert result.retry_bound == pytest.approx(1.0)  # metres, the unit given
    assert np.linalg.norm(result.pose[:3, 3] - reference[:3, 3]) < 0.03
    assert result.health["paired_fraction"] > 0.5 and result.health["pair_bound"] == pytest.approx(0.25)
    # A known motion in a synthetic room: trusted at once.
    rng = np.random.default_rng(3)
    room = _room(rng, 5000)
    moved = minemap.register(room + [0.05, 0.0, 0.0], room)
    assert moved.trusted and moved.retry_bound == 0.0 and np.allclose(moved.pose[:3, 3], [-0.05, 0, 0], atol=2e-3)


@pytest.mark.parametrize("bad, message", [
    (np.zeros((10, 2)), r"shape \(N, 3\), got shape \(10, 2\)"),
    (np.zeros((10, 3, 1)), r"shape \(N, 3\), got shape \(10, 3, 1\)"),
    (np.zeros(30), r"shape \(N, 3\), got shape \(30,\)"),
    (np.zeros((10, 3), np.int64), "float32 or float64 points, got dtype int64"),
    (np.zeros((0, 3)), "0 points; a scan needs at least 3"),
    ([[0.0, 0.0, 0.0]] * 10, "expected a numpy array"),
])
def test_bad_arrays_are_value_errors(bad, message):
    good = np.random.default_rng(0).normal(size=(100, 3))
    with pytest.raises(ValueError, match=message):
        minemap.register(bad, good)
    with pytest.raises(ValueError, match="^target: .*" + message):
        minemap.register(good, bad)


def test_nan_and_inf_name_the_point():
    points = np.random.default_rng(0).normal(size=(100, 3))
    points[17, 2] = np.nan
    with pytest.raises(ValueError, match="source: point 17 is not finite"):
        minemap.register(points, points)
    points[17, 2] = np.inf
    with pytest.raises(ValueError, match="scans\\[1\\]: point 17 is not finite"):
        minemap.map_survey([np.ones_like(points), points])
    with pytest.raises(ValueError, match="init: expected a 4x4"):
        minemap.register(np.ones((16, 3)), np.ones((16, 3)), init=np.eye(3))


def test_bad_input_names_file_and_line(fresh_copy):
    survey = fresh_copy()
    lines = (survey / "scan002.3d").read_text().splitlines()
    lines[40] = "12.5 abc 3.0"
    (survey / "scan002.3d").write_text("\n".join(lines) + "\n")
    with pytest.raises(minemap.InputError, match=r"scan002\.3d:41: ") as error:
        minemap.map_survey(survey)
    assert isinstance(error.value, ValueError)
    expected = run_cli("map", survey, "--out", survey.parent / "out", check=False)
    assert expected.returncode == 3 and str(error.value) in expected.stderr
    empty = survey.parent / "empty"
    empty.mkdir()
    with pytest.raises(minemap.InputError, match="no scans found"):
        minemap.read_survey(empty)


def test_opencl_backend_gives_the_cpu_poses(small_survey):
    """PoCL in CI: the OpenCL backend must be there (a failure, never a skip) and agree bit for bit."""
    cpu = minemap.map_survey(small_survey, backend="cpu")
    opencl = minemap.map_survey(small_survey, backend="opencl")
    assert opencl.report["backend"].startswith("opencl"), opencl.report["backend"]
    assert np.array_equal(cpu.poses, opencl.poses)


def test_the_gil_is_released_while_mapping(small_survey):
    ticks = 0
    done = threading.Event()

    def count():
        nonlocal ticks
        while not done.is_set():
            ticks += 1

    counter = threading.Thread(target=count)
    counter.start()
    try:
        start = time.perf_counter()
        minemap.map_survey(small_survey, threads=1, mode="simultaneous")
        elapsed = time.perf_counter() - start
    finally:
        done.set()
        counter.join()
    # A held GIL would leave the counter at a switch interval's worth per call; released, it counts
    # all along (hundreds of thousands per second).
    assert elapsed > 0.2 and ticks > 20000 * elapsed, (ticks, elapsed)


def test_no_copy_of_a_large_input_array():
    rng = np.random.default_rng(2)
    big = np.empty((1_000_000, 4))
    big[:, :3] = _room(rng, 1_000_000)
    view = big[:, :3]  # strided: a copy would be 24 MB of numpy memory
    target = _room(rng, 2000)
    tracemalloc.start()
    try:
        minemap.register(view, target, max_iterations=2)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000, peak


def test_ctrl_c_stops_between_scans_and_keeps_what_was_matched(tmp_path, python_sigint):
    survey = minemap.simulate(tmp_path / "survey", scans=40, seed=5)
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    start = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        minemap.map_survey(survey, out=tmp_path / "out", mode="simultaneous", threads=2)
    timer.cancel()
    assert time.perf_counter() - start < 20
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["partial"] and 0 < len(report["scans"]) < 40
    assert not list((tmp_path / "out").glob("*.tmp*"))


def test_python_command_line_interrupt_exits_130(tmp_path):
    survey = minemap.simulate(tmp_path / "survey", scans=40, seed=5)
    process = subprocess.Popen([sys.executable, "-m", "minemap", "map", str(survey), "--out", str(tmp_path / "out"),
                                "--mode", "simultaneous"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               text=True, preexec_fn=default_sigint)
    # Interrupt once it is matching (its progress lines say so), not while Python still starts up.
    for line in process.stderr:
        if "progress: simultaneous 3/" in line:
            break
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert json.loads((tmp_path / "out" / "report.json").read_text())["partial"]


# ---- LAS/LAZ and E57 surveys through the command line ------------------------------------------------

UTM = np.array([512345.0, 5712345.0, 300.0])


def _georeferenced_scans(survey_dir: Path):
    """The simulated scans in world coordinates at their odometry poses, right-handed z up, metres."""
    survey = minemap.read_survey(survey_dir)
    scans = []
    for points, pose in zip(survey.points, survey.poses):
        world = points @ pose[:3, :3].T + pose[:3, 3]                     # 3DTK frame, cm
        scans.append(np.stack([world[:, 2], -world[:, 0], world[:, 1]], axis=1) / 100.0)
    return survey, scans


def test_laz_survey_maps_through_the_command_line(small_survey, tmp_path):
    survey, scans = _georeferenced_scans(small_survey)
    folder = tmp_path / "laz"
    folder.mkdir()
    for i, points in enumerate(scans):
        header = laspy.LasHeader(point_format=6, version="1.4")
        header.scales = [0.001] * 3
        header.offsets = UTM
        las = laspy.LasData(header)
        las.x, las.y, las.z = (points + UTM).T
        las.write(folder / f"scan{i}.laz")
    result = subprocess.run([sys.executable, "-m", "minemap", "map", str(folder), "--out", str(tmp_path / "out"),
                             "--threads", "2"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    origin = np.array(report["origin"])
    assert report["unit"] == "m" and np.all(np.abs(origin - UTM) < 1000)
    # The map comes back georeferenced, to the millimetre of LAS' scale.
    laz = laspy.read(tmp_path / "out" / "map.laz")
    assert np.all(np.abs(np.array([laz.x.min(), laz.y.min()]) - UTM[:2]) < 200)
    # Registered poses: each scan was already in place but for its odometry error, which the
    # registration removes: the poses (local frame) move each scan by what truth says.
    registered = report_poses(report)
    assert registered.shape == (6, 4, 4) and np.all(np.abs(registered[:, :3, 3]) < 1.0)
    bad = folder / "scan9.laz"
    bad.write_bytes((folder / "scan0.laz").read_bytes()[:5000])
    broken = subprocess.run([sys.executable, "-m", "minemap", "map", str(folder), "--out", str(tmp_path / "out2")],
                            capture_output=True, text=True)
    assert broken.returncode == 3 and "scan9.laz" in broken.stderr and not (tmp_path / "out2").exists()
    # The C++ program alone says how to read such a survey.
    plain = run_cli("map", folder, "--out", tmp_path / "out3", check=False)
    assert plain.returncode == 3 and "Python package" in plain.stderr


def test_e57_survey_gets_its_registered_poses_back(small_survey, tmp_path):
    survey = minemap.read_survey(small_survey)
    path = tmp_path / "survey.e57"
    e57 = pye57.E57(str(path), mode="w")
    for i, (points, pose) in enumerate(zip(survey.points, survey.poses)):
        metres = points / 100.0
        # Each scan in its own frame, placed by its odometry pose (3DTK axes are fine for E57 here:
        # the rotation is proper, the frame only has to be consistent).
        rotation = pose[:3, :3]
        w = np.sqrt(max(1e-12, 1 + np.trace(rotation))) / 2
        quaternion = np.array([w, (rotation[2, 1] - rotation[1, 2]) / (4 * w), (rotation[0, 2] - rotation[2, 0]) / (4 * w),
                               (rotation[1, 0] - rotation[0, 1]) / (4 * w)])
        e57.write_scan_raw({"cartesianX": metres[:, 0], "cartesianY": metres[:, 1], "cartesianZ": metres[:, 2]},
                           name=f"station{i}", rotation=quaternion, translation=pose[:3, 3] / 100.0)
    e57.close()
    result = minemap.map_survey(path, out=tmp_path / "out", threads=2)
    assert result.format == "e57" and result.unit == "m" and result.names == [f"station{i}" for i in range(6)]
    truth = survey.truth
    errors_before = np.linalg.norm((result.initial_poses[:, :3, 3] - result.initial_poses[0, :3, 3])
                                   - (truth[:, :3, 3] - truth[0, :3, 3]) / 100.0, axis=1).mean()
    errors_after = np.linalg.norm((result.poses[:, :3, 3] - result.poses[0, :3, 3])
                                  - (truth[:, :3, 3] - truth[0, :3, 3]) / 100.0, axis=1).mean()
    assert errors_after < errors_before
    written = pye57.E57(str(tmp_path / "out" / "survey.e57"))
    assert written.scan_count == 6
    for i in range(6):
        header = written.get_header(i)
        assert np.allclose(header.translation, result.poses[i][:3, 3] + np.array(result.origin), atol=1e-6)


def _write_ply(path: Path, points: np.ndarray) -> None:
    """A binary little-endian PLY of float32 x y z."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n").encode()
    path.write_bytes(header + np.ascontiguousarray(points, dtype="<f4").tobytes())


def test_map_laz_is_z_up_whichever_frame_the_survey_was_mapped_in(small_survey, tmp_path):
    # A right-handed, z-up PLY survey (metres), mapped as it is and converted to 3DTK's frame
    # (--right-handed-to-3dtk): map.laz is right-handed and z up both times, in the same place. The
    # frame is the reader's to say (io::Survey::frame_3dtk); map.laz once took it from the format
    # alone and came out in 3DTK's frame (y up) after the conversion.
    _, scans = _georeferenced_scans(small_survey)
    folder = tmp_path / "ply"
    folder.mkdir()
    for i, points in enumerate(scans):
        _write_ply(folder / f"scan{i}.ply", points)
    boxes = []
    for name, extra in (("plain", {}), ("converted", {"right_handed_to_3dtk": True})):
        minemap.map_survey(folder, out=tmp_path / name, threads=2, **extra)
        laz = laspy.read(tmp_path / name / "map.laz")
        xyz = np.stack([laz.x, laz.y, laz.z], axis=1)
        boxes.append((xyz.min(axis=0), xyz.max(axis=0), xyz.mean(axis=0)))
    every = np.concatenate(scans)
    for low, high, mean in boxes:
        # The survey's own axes: the drive runs along x, the roof is a few metres up z.
        assert np.all(np.abs(low - every.min(axis=0)) < 0.5) and np.all(np.abs(high - every.max(axis=0)) < 0.5)
    assert np.all(np.abs(boxes[0][2] - boxes[1][2]) < 0.05)


def test_a_map_tied_to_control_is_in_the_grid(tmp_path):
    # Survey control (issue 29): the simulator's stations in a UTM-size grid; map.laz, the poses'
    # origin and a LAZ export all come back in grid coordinates, where the simulator put the truth.
    survey = minemap.simulate(tmp_path / "survey", scans=16, control=3)
    result = minemap.map_survey(survey, out=tmp_path / "out", control=survey / "control.txt", threads=2)
    report = result.report
    assert report["control"]["points_used"] == 3
    assert report["control"]["checked_for_blunders"] is False  # 3 points: a blunder could not be found
    origin = np.asarray(report["control"]["origin_grid_m"])
    truth = np.loadtxt(survey / "control_truth.tum")[:, 1:4]
    trajectory = np.loadtxt(tmp_path / "out" / "trajectory.tum")[:, 1:4] + origin
    assert np.max(np.linalg.norm(trajectory - truth, axis=1)) < 0.10
    laz = laspy.read(tmp_path / "out" / "map.laz")
    xyz = np.stack([laz.x, laz.y, laz.z], axis=1)
    assert np.all(np.abs(xyz.mean(axis=0)[:2] - truth.mean(axis=0)[:2]) < 30.0)  # the drive's scans, metres
    summary = minemap.export(tmp_path / "out", tmp_path / "grid.laz")
    assert summary["completed"] and not summary["warnings"]
    exported = laspy.read(tmp_path / "grid.laz")
    assert abs(float(np.mean(exported.y)) - truth[:, 1].mean()) < 30.0

    # The grid's CRS (EPSG:32633, WGS 84 / UTM zone 33N) in every file that can hold it.
    def wkt_of(las):  # a VLR, or an extended one (copclib writes it there)
        records = [v for v in list(las.header.vlrs) + list(las.evlrs or [])
                   if isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr)]
        return records[0].string if records else ""

    for las in (exported, laspy.read(tmp_path / "out" / "map.laz")):
        assert 'UTM zone 33N' in wkt_of(las) and 'AUTHORITY["EPSG","32633"]' in wkt_of(las)
        assert 'PARAMETER["central_meridian",15]' in wkt_of(las)
    assert minemap.export(tmp_path / "out", tmp_path / "grid.copc.laz")["completed"]
    assert 'AUTHORITY["EPSG","32633"]' in wkt_of(laspy.read(tmp_path / "grid.copc.laz"))
    e57 = minemap.export(tmp_path / "out", tmp_path / "grid.e57")
    assert e57["completed"] and any("EPSG:32633 is not written" in w for w in e57["warnings"])


def test_crs_wkt_for_the_utm_grids():
    from minemap import crs
    assert crs.wkt(32633).startswith('PROJCS["WGS 84 / UTM zone 33N"')
    assert 'PARAMETER["false_northing",10000000]' in crs.wkt(32755)
    assert 'PARAMETER["central_meridian",9]' in crs.wkt(25832) and "ETRS89" in crs.wkt(25832)
    assert crs.wkt(2056) is None and crs.wkt(None) is None
    assert "EPSG:2056" in crs.left_out(2056, "x.laz")[0] and crs.left_out(32633, "x.laz") == []
