"""Tests for minemap.formats on real LAS/LAZ/E57 files written at test time with laspy and pye57.

Real scans come from the shared data folder (fast_gicp_pair, see its README.txt); synthetic clouds cover
grids and edge cases. The module is loaded by path so these tests run without the compiled _core.
"""
import importlib.util
import os
import struct
from pathlib import Path

import laspy
import numpy as np
import pye57
import pytest
from pye57 import libe57

_HERE = Path(__file__).resolve()
_spec = importlib.util.spec_from_file_location("minemap_formats", _HERE.parents[1] / "minemap" / "formats.py")
formats = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(formats)

UTM = np.array([500123.456, 5712345.678, 312.5])  # metres, a UTM-sized offset
US_FOOT = 1200.0 / 3937.0


def _shared_data() -> Path:
    env = os.environ.get("MINEMAP_SHARED_DATA")
    candidates = [Path(env)] if env else [_HERE.parents[3] / "shared" / "data", Path("/work/shared/data")]
    for c in candidates:
        if (c / "fast_gicp_pair").is_dir():
            return c
    pytest.fail(f"shared scan data not found (looked in {[str(c) for c in candidates]}); "
                "set MINEMAP_SHARED_DATA to the folder holding fast_gicp_pair/")


def _read_pcd_xyz(path: Path) -> np.ndarray:
    """x, y, z of a PCD 'DATA binary' file whose fields are all float32."""
    blob = path.read_bytes()
    fields, pos = {}, 0
    while True:
        end = blob.index(b"\n", pos)
        line = blob[pos:end].decode("ascii").split()
        pos = end + 1
        if line and not line[0].startswith("#"):
            fields[line[0]] = line[1:]
            if line[0] == "DATA":
                break
    assert fields["DATA"] == ["binary"] and set(fields["TYPE"]) == {"F"} and set(fields["SIZE"]) == {"4"}
    n, width = int(fields["POINTS"][0]), len(fields["FIELDS"])
    xyz = np.frombuffer(blob, "<f4", n * width, pos).reshape(n, width)[:, :3].astype(np.float64)
    return xyz[np.isfinite(xyz).all(axis=1)]


@pytest.fixture(scope="module")
def real_pair():
    """The two fast_gicp scans (20k points each, fixed subsample) and T_target_source."""
    folder = _shared_data() / "fast_gicp_pair"
    rng = np.random.default_rng(7)
    clouds = []
    for name in ("251370668.pcd", "251371071.pcd"):
        xyz = _read_pcd_xyz(folder / name)
        clouds.append(xyz[np.sort(rng.choice(len(xyz), 20000, replace=False))])
    return clouds[0], clouds[1], np.loadtxt(folder / "relative.txt")


def _write_las(path, xyz, *, version="1.2", fmt=0, scale=0.001, offset=UTM, vlrs=()):
    """Write world coordinates with laspy; returns the coordinates as stored (scaled, offset)."""
    header = laspy.LasHeader(point_format=fmt, version=version)
    header.scales, header.offsets = np.full(3, scale), np.asarray(offset, np.float64)
    for v in vlrs:
        header.vlrs.append(v)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(str(path))
    back = laspy.read(str(path))
    return np.column_stack([np.asarray(back.x), np.asarray(back.y), np.asarray(back.z)])


def _rot(axis, deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _pose(rot, trans):
    p = np.eye(4)
    p[:3, :3], p[:3, 3] = rot, trans
    return p


def _grid_from_angles(xyz, rows, cols):
    """Scanner-like row/column indices: elevation ring and azimuth bin of each point."""
    az = np.arctan2(xyz[:, 1], xyz[:, 0])
    el = np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))
    col = np.clip(((az + np.pi) / (2 * np.pi) * cols).astype(int), 0, cols - 1)
    edges = np.quantile(el, np.linspace(0, 1, rows + 1)[1:-1])
    return np.searchsorted(edges, el).astype(np.uint16), col.astype(np.uint16)


def _write_e57(path, entries):
    """entries: dicts with xyz, pose (4x4, metres, world), name, optional row/col/invalid."""
    with pye57.E57(str(path), mode="w") as e57:
        for ent in entries:
            data = {"cartesianX": ent["xyz"][:, 0], "cartesianY": ent["xyz"][:, 1],
                    "cartesianZ": ent["xyz"][:, 2]}
            if "row" in ent:
                data["rowIndex"], data["columnIndex"] = ent["row"], ent["col"]
            if "invalid" in ent:
                data["cartesianInvalidState"] = ent["invalid"].astype(np.int8)
            e57.write_scan_raw(data, name=ent["name"], rotation=formats._matrix_to_quat(ent["pose"][:3, :3]),
                               translation=ent["pose"][:3, 3])


def _stored_e57(path):
    """(xyz float64, row, col, invalid) per data3D entry, as pye57 reads the file."""
    out = []
    with pye57.E57(str(path)) as e57:
        for i in range(e57.scan_count):
            raw = e57.read_scan_raw(i)
            out.append((np.column_stack([raw[f] for f in formats._CART]), raw.get("rowIndex"),
                        raw.get("columnIndex"), raw.get("cartesianInvalidState")))
    return out


def _world(scan, origin):
    p = scan["pose"]
    return scan["points"] @ p[:3, :3].T + p[:3, 3] + origin


def _check_scan_arrays(scan):
    assert scan["points"].dtype == np.float64 and scan["points"].ndim == 2 and scan["points"].shape[1] == 3
    assert scan["pose"].dtype == np.float64 and scan["pose"].shape == (4, 4)
    if scan["slice_offsets"] is not None:
        so = scan["slice_offsets"]
        assert so.dtype == np.uint32 and so[0] == 0 and so[-1] == len(scan["points"]) and np.all(np.diff(so) > 0)


# ------------------------------------------------------------------ LAS / LAZ

@pytest.mark.parametrize("version,fmt,suffix,scale", [
    ("1.2", 0, ".las", 0.01), ("1.2", 3, ".laz", 0.001), ("1.3", 1, ".las", 0.001),
    ("1.4", 6, ".las", 0.001), ("1.4", 7, ".laz", 0.01)])
def test_las_round_trip_keeps_utm_coordinates(tmp_path, real_pair, version, fmt, suffix, scale):
    world = real_pair[0] + UTM
    path = tmp_path / f"scan{suffix}"
    stored = _write_las(path, world, version=version, fmt=fmt, scale=scale)
    survey = formats.read_foreign_survey(path)
    assert survey["format"] == suffix[1:] and survey["unit"] == "m" and survey["warnings"] == []
    origin = survey["origin"]
    assert origin.dtype == np.float64 and origin.shape == (3,) and np.all(origin == np.round(origin))
    (scan,) = survey["scans"]
    _check_scan_arrays(scan)
    assert scan["name"] == "scan" and scan["source"] == str(path) and scan["slice_offsets"] is None
    np.testing.assert_array_equal(scan["pose"], np.eye(4))
    # The local frame is small (float32-safe) and adds back to the stored coordinates to well under 1 mm.
    assert np.abs(scan["points"]).max() < 200
    np.testing.assert_allclose(scan["points"] + origin, stored, rtol=0, atol=1e-6)
    np.testing.assert_allclose(scan["points"] + origin, world, rtol=0, atol=scale / 2 + 1e-6)


def test_las_folder_natural_order_mixed_scales_one_origin(tmp_path, real_pair):
    a, b, _ = real_pair
    shifted = b + UTM + [30.0, -20.0, 1.0]
    stored = {"full1.las": _write_las(tmp_path / "full1.las", a + UTM, scale=0.01, offset=[500000, 5700000, 0]),
              "full10.laz": _write_las(tmp_path / "full10.laz", shifted, version="1.4", fmt=6, scale=0.001,
                                       offset=[499000.5, 5713000.25, 100]),
              "full2.las": _write_las(tmp_path / "full2.las", a[:5000] * 2 + UTM, version="1.3", fmt=1,
                                      scale=0.0005, offset=[500100, 5712000, 300])}
    (tmp_path / "notes.txt").write_text("not a scan")
    assert formats.is_foreign_survey(tmp_path)
    survey = formats.read_foreign_survey(tmp_path)
    assert survey["format"] == "laz"
    assert [s["name"] for s in survey["scans"]] == ["full1", "full2", "full10"]
    np.testing.assert_array_equal(survey["origin"], np.floor(stored["full1.las"].min(axis=0)))
    for scan in survey["scans"]:
        _check_scan_arrays(scan)
        np.testing.assert_allclose(scan["points"] + survey["origin"], stored[Path(scan["source"]).name],
                                   rtol=0, atol=1e-6)


def test_las_unit_override_cm(tmp_path, real_pair):
    stored = _write_las(tmp_path / "s.las", real_pair[0] * 100 + UTM * 100, scale=0.1, offset=UTM * 100)
    survey = formats.read_foreign_survey(tmp_path / "s.las", unit="cm")
    assert survey["unit"] == "cm"
    np.testing.assert_allclose(survey["scans"][0]["points"] + survey["origin"], stored, rtol=0, atol=1e-4)
    with pytest.raises(ValueError):
        formats.read_foreign_survey(tmp_path / "s.las", unit="mm")


def _wkt_vlr(wkt):
    return laspy.vlrs.known.WktCoordinateSystemVlr(wkt)


def _geokeys_vlr(keys):
    record = struct.pack("<4H", 1, 1, 0, len(keys)) + b"".join(struct.pack("<4H", k, 0, 1, v) for k, v in keys)
    return laspy.VLR("LASF_Projection", 34735, "GeoKeyDirectoryTag", record)


_WKT_FTUS = ('PROJCS["NAD83 / New York Long Island (ftUS)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",'
             'SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
             'PROJECTION["Lambert_Conformal_Conic_2SP"],PARAMETER["false_easting",984250],'
             'UNIT["US survey foot",0.304800609601219],AXIS["Easting",EAST],AXIS["Northing",NORTH]]')
_WKT_COMPOUND = ('COMPD_CS["UTM 32N + height",PROJCS["WGS 84 / UTM zone 32N",GEOGCS["WGS 84",'
                 'UNIT["degree",0.0174532925199433]],UNIT["metre",1]],VERT_CS["height",UNIT["foot",0.3048]]]')


@pytest.mark.parametrize("vlr,factor", [
    (_wkt_vlr(_WKT_FTUS), [US_FOOT] * 3),
    (_wkt_vlr(_WKT_COMPOUND), [1.0, 1.0, 0.3048]),
    (_geokeys_vlr([(1024, 1), (3072, 2263), (3076, 9002)]), [0.3048] * 3),
    (_geokeys_vlr([(1024, 1), (3076, 9001), (4099, 9003)]), [1.0, 1.0, US_FOOT])])
def test_las_foot_units_converted_to_metres(tmp_path, real_pair, vlr, factor):
    path = tmp_path / "feet.las"
    stored = _write_las(path, real_pair[0] + UTM, version="1.4", fmt=6, vlrs=[vlr])
    survey = formats.read_foreign_survey(path)
    assert survey["unit"] == "m" and "converted to metres" in survey["warnings"][0]
    np.testing.assert_allclose(survey["scans"][0]["points"] + survey["origin"], stored * factor, rtol=0, atol=1e-6)
    # An explicit unit wins: numbers are taken as they are, with a warning.
    kept = formats.read_foreign_survey(path, unit="m")
    np.testing.assert_allclose(kept["scans"][0]["points"] + kept["origin"], stored, rtol=0, atol=1e-6)
    assert "not converted" in kept["warnings"][0]


@pytest.mark.parametrize("vlr", [_wkt_vlr('GEOGCS["WGS 84",DATUM["WGS_1984"],UNIT["degree",0.0174532925199433]]'),
                                 _geokeys_vlr([(1024, 2), (2048, 4326)])])
def test_las_geographic_crs_refused(tmp_path, vlr):
    path = tmp_path / "lonlat.las"
    _write_las(path, np.array([[7.1, 50.2, 80.0], [7.2, 50.3, 81.0]]), scale=1e-7, offset=[0, 0, 0], vlrs=[vlr])
    with pytest.raises(formats.SurveyFormatError, match=r"^.*lonlat\.las: geographic CRS"):
        formats.read_foreign_survey(path)


@pytest.mark.parametrize("unit,scale", [("m", 0.001), ("cm", 0.1)])
def test_write_laz_round_trip(tmp_path, real_pair, unit, scale):
    a, b, _ = real_pair
    k = 100.0 if unit == "cm" else 1.0
    origin = np.round(UTM) * k
    local = np.vstack([a, b]) * k
    index = np.repeat(np.arange(2, dtype=np.uint32), [len(a), len(b)])
    path = tmp_path / "map.laz"
    formats.write_laz(path, local, unit=unit, origin=origin, scan_index=index)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.laz"]  # temp file moved, none left behind
    las = laspy.read(str(path))
    assert las.header.are_points_compressed and las.header.version == "1.4" and las.header.point_format.id == 6
    np.testing.assert_array_equal(las.header.scales, [scale] * 3)
    np.testing.assert_array_equal(las.header.offsets, origin)
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    np.testing.assert_allclose(xyz, local + origin, rtol=0, atol=scale / 2 + 1e-9 * k)
    np.testing.assert_array_equal(las.point_source_id, index)
    back = formats.read_foreign_survey(path, unit=unit)
    np.testing.assert_allclose(back["scans"][0]["points"] + back["origin"], local + origin,
                               rtol=0, atol=scale / 2 + 1e-9 * k)


def test_write_laz_plain_las_and_errors_leave_nothing(tmp_path):
    pts = np.array([[0.0, 0.0, 0.0], [1.2345, -2.5, 3.0]])
    formats.write_laz(tmp_path / "p.las", pts, unit="m", origin=[1.0, 2.0, 3.0])
    assert not laspy.read(str(tmp_path / "p.las")).header.are_points_compressed
    before = (tmp_path / "p.las").read_bytes()
    for bad in (dict(points=np.array([[np.nan, 0, 0]])), dict(points=pts, scan_index=[0, 70000]),
                dict(points=np.array([[3e6, 0, 0]]))):
        args = dict(unit="m", origin=[0, 0, 0]) | bad
        with pytest.raises(ValueError):
            formats.write_laz(tmp_path / "p.las", **args)
    assert (tmp_path / "p.las").read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["p.las"]


# ------------------------------------------------------------------ E57

def _full_grid(rows, cols, rng):
    """A synthetic scanner grid: every (row, column) once, shuffled, about 10% invalid."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    el, az = np.radians(-40 + 80 * r / rows), np.radians(360 * c / cols)
    rng_m = rng.uniform(2, 20, r.shape)
    xyz = np.stack([rng_m * np.cos(el) * np.cos(az), rng_m * np.cos(el) * np.sin(az), rng_m * np.sin(el)], -1)
    order = rng.permutation(rows * cols)
    invalid = rng.random(rows * cols) < 0.1
    return (xyz.reshape(-1, 3)[order], r.ravel()[order].astype(np.uint16), c.ravel()[order].astype(np.uint16),
            invalid)


@pytest.fixture
def e57_survey(tmp_path, real_pair):
    """Three data3D entries: a full synthetic grid, a real scan binned into a grid, a real unordered scan."""
    a, b, rel = real_pair
    rng = np.random.default_rng(11)
    gx, grow, gcol, ginv = _full_grid(30, 80, rng)
    p0 = _pose(_rot(2, 30), UTM + [0.7, 0.2, 0.4])
    u, _, vt = np.linalg.svd(rel[:3, :3])  # relative.txt is printed to 6 digits: not quite a rotation
    p1 = p0 @ _pose(u @ vt, rel[:3, 3])
    p2 = _pose(_rot(2, 179.9) @ _rot(0, 5), UTM + [12.0, -7.5, 1.0])
    arow, acol = _grid_from_angles(a, 16, 360)
    entries = [dict(xyz=gx, row=grow, col=gcol, invalid=ginv, pose=p0, name="Station/1"),
               dict(xyz=a, row=arow, col=acol, pose=p1, name="Station/1"),
               dict(xyz=b, pose=p2, name="")]
    path = tmp_path / "survey.e57"
    _write_e57(path, entries)
    return path, entries


def test_e57_scans_poses_and_column_slices(e57_survey):
    path, entries = e57_survey
    assert formats.is_foreign_survey(path)
    survey = formats.read_foreign_survey(path)
    assert survey["format"] == "e57" and survey["unit"] == "m"
    np.testing.assert_array_equal(survey["origin"], np.round(entries[0]["pose"][:3, 3]))
    scans, stored = survey["scans"], _stored_e57(path)
    assert [s["name"] for s in scans] == ["Station_1", "Station_1_2", "survey_2"]
    assert [s["source"] for s in scans] == [f"{path}#data3D[{i}]" for i in range(3)]
    for scan, ent in zip(scans, entries):
        _check_scan_arrays(scan)
        np.testing.assert_allclose(scan["pose"][:3, :3], ent["pose"][:3, :3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(scan["pose"][:3, 3] + survey["origin"], ent["pose"][:3, 3], rtol=0, atol=1e-9)
    # Full grid of 30 rows x 80 columns: 80 slices, each one column with rows ascending, invalid points gone.
    g, (gxyz, grow, gcol, ginv) = scans[0], stored[0]
    keep = ginv == 0
    order = np.lexsort((grow[keep], gcol[keep]))
    np.testing.assert_array_equal(g["points"], gxyz[keep][order])
    so = g["slice_offsets"]
    assert len(so) == 81
    np.testing.assert_array_equal(np.diff(so), [30 - np.sum(~keep & (gcol == c)) for c in range(80)])
    assert f"dropped {int((~keep).sum())} invalid points" in survey["warnings"][0]
    # Binned real scan: one slice per occupied azimuth column, all points kept.
    r, (rxyz, rrow, rcol, _) = scans[1], stored[1]
    order = np.lexsort((rrow, rcol))
    np.testing.assert_array_equal(r["points"], rxyz[order])
    assert len(r["slice_offsets"]) - 1 == len(np.unique(rcol))
    for s0, s1 in zip(r["slice_offsets"][:-1], r["slice_offsets"][1:]):
        assert len(np.unique(rcol[order][s0:s1])) == 1 and np.all(np.diff(rrow[order][s0:s1].astype(int)) >= 0)
    # Unordered scan: points as stored, no slices.
    np.testing.assert_array_equal(scans[2]["points"], stored[2][0])
    assert scans[2]["slice_offsets"] is None
    # And every scan lands where its input world points were, to float32 storage precision (78 m range).
    for scan, ent in zip(scans, entries):
        idx = np.flatnonzero(~ent.get("invalid", np.zeros(len(ent["xyz"]), bool)))
        if "row" in ent:
            idx = idx[np.lexsort((ent["row"][idx], ent["col"][idx]))]
        world_in = ent["xyz"] @ ent["pose"][:3, :3].T + ent["pose"][:3, 3]
        np.testing.assert_allclose(_world(scan, survey["origin"]), world_in[idx], rtol=0, atol=2e-5)


def test_e57_folder_unique_names_and_one_origin(tmp_path, real_pair):
    a = real_pair[0][:3000]
    for stem, t in (("site10", [5.0, 0, 0]), ("site2", [0.0, 0, 0])):
        _write_e57(tmp_path / f"{stem}.e57", [dict(xyz=a, pose=_pose(np.eye(3), UTM + t), name="Scan 0")])
    survey = formats.read_foreign_survey(tmp_path)
    assert [s["name"] for s in survey["scans"]] == ["Scan_0", "Scan_0_2"]
    assert [Path(s["source"]).name for s in survey["scans"]] == ["site2.e57#data3D[0]", "site10.e57#data3D[0]"]
    np.testing.assert_allclose([s["pose"][0, 3] for s in survey["scans"]], [UTM[0] - round(UTM[0]), 5 + UTM[0]
                               - round(UTM[0])], atol=1e-9)


def test_write_e57_poses_round_trip(tmp_path, e57_survey):
    path, entries = e57_survey
    survey = formats.read_foreign_survey(path)
    new = [s["pose"] @ _pose(_rot(k % 3, 2.0 + k), [0.3, -0.1 * k, 0.05]) for k, s in enumerate(survey["scans"])]
    dest = tmp_path / "out" / "registered.e57"
    dest.parent.mkdir()
    formats.write_e57_poses(path, dest, new, origin=survey["origin"])
    assert [p.name for p in dest.parent.iterdir()] == ["registered.e57"]
    back = formats.read_foreign_survey(dest)
    assert [s["name"] for s in back["scans"]] == ["Station_1", "Station_1_2", "registered_2"]  # unnamed: stem
    for before, after, pose in zip(survey["scans"], back["scans"], new):
        np.testing.assert_allclose(after["pose"][:3, :3], pose[:3, :3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(after["pose"][:3, 3] + back["origin"], pose[:3, 3] + survey["origin"],
                                   rtol=0, atol=1e-9)
        np.testing.assert_array_equal(after["points"], before["points"])
        if before["slice_offsets"] is None:
            assert after["slice_offsets"] is None
        else:
            np.testing.assert_array_equal(after["slice_offsets"], before["slice_offsets"])
    # Grid indices and invalid flags are carried over entry by entry, not only what the reader keeps.
    for (x0, r0, c0, i0), (x1, r1, c1, i1) in zip(_stored_e57(path), _stored_e57(dest)):
        np.testing.assert_array_equal(x0, x1)
        for u, v in ((r0, r1), (c0, c1), (i0, i1)):
            assert (u is None and v is None) or np.array_equal(u, v)
    with pytest.raises(formats.SurveyFormatError, match=r"survey\.e57: .*2 poses given for 3 data3D"):
        formats.write_e57_poses(path, dest, new[:2], origin=survey["origin"])


def test_e57_world_coordinate_points_are_recentred(tmp_path, real_pair):
    """Points stored georeferenced under an identity pose are shifted into the pose, and written back so."""
    world = real_pair[0][:5000] + UTM
    path = tmp_path / "georef_points.e57"
    _write_e57(path, [dict(xyz=world, pose=np.eye(4), name="georef")])
    stored = _stored_e57(path)[0][0]
    survey = formats.read_foreign_survey(path)
    (scan,) = survey["scans"]
    assert np.abs(scan["points"]).max() < 200 and "shifted by" in survey["warnings"][0]
    np.testing.assert_allclose(_world(scan, survey["origin"]), stored, rtol=0, atol=1e-6)
    dest = tmp_path / "out.e57"
    formats.write_e57_poses(path, dest, [scan["pose"]], origin=survey["origin"])
    back = formats.read_foreign_survey(dest)
    assert back["warnings"] == []
    np.testing.assert_allclose(_world(back["scans"][0], back["origin"]), stored, rtol=0, atol=1e-6)


def test_e57_spherical_only_scan_is_converted(tmp_path):
    path = tmp_path / "spherical.e57"
    rae = np.array([[2.0, 0.0, 0.0], [3.0, np.pi / 2, 0.0], [4.0, 0.0, np.pi / 2], [5.0, np.pi, -np.pi / 4]])
    with pye57.E57(str(path), mode="w") as e57:  # pye57's writer is cartesian-only; build the node by hand
        imf = e57.image_file
        scan = libe57.StructureNode(imf)
        scan.set("guid", libe57.StringNode(imf, "{spherical-test}"))
        scan.set("name", libe57.StringNode(imf, "sph"))
        proto = libe57.StructureNode(imf)
        for f in formats._SPH:
            proto.set(f, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE, -1e3, 1e3))
        points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
        scan.set("points", points)
        e57.data3d.append(scan)
        arrays, buffers = e57.make_buffers(list(formats._SPH), len(rae))
        for k, f in enumerate(formats._SPH):
            arrays[f][:] = rae[:, k]
        writer = points.writer(buffers)
        writer.write(len(rae))
        writer.close()
    (scan,) = formats.read_foreign_survey(path)["scans"]
    expect = [[2, 0, 0], [0, 3, 0], [0, 0, 4], [-5 * np.sqrt(0.5), 0, -5 * np.sqrt(0.5)]]
    np.testing.assert_allclose(scan["points"], expect, atol=1e-12)
    np.testing.assert_array_equal(scan["pose"], np.eye(4))


def test_quaternion_helpers_round_trip_at_all_angles():
    rng = np.random.default_rng(3)
    rots = [_rot(ax, deg) for ax in range(3) for deg in (0, 90, 179.99, 180)]
    rots += [_rot(0, a) @ _rot(1, b) @ _rot(2, c) for a, b, c in rng.uniform(-180, 180, (20, 3))]
    for r in rots:
        q = formats._matrix_to_quat(r)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(formats._quat_to_matrix(q), r, atol=1e-12)


# ------------------------------------------------------------------ detection and bad input

def test_is_foreign_survey(tmp_path):
    for name in ("a.las", "b.LAZ", "c.e57"):
        assert formats.is_foreign_survey(tmp_path / name)
    assert not formats.is_foreign_survey(tmp_path / "scan000.3d")
    assert not formats.is_foreign_survey(tmp_path)  # empty folder
    (tmp_path / "README").write_text("x")
    assert not formats.is_foreign_survey(tmp_path)
    (tmp_path / "scan2.las").write_bytes(b"")
    (tmp_path / "scan1.LAZ").write_bytes(b"")
    assert formats.is_foreign_survey(tmp_path)
    (tmp_path / "scan3.pcd").write_bytes(b"")
    assert not formats.is_foreign_survey(tmp_path)
    with pytest.raises(formats.SurveyFormatError, match="not a LAS/LAZ/E57 survey"):
        formats.read_foreign_survey(tmp_path)
    (tmp_path / "scan3.pcd").unlink()
    (tmp_path / "scan4.e57").write_bytes(b"")
    with pytest.raises(formats.SurveyFormatError, match="mixes E57"):
        formats.read_foreign_survey(tmp_path)


def _patched(data: bytes, offset: int, value: int) -> bytes:
    b = bytearray(data)
    b[offset] = value
    return bytes(b)


def _flip_middle_page(data: bytes) -> bytes:
    """Flip bytes inside the middle 1024-byte E57 page, leaving its CRC as it was."""
    start = (len(data) // 2048) * 1024 + 100
    b = bytearray(data)
    b[start:start + 16] = bytes(x ^ 0xFF for x in b[start:start + 16])
    return bytes(b)


def _bad_inputs(tmp_path, real_pair):
    """(path to read, file name the message must name, extra text expected)."""
    a = real_pair[0][:4000] + UTM
    good = {}
    for name, version, fmt in (("g.las", "1.2", 0), ("g.laz", "1.4", 6)):
        _write_las(tmp_path / name, a, version=version, fmt=fmt)
        good[name] = (tmp_path / name).read_bytes()
    _write_e57(tmp_path / "g.e57", [dict(xyz=a - UTM, pose=np.eye(4), name="s")])
    good["g.e57"] = (tmp_path / "g.e57").read_bytes()
    las, laz, e57 = good["g.las"], good["g.laz"], good["g.e57"]
    point_start = struct.unpack_from("<I", las, 96)[0]
    cases = {
        "half.las": (las[:len(las) // 2], "truncated"),
        "records.las": (las[:point_start + 20 * 1000], "truncated"),  # cut on a record boundary
        "half.laz": (laz[:len(laz) // 2], "LAZ data unreadable"),
        "fmt42.las": (_patched(las, 104, 42), "point data format id 42 (header byte 104)"),
        "fmt3.las": (_patched(las, 104, 3), "point size"),
        "fmt42.laz": (_patched(laz, 104, 42 | 0x80), "point data format id 42"),
        "garbage.las": (b"LAS?" + bytes(range(256)) * 4, "signature"),
        "crc.e57": (_flip_middle_page(e57), "checksum"),
        "half.e57": (e57[:len(e57) // 2], "ErrorBadFileLength"),
        "junk.e57": (b"\0" * 4096, "E57Exception"),
    }
    out = []
    for name, (data, text) in cases.items():
        (tmp_path / name).write_bytes(data)
        out.append((tmp_path / name, name, text))
    _write_las(tmp_path / "empty.las", np.zeros((0, 3)))
    out.append((tmp_path / "empty.las", "empty.las", "0 points"))
    out.append((tmp_path / "missing.laz", "missing.laz", "no such file"))
    (tmp_path / "nothing").mkdir()
    out.append((tmp_path / "nothing", "nothing", "empty survey"))
    # A bad file inside a folder survey is named itself, not just the folder.
    (tmp_path / "mixed").mkdir()
    (tmp_path / "mixed" / "a1.las").write_bytes(las)
    (tmp_path / "mixed" / "a2.las").write_bytes(las[:len(las) - 7])
    out.append((tmp_path / "mixed", "a2.las", "truncated"))
    return out


def test_bad_inputs_raise_survey_format_error_naming_the_file(tmp_path, real_pair):
    for path, name, text in _bad_inputs(tmp_path, real_pair):
        with pytest.raises(formats.SurveyFormatError) as info:
            formats.read_foreign_survey(path)
        message = str(info.value)
        head = message.split(": ", 1)[0]
        assert head.endswith(name) and Path(head).exists() == (name != "missing.laz"), message
        assert text.lower() in message.lower(), message
        assert isinstance(info.value, ValueError)
    msg = str(pytest.raises(formats.SurveyFormatError, formats.read_foreign_survey, tmp_path / "crc.e57").value)
    assert "byte offset" in msg and "\n" not in msg
