"""`minemap export`'s writers for what the C++ core leaves to this package: LAS/LAZ (laspy + lazrs),
COPC (.copc.laz: copclib) and E57 (pye57).

The scans come from the C++ core's stream (``_core.SurveyExport``, report/survey_export.hpp): the
survey re-read one scan at a time, placed by the map's poses, in the export's frame and unit, in the
survey's own (world) coordinates as float64. Each writer takes them in turn, so memory does not grow
with the survey; the file appears under its name only when it is complete (a temp file beside it,
renamed), and a stop between scans leaves nothing.

What each format keeps (every attribute the scans carry, and each point's scan):
  LAS/LAZ  1.4, point format 6 (7 with colour); scale 1 mm (0.1 for a cm export), offset = the
           survey's origin in whole units, so UTM-size coordinates keep their millimetres. intensity
           (uint16: the file's values rounded, or x65535 when they lie in 0..1), and the exact value
           in the extra dimension ``intensity_value`` (float32); colour (x257 to 16 bits); time as
           gps_time; return_number; point_source_id = scan index (mod 65536) and the extra
           dimension ``scan_index`` (uint32); ``ring`` (uint16) as an extra dimension.
  COPC     the same points and dimensions, organised as the octree of COPC 1.0 (see _write_copc).
  E57      one data3D per scan, world coordinates (float64) and an identity pose; intensity
           (float32, exact) and colour; pye57 writes no time, ring or return number (a warning).
A map tied to control (report.json ``control``) is exported in its grid; LAS/LAZ and COPC carry the
grid's CRS as an OGC WKT record where crs.py knows the EPSG code (the UTM zones of WGS 84 and ETRS89),
and say so in a warning where it does not; E57 says so in a warning (pye57 cannot set it).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import laspy
import numpy as np

from . import _core, crs, formats

BITS = _core.attribute_bits
INTENSITY, COLOUR, TIME, RING, RETURN = (BITS[k] for k in ("intensity", "colour", "time", "ring", "return_number"))


class _Stopped(Exception):
    """Raised inside a writer's temp-file block when asked to stop: the temp file goes."""


def _summary(scans: int, points: int, attributes: int, completed: bool, warnings=()) -> dict:
    return {"scans": scans, "points": points, "attributes": attributes, "completed": completed,
            "warnings": list(warnings)}


# ---- LAS / LAZ ------------------------------------------------------------------------------------

def _las_header(scans, attributes: int) -> laspy.LasHeader:
    header = laspy.LasHeader(point_format=7 if attributes & COLOUR else 6, version="1.4")
    header.global_encoding.wkt = True  # LAS 1.4 point formats 6 and up (COPC's readers insist)
    scale = 0.001 if scans.unit == "m" else 0.1
    header.scales = np.full(3, scale)
    header.offsets = np.round(np.asarray(scans.origin, np.float64))  # whole units: exact in the header
    extra = [laspy.ExtraBytesParams("scan_index", np.uint32, description="scan index in report.json")]
    if attributes & INTENSITY:
        extra.append(laspy.ExtraBytesParams("intensity_value", np.float32, description="intensity as the scan stored it"))
    if attributes & RING:
        extra.append(laspy.ExtraBytesParams("ring", np.uint16, description="laser ring"))
    header.add_extra_dims(extra)
    grid = crs.wkt(scans.epsg)
    if grid is not None:  # a map tied to control: its grid's CRS (LAS 1.4: an OGC WKT record)
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(grid))
    return header


def _intensity_factor(first: dict) -> float:
    """LAS intensity is uint16: values in 0..1 (KITTI's reflectance) are stretched to it."""
    values = first.get("intensity")
    return 65535.0 if values is not None and values.size and float(values.max()) <= 1.0 else 1.0


def _las_record(scan: dict, header: laspy.LasHeader, intensity_factor: float) -> laspy.ScaleAwarePointRecord:
    points = scan["points"]
    n = len(points)
    record = laspy.ScaleAwarePointRecord.zeros(n, header=header)
    counts = np.round((points - header.offsets) / header.scales)
    if n and np.abs(counts).max() > np.iinfo(np.int32).max:
        raise ValueError(f"{scan['source']}: its points lie beyond the int32 range of the LAS scale around the offset")
    record.X, record.Y, record.Z = (counts[:, k].astype(np.int32) for k in range(3))
    record.point_source_id = np.full(n, scan["index"] & 0xFFFF, np.uint16)
    record["scan_index"] = np.full(n, scan["index"], np.uint32)
    returns = scan.get("return_number")
    one_return = np.clip(returns, 1, 15).astype(np.uint8) if returns is not None else np.ones(n, np.uint8)
    record.return_number = one_return
    record.number_of_returns = one_return
    if "intensity" in scan and "intensity_value" in header.point_format.dimension_names:
        values = scan["intensity"]
        record.intensity = np.clip(np.round(values * intensity_factor), 0, 65535).astype(np.uint16)
        record["intensity_value"] = values
    if "time" in scan:
        record.gps_time = scan["time"]
    if "rgb" in scan and header.point_format.id == 7:
        rgb = scan["rgb"].astype(np.uint32)
        for channel, shift in (("red", 16), ("green", 8), ("blue", 0)):
            setattr(record, channel, (((rgb >> shift) & 0xFF) * 257).astype(np.uint16))
    if "ring" in scan and "ring" in header.point_format.dimension_names:
        record["ring"] = scan["ring"]
    return record


def _write_las(scans, path: Path, stop) -> dict:
    attributes = scans.attributes()
    header = _las_header(scans, attributes)
    first = None
    done = points = 0
    warnings = crs.left_out(scans.epsg, path)
    try:
        with formats._atomic(path, path.suffix) as tmp:
            with laspy.open(str(tmp), mode="w", header=header, do_compress=path.suffix.lower() == ".laz") as writer:
                while (scan := scans.next()) is not None:
                    if stop():
                        raise _Stopped()
                    first = first or scan
                    writer.write_points(_las_record(scan, header, _intensity_factor(first)))
                    done, points = done + 1, points + len(scan["points"])
    except _Stopped:
        return _summary(done, points, attributes, False)
    return _summary(done, points, attributes, True, warnings)


# ---- COPC -----------------------------------------------------------------------------------------

# COPC 1.0 (copc.io): a LAZ 1.4 file whose points are stored as the nodes of an octree over a cube
# around the cloud, with a hierarchy saying where each node lies, so a viewer or a GIS streams what
# it looks at. copclib (PyPI, on lazperf) writes the file from the nodes handed to it; it does not
# build the tree: that is done here, out of core, in four passes over a spill file beside the
# target (so memory stays bounded by one bucket, not by the survey):
#   1. the scans, as LAS records (exactly as _write_las makes them), appended to the spill file;
#   2. each point's cell at the deepest level (COPC_MAX_DEPTH) counted: a node is split while it holds
#      more than COPC_NODE_POINTS points; a split node keeps a random share of them (COPC_KEPT of
#      that budget, a level of detail) and hands the rest down;
#   3. each point given its node (the first node on its way down that keeps it: a hash of its index
#      decides, so the same survey gives the same file) and written to one of a few bucket files;
#   4. bucket by bucket, its points sorted by node and each node handed to copclib.
COPC_NODE_POINTS = 100_000
COPC_KEPT = 0.25
COPC_MAX_DEPTH = 10  # 2^10 cells a side: a 250 m drive's cube in cells of 24 cm
COPC_CHUNK = 500_000  # points read at once in passes 2 and 3 (about 100 MB of arrays)


def _uniform(index: np.ndarray, depth: int) -> np.ndarray:
    """A uniform number in [0, 1) per point index and depth, the same on every run (splitmix64)."""
    with np.errstate(over="ignore"):  # arithmetic modulo 2^64, as intended
        x = index.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        x += np.full_like(x, depth + 1) * np.uint64(0xBF58476D1CE4E5B9)
        x ^= x >> np.uint64(30)
        x *= np.uint64(0xBF58476D1CE4E5B9)
        x ^= x >> np.uint64(27)
        x *= np.uint64(0x94D049BB133111EB)
        x ^= x >> np.uint64(31)
    return (x >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _pack(cells: np.ndarray) -> np.ndarray:
    """(N, 3) cell indices (< 2^16 each) as one int64 key per point; a node adds its depth above
    (depth << 48), so keys sort by depth, then cell."""
    return (cells[:, 0] << 32) | (cells[:, 1] << 16) | cells[:, 2]


def _unpack(keys: np.ndarray) -> np.ndarray:
    return np.stack([(keys >> 32) & 0xFFFF, (keys >> 16) & 0xFFFF, keys & 0xFFFF], axis=1)


def _extra_bytes_vlr(header: laspy.LasHeader, workdir: Path):
    """copclib's extra-bytes VLR for `header`'s extra dimensions: copclib's Python API builds none, so
    it is read back from a one-point LAZ that laspy writes with them."""
    import copclib as copc

    template = workdir / "template.laz"
    las = laspy.LasData(header.copy() if hasattr(header, "copy") else header)
    las.points = laspy.ScaleAwarePointRecord.zeros(1, header=header)
    las.write(str(template))
    return copc.LazReader(str(template)).laz_config.extra_bytes_vlr


class _CopcBuild:
    """One COPC file built out of core in the four passes above, in the work folder `workdir`."""

    def __init__(self, header: laspy.LasHeader, workdir: Path):
        self.header, self.workdir = header, workdir
        self.wkt = None  # the grid's CRS (a map tied to control), for copclib's header
        self.spill = workdir / "points.bin"
        self.dtype = laspy.ScaleAwarePointRecord.zeros(0, header=header).array.dtype
        self.total = 0
        self.lo = np.full(3, np.iinfo(np.int64).max, np.int64)
        self.hi = np.full(3, np.iinfo(np.int64).min, np.int64)

    def spill_scans(self, scans, stop) -> int | None:
        """Pass 1: the scans as LAS records into the spill file; the scans done, or None if stopped."""
        done, first = 0, None
        with open(self.spill, "wb") as out:
            while (scan := scans.next()) is not None:
                if stop():
                    return None
                first = first or scan
                record = _las_record(scan, self.header, _intensity_factor(first))
                xyz = np.stack([record.X, record.Y, record.Z], axis=1).astype(np.int64)
                if len(xyz):
                    self.lo, self.hi = np.minimum(self.lo, xyz.min(axis=0)), np.maximum(self.hi, xyz.max(axis=0))
                record.array.tofile(out)
                done, self.total = done + 1, self.total + len(xyz)
        return done

    def place_cube(self) -> None:
        """The cube (in LAS counts) around the cloud. Its side is a multiple of the deepest cells, and
        its corner half a count off the points' grid: no point lies on a node's face, where float
        rounding in a reader could put it outside its node."""
        cells_per_side = 1 << COPC_MAX_DEPTH
        extent = int((self.hi - self.lo).max()) + 1
        self.cell = -(-extent // cells_per_side)  # counts per deepest cell
        self.side = self.cell * cells_per_side
        pad = (self.side - (self.hi - self.lo + 1)) // 2  # per axis: the cloud in the middle
        self.corner2 = 2 * (self.lo - pad) - 1             # twice the corner: lo - pad - 1/2

    def chunks(self):
        """(first point index, records, deepest cells) of the spill file, COPC_CHUNK points at once."""
        size = self.header.point_format.size
        for start in range(0, self.total, COPC_CHUNK):
            records = np.fromfile(self.spill, dtype=self.dtype, count=min(COPC_CHUNK, self.total - start),
                                  offset=start * size)
            xyz = np.stack([records["X"], records["Y"], records["Z"]], axis=1).astype(np.int64)
            deep = np.clip((2 * xyz - self.corner2) // (2 * self.cell), 0, (1 << COPC_MAX_DEPTH) - 1)
            yield start, records, deep

    def plan_tree(self) -> None:
        """Pass 2: points per deepest cell, then per node at every depth; a node is split while it holds
        more than COPC_NODE_POINTS (above the deepest level). self.split[depth]: the split nodes'
        sorted keys and the share of their points each keeps."""
        keys, counts = np.zeros(0, np.int64), np.zeros(0, np.int64)
        for _, _, deep in self.chunks():
            k, c = np.unique(_pack(deep), return_counts=True)
            keys, inverse = np.unique(np.concatenate([keys, k]), return_inverse=True)
            counts = np.bincount(inverse, weights=np.concatenate([counts, c]).astype(np.float64)).astype(np.int64)
        deep_cells = _unpack(keys)
        self.split = []
        for depth in range(COPC_MAX_DEPTH + 1):
            node_keys, inverse = np.unique(_pack(deep_cells >> (COPC_MAX_DEPTH - depth)), return_inverse=True)
            node_counts = np.bincount(inverse, weights=counts.astype(np.float64))
            busy = node_counts > COPC_NODE_POINTS if depth < COPC_MAX_DEPTH else np.zeros(len(node_keys), bool)
            self.split.append((node_keys[busy], COPC_KEPT * COPC_NODE_POINTS / node_counts[busy]))

    def node_of(self, start: int, deep: np.ndarray) -> np.ndarray:
        """Each point's node, (depth << 48) | cell key: the first node on its way down that keeps it."""
        node_depth = np.full(len(deep), -1, np.int64)
        for depth in range(COPC_MAX_DEPTH + 1):
            open_ = np.nonzero(node_depth < 0)[0]
            if not len(open_):
                break
            key = _pack(deep[open_] >> (COPC_MAX_DEPTH - depth))
            split_keys, share = self.split[depth]
            where = np.searchsorted(split_keys, key)
            inside = np.zeros(len(key), bool)
            if len(split_keys):
                inside = (where < len(split_keys)) & (split_keys[np.minimum(where, len(split_keys) - 1)] == key)
            kept = np.ones(len(key), bool)  # a node not split keeps every point reaching it
            kept[inside] = _uniform(start + open_[inside], depth) < share[where[inside]]
            node_depth[open_[kept]] = depth
        return (node_depth << 48) | _pack(deep >> (COPC_MAX_DEPTH - node_depth)[:, None])

    def bucket(self) -> int:
        """Pass 3: every point, with its node, into one of a few bucket files (by node)."""
        buckets = max(1, min(256, self.total // 500_000 + 1))
        files = [open(self.workdir / f"bucket{b}.bin", "wb") for b in range(buckets)]
        try:
            for start, records, deep in self.chunks():
                node = self.node_of(start, deep)
                which = node % buckets
                for b in range(buckets):
                    mine = which == b
                    if mine.any():
                        np.save(files[b], node[mine])
                        np.save(files[b], records[mine])
        finally:
            for f in files:
                f.close()
        return buckets

    def write(self, tmp: Path, buckets: int, stop) -> bool:
        """Pass 4: the nodes, bucket by bucket, to copclib; False if stopped."""
        import copclib as copc

        h = self.header
        config = copc.CopcConfigWriter(h.point_format.id, copc.Vector3(*h.scales), copc.Vector3(*h.offsets),
                                       self.wkt or "",
                                       _extra_bytes_vlr(h, self.workdir))
        # The header's bounds are the cube's: copclib (and readers built on it) take a node's box from
        # them, as COPC's info does from its centre and half size.
        cube_lo = self.corner2 / 2 * h.scales + h.offsets
        config.las_header.min = copc.Vector3(*cube_lo)
        config.las_header.max = copc.Vector3(*(cube_lo + self.side * h.scales))
        info = config.copc_info
        info.center_x, info.center_y, info.center_z = cube_lo + self.side / 2 * h.scales
        info.halfsize = float(self.side / 2 * h.scales[0])
        info.spacing = float(self.side * h.scales[0] / 128)
        writer = copc.FileWriter(str(tmp), config)
        try:
            for b in range(buckets):
                nodes, parts = [], []
                with open(self.workdir / f"bucket{b}.bin", "rb") as f:
                    while True:
                        try:
                            nodes.append(np.load(f))
                            parts.append(np.load(f))
                        except (EOFError, ValueError):
                            break
                if nodes:
                    self._add_nodes(writer, np.concatenate(nodes), np.concatenate(parts))
                if stop():
                    return False
        finally:
            writer.Close()
        return True

    @staticmethod
    def _add_nodes(writer, node: np.ndarray, records: np.ndarray) -> None:
        import copclib as copc

        order = np.argsort(node, kind="stable")
        node, records = node[order], records[order]
        starts = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])
        ends = np.r_[starts[1:], len(node)]
        for begin, end in zip(starts, ends):
            key = int(node[begin])
            voxel = copc.VoxelKey(key >> 48, (key >> 32) & 0xFFFF, (key >> 16) & 0xFFFF, key & 0xFFFF)
            writer.AddNode(voxel, copc.VectorChar(memoryview(records[begin:end].tobytes()).cast("b")))


def _write_copc(scans, path: Path, stop) -> dict:
    attributes = scans.attributes()
    header = _las_header(scans, attributes)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.name}.") as work:
        build = _CopcBuild(header, Path(work))
        build.wkt = crs.wkt(scans.epsg)
        done = build.spill_scans(scans, stop)
        if done is None:
            return _summary(0, 0, attributes, False)
        build.place_cube()
        build.plan_tree()
        buckets = build.bucket()
        tmp = Path(work) / "out.copc.laz"
        if not build.write(tmp, buckets, stop):
            return _summary(done, build.total, attributes, False)
        os.replace(tmp, path)
    return _summary(done, build.total, attributes, True, crs.left_out(scans.epsg, path))


# ---- E57 ------------------------------------------------------------------------------------------

def _write_e57(scans, path: Path, stop) -> dict:
    import pye57

    attributes = scans.attributes()
    warnings = []
    lost = attributes & (TIME | RING | RETURN)
    if lost:
        warnings.append(f"{path}: E57 (pye57) holds no {_core.describe_attributes(lost)}: left out")
    if scans.epsg is not None:
        # E57 keeps a CRS in its root's coordinateMetadata, but pye57 writes that field (empty) when
        # it opens the file, and libE57 lets no field be set twice.
        warnings.append(f"{path}: EPSG:{scans.epsg} is not written into the file (pye57 leaves its "
                        f"coordinateMetadata empty); the coordinates are the grid's, report.json names it")
    done = points = 0
    try:
        with formats._atomic(path, ".e57") as tmp:
            e57 = pye57.E57(str(tmp), mode="w")
            try:
                while (scan := scans.next()) is not None:
                    if stop():
                        raise _Stopped()
                    xyz = scan["points"]
                    data = {"cartesianX": xyz[:, 0].copy(), "cartesianY": xyz[:, 1].copy(), "cartesianZ": xyz[:, 2].copy()}
                    if "intensity" in scan:
                        data["intensity"] = scan["intensity"].astype(np.float32)
                    if "rgb" in scan:
                        rgb = scan["rgb"]
                        data["colorRed"] = ((rgb >> 16) & 0xFF).astype(np.uint8)
                        data["colorGreen"] = ((rgb >> 8) & 0xFF).astype(np.uint8)
                        data["colorBlue"] = (rgb & 0xFF).astype(np.uint8)
                    e57.write_scan_raw(data, name=scan["name"])
                    done, points = done + 1, points + len(xyz)
            finally:
                e57.close()
    except _Stopped:
        return _summary(done, points, attributes, False)
    return _summary(done, points, attributes, True, warnings)


# ---- dispatch ---------------------------------------------------------------------------------------

def write(scans, path, stop) -> dict:
    """The C++ command line's export writer (Hooks::export_writer): `scans` a _core.SurveyExport,
    `stop()` asked between scans. Returns the summary the command line prints."""
    path = Path(path)
    name = path.name.lower()
    if name.endswith(".copc.laz"):
        return _write_copc(scans, path, stop)
    if name.endswith((".las", ".laz")):
        return _write_las(scans, path, stop)
    if name.endswith(".e57"):
        return _write_e57(scans, path, stop)
    raise ValueError(f"{path}: unknown export format (expected .ply, .las, .laz, .copc.laz or .e57)")


def export(out, to, *, frame: str = "z-up", voxel_cm: float = 0.0, scans=None) -> dict:
    """Writes the registered survey of the finished map in `out` to `to` (format from the extension),
    as `minemap export OUT --to TO` does. Returns {"scans", "points", "attributes", "completed",
    "warnings"}."""
    stream = _core.SurveyExport(os.fspath(out), frame, float(voxel_cm), list(scans or []))
    to = Path(to)
    if to.name.lower().endswith(".ply"):
        return _core.write_export_ply(stream, os.fspath(to))
    return write(stream, to, lambda: False)
