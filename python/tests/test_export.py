"""`minemap export` through the package: LAS/LAZ, COPC and E57 from the C++ core's stream of scans,
every point with its attributes and scan, whole or not at all."""
import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

import minemap
from conftest import run_cli

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"


@pytest.fixture(scope="module")
def mine_map(tmp_path_factory):
    """The shared mine's two PCD segments mapped (their intensities carried), and exported to PLY by
    the C++ program: the reference the package's formats are held against."""
    out = tmp_path_factory.mktemp("mine") / "out"
    run_cli("map", SHARED / "mine_jinchuan_pcr", "--out", out, "--quiet", "--threads", 2)
    run_cli("export", out, "--to", out.parent / "mine.ply", "--quiet")
    return out


def _ply_columns(path: Path) -> dict:
    data = path.read_bytes()
    header, body = data.split(b"end_header\n", 1)
    names, types = [], {"float": "<f4", "double": "<f8", "uint": "<u4", "uchar": "u1", "ushort": "<u2"}
    for line in header.decode().splitlines():
        if line.startswith("property"):
            _, kind, name = line.split()
            names.append((name, types[kind]))
    return np.frombuffer(body, dtype=np.dtype(names))


def test_laz_keeps_every_point_its_intensity_and_its_scan(mine_map, tmp_path):
    ply = _ply_columns(mine_map.parent / "mine.ply")
    result = subprocess.run([sys.executable, "-m", "minemap", "export", str(mine_map), "--to", str(tmp_path / "mine.laz")],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "wrote" in result.stdout and "intensity" in result.stdout
    laz = laspy.read(tmp_path / "mine.laz")
    assert laz.header.point_count == len(ply)
    # The exact intensities (a float32 extra dimension) as a multiset; LAS's own uint16 is rounded.
    assert np.array_equal(np.sort(np.asarray(laz.intensity_value)), np.sort(ply["intensity"]))
    assert np.array_equal(np.asarray(laz.intensity), np.clip(np.round(laz.intensity_value), 0, 65535).astype(np.uint16))
    assert set(np.unique(laz.scan_index)) == {0, 1} and np.array_equal(laz.point_source_id, laz.scan_index)
    # The same points as the PLY, to the LAS scale (1 mm).
    assert np.abs(np.asarray(laz.x) - ply["x"]).max() < 6e-4
    # A .las is the same, uncompressed, through the API.
    summary = minemap.export(mine_map, tmp_path / "mine.las")
    assert summary["completed"] and summary["points"] == len(ply)
    assert laspy.read(tmp_path / "mine.las").header.point_count == len(ply)


def test_copc_is_an_octree_its_reader_queries(mine_map, tmp_path):
    import copclib as copc  # a dependency of the package: missing is a failure, not a skip
    summary = minemap.export(mine_map, tmp_path / "mine.copc.laz")
    ply = _ply_columns(mine_map.parent / "mine.ply")
    assert summary["completed"] and summary["points"] == len(ply)
    reader = copc.FileReader(str(tmp_path / "mine.copc.laz"))
    assert reader.ValidateSpatialBounds()  # every point inside its node
    assert len(reader.GetAllNodes()) > 1 and reader.GetMaxDepth() >= 1
    with laspy.CopcReader.open(tmp_path / "mine.copc.laz") as copc_file:
        everything = copc_file.query()
        assert len(everything) == len(ply)
        assert np.array_equal(np.sort(np.asarray(everything["intensity_value"])), np.sort(ply["intensity"]))
        lo, hi = np.array([0.0, 0.0, -100.0]), np.array([20.0, 20.0, 100.0])
        part = copc_file.query(bounds=laspy.Bounds(mins=lo, maxs=hi))
    inside = (ply["x"] >= lo[0]) & (ply["x"] <= hi[0]) & (ply["y"] >= lo[1]) & (ply["y"] <= hi[1])
    assert 0 < len(part) < len(ply)
    assert abs(len(part) - int(inside.sum())) <= int(0.001 * len(ply)) + 5  # points on the box's faces aside
    # The same survey gives the same file.
    minemap.export(mine_map, tmp_path / "again.copc.laz")
    assert (tmp_path / "again.copc.laz").read_bytes() == (tmp_path / "mine.copc.laz").read_bytes()


def test_e57_holds_one_scan_each_in_world_coordinates(mine_map, tmp_path):
    import pye57

    summary = minemap.export(mine_map, tmp_path / "mine.e57")
    assert summary["completed"]
    e57 = pye57.E57(str(tmp_path / "mine.e57"))
    assert e57.scan_count == 2
    ply = _ply_columns(mine_map.parent / "mine.ply")
    first = e57.read_scan_raw(0)
    n0 = int((ply["scan"] == 0).sum())
    assert len(first["cartesianX"]) == n0
    assert np.abs(first["cartesianX"] - ply["x"][:n0]).max() < 1e-3
    assert np.array_equal(np.sort(first["intensity"]), np.sort(ply["intensity"][:n0]))


def test_a_stop_leaves_nothing_and_the_old_file_as_it_was(mine_map, tmp_path):
    for name in ("stopped.laz", "stopped.copc.laz", "stopped.e57"):
        target = tmp_path / name
        target.write_bytes(b"the old file")
        stream = minemap._core.SurveyExport(str(mine_map))
        asked = []
        summary = minemap.exports.write(stream, target, lambda: asked.append(1) or len(asked) > 1)
        assert not summary["completed"], name
        assert target.read_bytes() == b"the old file", name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stopped.copc.laz", "stopped.e57", "stopped.laz"]


def test_a_uos_survey_exports_in_metres_z_up(small_survey, tmp_path):
    out = tmp_path / "out"
    run_cli("map", small_survey, "--out", out, "--quiet")
    minemap.export(out, tmp_path / "sim.laz")
    laz = laspy.read(tmp_path / "sim.laz")
    report = json.loads((out / "report.json").read_text())
    assert laz.header.point_count == sum(s["points_in"] for s in report["scans"])
    # The drive runs forward (x), the roof a few metres up (z): 3DTK's y-up cm, turned.
    extent = np.array([np.ptp(laz.x), np.ptp(laz.y), np.ptp(laz.z)])
    assert extent[0] > 15 and extent[2] < 10, extent


def test_copc_node_keys_hold_every_depth():
    # A node's key holds its depth above its cell (depth << 48); at COPC_MAX_DEPTH, with the last
    # cell of each axis, it must stay a positive int64 and give the same node back.
    from minemap import exports

    for depth in range(exports.COPC_MAX_DEPTH + 1):
        cells = np.array([[0, 0, 0], [(1 << depth) - 1] * 3], np.int64)
        keys = (np.int64(depth) << np.int64(48)) | exports._pack(cells)
        assert (keys >= 0).all()
        assert np.array_equal(exports._unpack(keys & ((1 << 48) - 1)), cells)
        assert all(int(k) >> 48 == depth for k in keys)


def test_a_map_of_arrays_has_nothing_to_export(tmp_path):
    rng = np.random.default_rng(5)
    cloud = rng.uniform(-5, 5, (3000, 3))
    minemap.map_survey([cloud, cloud + [0.02, 0, 0]], out=tmp_path / "out")
    with pytest.raises(minemap.InputError, match="arrays"):
        minemap.export(tmp_path / "out", tmp_path / "x.ply")
    assert not (tmp_path / "x.ply").exists()


def _write_ply_xyz(path: Path, xyz: np.ndarray, double: bool):
    kind = "double" if double else "float"
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(xyz)}\n"
              f"property {kind} x\nproperty {kind} y\nproperty {kind} z\nend_header\n")
    path.write_bytes(header.encode() + np.ascontiguousarray(xyz, dtype="<f8" if double else "<f4").tobytes())


def test_a_utm_copy_maps_as_the_original_and_its_laz_lands_on_its_world_coordinates(tmp_path):
    """A PLY survey and its copy moved by a UTM-size offset (whole hundreds of metres): the copy maps
    to the original's local poses (well under 1 mm), and its LAZ export holds each point where the
    registered pose puts its world coordinates, to the millimetre."""
    base = tmp_path / "base"
    run_cli("map", SHARED / "fast_gicp_pair", "--out", base, "--quiet", "--threads", 2)
    names = [s["name"] for s in json.loads((base / "report.json").read_text())["scans"]]
    offset = np.array([500000.0, 6000000.0, 100.0])
    for folder in ("local", "world"):
        (tmp_path / folder).mkdir()
    for name in names:
        run_cli("export", base, "--to", tmp_path / "one.ply", "--scans", name, "--quiet")
        cols = _ply_columns(tmp_path / "one.ply")
        xyz = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float32).astype(np.float64)
        _write_ply_xyz(tmp_path / "local" / f"{name}.ply", xyz, double=False)
        _write_ply_xyz(tmp_path / "world" / f"{name}.ply", xyz + offset, double=True)
    for folder in ("local", "world"):
        run_cli("map", tmp_path / folder, "--out", tmp_path / f"{folder}-out", "--quiet", "--threads", 2,
                "--accept-doubtful")
    local = json.loads((tmp_path / "local-out" / "report.json").read_text())
    world = json.loads((tmp_path / "world-out" / "report.json").read_text())
    np.testing.assert_array_equal(world["origin"], offset)
    for a, b in zip(local["scans"], world["scans"]):
        pa, pb = np.array(a["pose"]), np.array(b["pose"])
        assert np.linalg.norm(pa[:3, 3] - pb[:3, 3]) < 1e-3, (a["name"], pa, pb)  # metres: under 1 mm
        assert np.abs(pa[:3, :3] - pb[:3, :3]).max() < 1e-5
    laz = tmp_path / "world.laz"
    done = subprocess.run([sys.executable, "-m", "minemap", "export", str(tmp_path / "world-out"), "--to", str(laz),
                           "--quiet"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    las = laspy.read(laz)
    got = np.stack([las.x, las.y, las.z], axis=1)
    start = 0
    for s, name in zip(world["scans"], names):
        cols = _ply_columns(tmp_path / "world" / f"{name}.ply")
        xyz = np.stack([cols["x"], cols["y"], cols["z"]], axis=1)
        pose = np.array(s["pose"])
        want = (xyz - offset) @ pose[:3, :3].T + pose[:3, 3] + offset
        np.testing.assert_allclose(got[start:start + len(xyz)], want, rtol=0, atol=1e-3)
        start += len(xyz)
    assert start == len(got)
