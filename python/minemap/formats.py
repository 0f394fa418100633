"""Survey formats read and written through well-kept libraries: LAS/LAZ (laspy + lazrs) and E57 (pye57).

Everything here works in the *file unit* (metres for LAS and E57, unless the caller overrides it);
the C++ side converts to minemap's centimetres. Survey coordinates are often UTM-sized (x ~ 5e5 m,
y ~ 6e6 m), which float32 cannot hold to the millimetre, so one survey-wide ``origin`` is subtracted
in float64 before any point leaves this module: file coordinate = local coordinate + origin.

Foot units: a LAS file whose CRS (WKT VLR, or GeoTIFF keys) gives a linear unit other than the metre
is converted to metres per axis (horizontal and vertical apart) with a warning; a geographic CRS
(degrees) is refused. When ``unit`` is passed, it wins and no conversion is made.

This module imports only numpy, laspy, pye57 and the standard library, so it loads without ``_core``.
"""
from __future__ import annotations

import os
import re
import uuid
from contextlib import contextmanager, suppress
from pathlib import Path

import laspy
import numpy as np
import pye57
from pye57.utils import convert_spherical_to_cartesian

FOREIGN_SUFFIXES = (".las", ".laz", ".e57")
_NATIVE_SUFFIXES = (".3d", ".pcd", ".ply", ".bin")  # scan files minemap reads itself
_CART = ("cartesianX", "cartesianY", "cartesianZ")
_SPH = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
# GeoTIFF linear unit codes (EPSG) -> metres per unit.
_GEOTIFF_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0, 9005: 0.3047972654}
_ANGULAR = ("degree", "radian", "grad", "gon", "arc")
_RECENTRE = 1e3  # file units: an E57 scan centred farther out than this was stored in world coordinates


class SurveyFormatError(ValueError):
    """A survey file that cannot be read. The message starts with the file path, then ': '."""


def _natural_key(path: Path):
    # re.split with a group alternates text and digit runs, so keys compare element-wise safely.
    return [int(t) if i % 2 else t.lower() for i, t in enumerate(re.split(r"(\d+)", path.name))]


def _scan_files(folder: Path) -> list[Path]:
    return sorted((p for p in folder.iterdir() if p.is_file()
                   and p.suffix.lower() in FOREIGN_SUFFIXES + _NATIVE_SUFFIXES), key=_natural_key)


def is_foreign_survey(path) -> bool:
    """True for a .las/.laz/.e57 path, or a folder whose scan files are all .las/.laz/.e57."""
    path = Path(path)
    if path.is_dir():
        suffixes = {p.suffix.lower() for p in _scan_files(path)}
        return bool(suffixes) and suffixes <= set(FOREIGN_SUFFIXES)
    return path.suffix.lower() in FOREIGN_SUFFIXES


def _fail(path, problem, cause=None):
    raise SurveyFormatError(f"{path}: {problem}") from cause


def _library_text(ex: Exception) -> str:
    """One line from a laspy/lazrs/libE57 exception; libE57's page number becomes a byte offset."""
    text = str(ex).strip()
    first = next((ln.strip() for ln in text.splitlines() if ln.strip() and "****" not in ln), "")
    if type(ex) is not ValueError:  # our own plain ValueErrors need no class name
        first = f"{type(ex).__name__}: {first}" if first else type(ex).__name__
    page = re.search(r"\bpage=(\d+)", text)
    if page:  # libE57 pages are 1024 bytes, each ending in its CRC
        first += f" (page {page.group(1)}, byte offset {int(page.group(1)) * 1024})"
    return first


def _unique_name(raw: str, taken: set, fallback: str) -> str:
    base = re.sub(r"[^A-Za-z0-9._-]+", "_", raw).strip("._") or fallback
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


# ---------------------------------------------------------------- LAS / LAZ

def _wkt_factors(wkt: str):
    """(horizontal, vertical) metres per unit from WKT1/WKT2 text, or None for a geographic CRS."""
    unit_re = r'(?<![A-Z])(?:LENGTH)?UNIT\[\s*"([^"]*)"\s*,\s*([-+0-9.eE]+)'
    parts = re.split(r"VERT_CS\[|VERTCRS\[|VERTICALCRS\[", wkt, maxsplit=1)
    linear = [[float(f) for n, f in re.findall(unit_re, part)
               if not any(a in n.lower() for a in _ANGULAR)] for part in parts]
    if not linear[0]:
        return None if re.search(r"GEOGCS|GEOGCRS|GEODCRS", parts[0]) else (1.0, 1.0)
    horizontal = linear[0][-1]  # the projected CS's own unit comes last (after datum/parameter units)
    return horizontal, (linear[1][-1] if len(parts) > 1 and linear[1] else horizontal)


def _las_metres_per_unit(las, path, warnings) -> np.ndarray:
    """Per-axis metres per file unit, read from the CRS records; refuses a geographic CRS."""
    vlrs = list(las.header.vlrs) + list(las.header.evlrs or [])
    wkt = [v.string for v in vlrs if isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr) and v.string]
    keys = {k.id: k.value_offset for v in vlrs
            if isinstance(v, laspy.vlrs.known.GeoKeyDirectoryVlr) for k in v.geo_keys}
    if wkt:
        factors = _wkt_factors(wkt[0])
    elif keys:
        if keys.get(1024) == 2 and 3076 not in keys:  # GTModelTypeGeoKey: geographic
            factors = None
        else:
            codes = [keys.get(3076, 9001), keys.get(4099, keys.get(3076, 9001))]
            if any(c not in _GEOTIFF_UNITS for c in codes):
                _fail(path, f"unsupported GeoTIFF linear unit code {codes} (known: {sorted(_GEOTIFF_UNITS)})")
            if 3076 not in keys and 3072 in keys:
                warnings.append(f"{path}: CRS given only as EPSG:{keys[3072]}; its unit cannot be "
                                "looked up here, metres assumed")
            factors = tuple(_GEOTIFF_UNITS[c] for c in codes)
    else:
        factors = (1.0, 1.0)
    if factors is None:
        _fail(path, "geographic CRS (coordinates in degrees) is not supported; reproject to a projected CRS")
    return np.array([factors[0], factors[0], factors[1]])


def _read_las(path: Path, unit, warnings) -> np.ndarray:
    """World coordinates as stored (scale and offset applied), float64, in metres unless `unit`."""
    try:
        with laspy.open(path) as reader:
            hdr = reader.header
            if hdr.point_count == 0:
                _fail(path, "file has 0 points")
            if not hdr.are_points_compressed:
                # laspy can read short files without complaint when the cut falls on a record boundary.
                need = hdr.offset_to_point_data + hdr.point_count * hdr.point_format.size
                size = path.stat().st_size
                if size < need:
                    _fail(path, f"truncated: {hdr.point_count} point records need bytes "
                                f"{hdr.offset_to_point_data}..{need}, file ends at byte {size}")
            las = reader.read()
    except SurveyFormatError:
        raise
    except laspy.errors.PointFormatNotSupported as ex:
        _fail(path, f"unsupported point data format id {ex} (header byte 104)", ex)
    except Exception as ex:  # laspy, lazrs and numpy all raise their own types on bad input
        hint = "LAZ data unreadable (truncated or corrupt): " if "Laz" in type(ex).__name__ else ""
        _fail(path, hint + _library_text(ex), ex)
    if len(las.points) != hdr.point_count:
        _fail(path, f"header says {hdr.point_count} points, {len(las.points)} could be read")
    # Integer counts times scale plus offset, all in float64: exact to ~1e-9 m at UTM magnitudes.
    xyz = np.column_stack([np.asarray(las.X, np.float64), np.asarray(las.Y, np.float64),
                           np.asarray(las.Z, np.float64)]) * hdr.scales + hdr.offsets
    factor = _las_metres_per_unit(las, path, warnings)
    if np.any(factor != 1.0):
        if unit is None:
            warnings.append(f"{path}: CRS unit is {factor[0]:g} m (vertical {factor[2]:g} m); "
                            "converted to metres")
            xyz *= factor
        else:
            warnings.append(f"{path}: CRS unit is {factor[0]:g} m (vertical {factor[2]:g} m); "
                            f"not converted, unit={unit!r} given")
    return xyz


# ---------------------------------------------------------------- E57

def _quat_to_matrix(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _matrix_to_quat(rot) -> np.ndarray:
    """(w, x, y, z), w >= 0, by Bar-Itzhack's eigenvector method: stable for any angle, and it
    returns the nearest rotation when registration output has drifted off SO(3) by rounding."""
    r = np.asarray(rot, np.float64)
    if np.linalg.det(r) <= 0:
        raise ValueError("pose rotation is a reflection or singular")
    k = np.array([[r[0, 0] - r[1, 1] - r[2, 2], r[1, 0] + r[0, 1], r[2, 0] + r[0, 2], r[2, 1] - r[1, 2]],
                  [r[1, 0] + r[0, 1], r[1, 1] - r[0, 0] - r[2, 2], r[2, 1] + r[1, 2], r[0, 2] - r[2, 0]],
                  [r[2, 0] + r[0, 2], r[2, 1] + r[1, 2], r[2, 2] - r[0, 0] - r[1, 1], r[1, 0] - r[0, 1]],
                  [r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1], r[0, 0] + r[1, 1] + r[2, 2]]])
    x, y, z, w = np.linalg.eigh(k)[1][:, -1]  # eigenvector of the largest eigenvalue
    return np.array([w, x, y, z]) * (1.0 if w >= 0 else -1.0)


def _e57_entry(e57, i: int):
    """Name, pose, raw fields, cartesian xyz (all points), validity mask, recentring shift of data3D[i]."""
    hdr = e57.get_header(i)
    if hdr.point_count == 0:
        raise ValueError("has 0 points")
    raw = e57.read_scan_raw(i, ignore_unsupported_fields=True)
    if all(f in raw for f in _CART):
        xyz, state = np.column_stack([raw[f] for f in _CART]), raw.get("cartesianInvalidState")
    elif all(f in raw for f in _SPH):  # range/azimuth/elevation, converted as libE57 defines them
        xyz = convert_spherical_to_cartesian(np.column_stack([raw[f] for f in _SPH]))
        state = raw.get("sphericalInvalidState")
    else:
        raise ValueError(f"has neither cartesian nor spherical coordinates (fields: {sorted(raw)})")
    valid = np.isfinite(xyz).all(axis=1) & (True if state is None else state == 0)
    if not valid.any():
        raise ValueError("has no valid points")
    # Some exporters store georeferenced points under an identity pose; float32 downstream would
    # lose them, so such scans are shifted by a whole-unit vector folded into their pose.
    lo, hi = xyz[valid].min(axis=0), xyz[valid].max(axis=0)
    shift = np.round((lo + hi) / 2) if np.linalg.norm((lo + hi) / 2) > _RECENTRE else np.zeros(3)
    name = hdr["name"].value() if hdr.node.isDefined("name") else ""
    return name, hdr.rotation, hdr.translation, raw, xyz, state, valid, shift


def _read_e57(path: Path, scans: list, names: set, warnings, origin):
    """Append one dict per data3D entry of `path`; returns the survey origin (set by the first scan)."""
    try:
        with pye57.E57(str(path)) as e57:
            if e57.scan_count == 0:
                _fail(path, "no data3D scans")
            for i in range(e57.scan_count):
                try:
                    name, quat, trans, raw, xyz, _, valid, shift = _e57_entry(e57, i)
                except SurveyFormatError:
                    raise
                except Exception as ex:
                    _fail(path, f"data3D[{i}]: {_library_text(ex)}", ex)
                rot = _quat_to_matrix(quat)
                trans = trans + rot @ shift
                if origin is None:  # whole metres, so a georeferenced survey keeps exact offsets
                    origin = np.round(trans)
                pose = np.eye(4)
                pose[:3, :3], pose[:3, 3] = rot, trans - origin
                slices = None
                if "rowIndex" in raw and "columnIndex" in raw:
                    # Scanner grid: one slice per column, points ordered by row inside it.
                    row, col = raw["rowIndex"][valid], raw["columnIndex"][valid]
                    order = np.lexsort((row, col))
                    col = col[order]
                    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
                    slices = np.r_[starts, col.size].astype(np.uint32)
                else:
                    order = slice(None)
                if not valid.all():
                    warnings.append(f"{path}#data3D[{i}]: dropped {int((~valid).sum())} invalid points")
                if shift.any():
                    warnings.append(f"{path}#data3D[{i}]: points stored in world coordinates; "
                                    f"shifted by {shift.tolist()} into the pose")
                stem = f"{path.stem}_{i}"
                scans.append({"name": _unique_name(name or stem, names, stem),
                              "source": f"{path}#data3D[{i}]",
                              "points": (xyz[valid] - shift)[order], "pose": pose,
                              "slice_offsets": slices})
    except SurveyFormatError:
        raise
    except Exception as ex:  # libE57: open failure, bad length, checksum mismatch, ...
        _fail(path, _library_text(ex), ex)
    return origin


# ---------------------------------------------------------------- public

def read_foreign_survey(path, unit: str | None = None) -> dict:
    """Read a .las/.laz/.e57 file or a folder of them; see the module doc for frames and units."""
    if unit not in (None, "m", "cm"):
        raise ValueError(f"unit must be 'm' or 'cm', not {unit!r}")
    path = Path(path)
    if not path.exists():
        _fail(path, "no such file or folder")
    files = _scan_files(path) if path.is_dir() else [path]
    kinds = {f.suffix.lower() for f in files}
    if not files:
        _fail(path, "empty survey: no .las/.laz/.e57 scan files")
    if not kinds <= set(FOREIGN_SUFFIXES):
        _fail(path, f"not a LAS/LAZ/E57 survey (scan file types: {sorted(kinds)})")
    if ".e57" in kinds and len(kinds) > 1:
        _fail(path, "mixes E57 with LAS/LAZ files; keep one format per survey")
    file_unit = unit or "m"
    scans, names, warnings, origin = [], set(), [], None
    if ".e57" in kinds:
        for f in files:
            origin = _read_e57(f, scans, names, warnings, origin)
        fmt = "e57"
    else:
        for f in files:
            xyz = _read_las(f, unit, warnings)
            if origin is None:  # first file's minimum, whole units: the local frame stays small
                origin = np.floor(xyz.min(axis=0))
            scans.append({"name": _unique_name(f.stem, names, f"scan{len(scans)}"), "source": str(f),
                          "points": xyz - origin, "pose": np.eye(4), "slice_offsets": None})
        fmt = "laz" if ".laz" in kinds else "las"
    return {"format": fmt, "unit": file_unit, "origin": np.asarray(origin, np.float64),
            "scans": scans, "warnings": warnings}


@contextmanager
def _atomic(path: Path, suffix: str):
    """Yield a temp path in the target folder; move it onto `path` only if the block succeeds."""
    # The writer creates the file itself, so it gets ordinary permissions (mkstemp would give 0600).
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with suppress(OSError):
            tmp.unlink()
        raise


def write_laz(path, points, *, unit: str, origin, scan_index=None, wkt: str | None = None) -> None:
    """Write LAS 1.4 point format 6 (LAZ-compressed unless `path` ends in .las).

    points: (N,3) float64 in the local frame, file unit; origin (3,) in the file unit becomes the LAS
    offset, so readers see the original (e.g. UTM) coordinates. Scale is 1 mm. scan_index -> point_source_id.
    """
    if unit not in ("m", "cm"):
        raise ValueError(f"unit must be 'm' or 'cm', not {unit!r}")
    path, pts = Path(path), np.asarray(points, np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.isfinite(pts).all():
        raise ValueError(f"points must be a finite (N,3) array, got shape {pts.shape}")
    scale = 0.001 if unit == "m" else 0.1
    counts = np.round(pts / scale)  # offset == origin, so the local frame maps straight to counts
    if counts.size and np.abs(counts).max() > np.iinfo(np.int32).max:
        raise ValueError(f"points lie beyond the int32 range of a {scale} {unit} LAS scale around origin")
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.full(3, scale), np.asarray(origin, np.float64)
    if wkt is not None:  # the grid's CRS (a map tied to control): LAS 1.4's OGC WKT record
        header.global_encoding.wkt = True
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
    las = laspy.LasData(header, laspy.ScaleAwarePointRecord.zeros(len(pts), header=header))
    las.X, las.Y, las.Z = (counts[:, k].astype(np.int32) for k in range(3))
    if scan_index is not None:
        idx = np.asarray(scan_index)
        if idx.shape != (len(pts),) or (idx.size and (idx.min() < 0 or idx.max() > 65535)):
            raise ValueError("scan_index must be (N,) integers in 0..65535 (LAS point_source_id)")
        las.point_source_id = idx.astype(np.uint16)
    with _atomic(path, ".laz") as tmp, open(tmp, "wb") as out:
        las.write(out, do_compress=path.suffix.lower() != ".las")


def write_e57_poses(source_e57, dest_e57, poses, *, origin) -> None:
    """Copy `source_e57` to `dest_e57` with data3D[i]'s pose replaced by poses[i].

    poses: one 4x4 T_world_scan per data3D entry, local frame, file unit (as read_foreign_survey gives);
    origin is added back to each translation. Points, grid indices, intensity, colour and names are
    kept; pye57 stores coordinates as float32 and drops other fields and metadata (see report).
    """
    source_e57, dest_e57 = Path(source_e57), Path(dest_e57)
    poses = [np.asarray(p, np.float64) for p in poses]
    if any(p.shape != (4, 4) or not np.isfinite(p).all() for p in poses):
        raise ValueError("poses must be finite 4x4 matrices")
    origin = np.asarray(origin, np.float64)
    try:
        with pye57.E57(str(source_e57)) as src:
            if len(poses) != src.scan_count:
                _fail(source_e57, f"{len(poses)} poses given for {src.scan_count} data3D scans")
            entries = []
            for i in range(src.scan_count):
                try:
                    entries.append(_e57_entry(src, i))
                except Exception as ex:
                    _fail(source_e57, f"data3D[{i}]: {_library_text(ex)}", ex)
    except SurveyFormatError:
        raise
    except Exception as ex:  # libE57: open failure, bad length, checksum mismatch, ...
        _fail(source_e57, _library_text(ex), ex)
    with _atomic(dest_e57, ".e57") as tmp, pye57.E57(str(tmp), mode="w") as dst:
        for (name, _, _, raw, xyz, state, _, shift), pose in zip(entries, poses):
            # Points are written in the (possibly recentred) frame the pose refers to.
            data = {f: (xyz[:, k] - shift[k]) for k, f in enumerate(_CART)}
            data.update({f: raw[f] for f in ("intensity", "colorRed", "colorGreen", "colorBlue",
                                              "rowIndex", "columnIndex") if f in raw})
            if state is not None:
                data["cartesianInvalidState"] = state
            dst.write_scan_raw(data, name=name, rotation=_matrix_to_quat(pose[:3, :3]),
                               translation=pose[:3, 3] + origin)
