"""minemap: 6D SLAM for 3D laser scans (Nüchter et al., "6D SLAM with an Application in Autonomous
Mine Mapping"), from Python.

    import minemap
    result = minemap.register(source, target, init=np.eye(4))       # (N, 3) arrays in metres
    survey = minemap.read_survey("survey/")                          # uos, PCD, PLY, KITTI, LAS/LAZ, E57
    result = minemap.map_survey("survey/", out="map/", mode="simultaneous")
    minemap.simulate("sim/", scans=24)
    minemap.batch(["a/", "b/"], "maps/")                             # many surveys on a Dask cluster

Settings are keyword arguments named as `minemap map`'s options (``--max-pair-dist-cm 25`` is
``max_pair_dist_cm=25``, the flag ``--no-filter`` is ``no_filter=True``) and parsed by the command
line's own definitions in C++, so names, defaults and checks are the command line's:
``minemap.options()`` lists them with their defaults. The backend is chosen as in the command line
(``backend="auto" | "cpu" | "opencl"``). Lengths are in the survey's unit (uos: cm, the other
formats: m), or in ``unit`` for arrays (default m). The GIL is released while C++ works; Ctrl-C stops
a mapping between scans (KeyboardInterrupt). Errors: bad input raises InputError (a ValueError) with
the command line's message (file and line or byte), bad settings or arrays raise ValueError.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import _core, crs, exports, formats
from ._core import BackendError, InputError, OutputError, __version__
from .batch import batch  # many surveys on a Dask cluster; dask is imported only when it runs

__all__ = ["__version__", "export", "register", "map_survey", "read_survey", "simulate", "batch", "options", "RegistrationResult",
           "MappingResult", "Survey", "InputError", "BackendError", "OutputError", "formats"]


# ---- settings: keyword arguments as `minemap map` options ---------------------------------------------

def options(preset: str = "default") -> dict[str, dict[str, Any]]:
    """`minemap map`'s options as keyword names: {name: {"default": text, "help": text, "flag": bool}}."""
    return {name[2:].replace("-", "_"): {"default": default, "help": help_text, "flag": flag}
            for name, default, help_text, flag in _core.map_options(preset)}


def _option_args(settings: dict[str, Any], function: str) -> list[str]:
    """Keyword arguments to `minemap map` arguments; an unknown name is a TypeError as Python's own."""
    known = options()
    args: list[str] = []
    for key, value in settings.items():
        if value is None:
            continue
        if key not in known:
            raise TypeError(f"{function}() got an unexpected keyword argument '{key}' "
                            f"(minemap.options() lists the settings)")
        name = "--" + key.replace("_", "-")
        if known[key]["flag"]:
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{key}: expected True or False, got {value!r}")
            if value:
                args.append(name)
        else:
            args += [name, os.fspath(value) if isinstance(value, os.PathLike) else str(value)]
    return args


# ---- results ----------------------------------------------------------------------------------------

@dataclass
class RegistrationResult:
    """One registration (minemap.register): `pose` is T_target_source (4x4, translation in the
    unit given), `rms` the RMS pair distance in that unit, `stop_reason` "converged",
    "iteration cap reached", "too few pairs (no overlap)" or "numeric failure (...)" (the last two:
    the pose is `init`, `converged` is False).

    ICP converges from any start, right or not: `trusted` is the verdict `minemap map` gives a match
    (False where it exits 13), `doubt` says which test failed with its figures, `health` holds them
    (lengths in the unit given), and `retry_bound` (> 0) the wider bound a trusted retry started
    from after the match at the pair bound was doubtful."""
    pose: np.ndarray
    iterations: int
    pairs: int
    rms: float
    stop_reason: str
    converged: bool
    trusted: bool = False
    doubt: str = ""
    retry_bound: float = 0.0
    health: dict = field(default_factory=dict)


@dataclass
class MappingResult:
    """A mapped survey (minemap.map_survey). `poses[i]` is scan i's registered T_world_scan (4x4, the
    survey's unit, the first scan fixing the frame); `report` holds report.json's fields (timings,
    per-scan ICP figures and health, loops, the error against reference poses)."""
    names: list[str]
    poses: np.ndarray
    initial_poses: np.ndarray
    registered: list[bool]
    doubts: list[str]
    interrupted: bool
    format: str
    unit: str
    origin: tuple[float, float, float]
    report: dict[str, Any] = field(repr=False)

    @property
    def doubtful(self) -> list[str]:
        """Names of the scans whose match was judged doubtful (the command line exits 13)."""
        return [n for n, d in zip(self.names, self.doubts) if d]

    @property
    def ok(self) -> bool:
        """Every scan registered and none doubtful: what `minemap map` exits 0 for."""
        return all(self.registered) and not self.doubtful and not self.interrupted


@dataclass
class Survey:
    """A survey as read (minemap.read_survey): per scan its points in its file frame (float64, the
    survey's unit), its initial pose and its slices."""
    format: str
    unit: str
    origin: tuple[float, float, float]
    names: list[str]
    sources: list[str]
    points: list[np.ndarray]
    poses: np.ndarray
    slice_offsets: list[np.ndarray | None]
    truth: np.ndarray | None
    warnings: list[str]

    def __len__(self) -> int:
        return len(self.names)


# ---- the API ----------------------------------------------------------------------------------------

def register(source, target, init=None, *, unit: str = "m", **settings) -> RegistrationResult:
    """Registers `source` onto `target` ((N, 3) float32/float64 arrays in `unit`) as `minemap map`
    registers a scan against the one before it: both reduced as map reduces them (15 cm voxel means,
    the target's model 10 cm; reduction="slices" keeps every point of arrays, which have no
    slices), minemap's ICP (Horn's closed form, the bucket kd-tree) from `init` (4x4,
    T_target_source), judged, and when doubtful tried again from `init` at 4x and 16x the pair bound
    (at most 4 m), coarse to fine, kept when trusted. Settings: the options of `minemap map` that
    apply to a pair (voxel_cm, model_voxel_cm, reduction, max_pair_dist_cm, refine_fraction,
    max_iterations, min_step_cm, min_step_deg, search, bucket_size, plain_icp, no_retry,
    retry_bound_factors, no_health_check, health_*, backend, threads, preset)."""
    d = _core.register(source, target, init, unit, _option_args(settings, "register"))
    return RegistrationResult(pose=d["pose"], iterations=d["iterations"], pairs=d["pairs"], rms=d["rms"],
                              stop_reason=d["stop_reason"], converged=d["converged"], trusted=d["trusted"],
                              doubt=d["doubt"], retry_bound=d["retry_bound"], health=dict(d["health"]))


def _mapping_result(d: dict) -> MappingResult:
    return MappingResult(names=list(d["names"]), poses=d["poses"], initial_poses=d["initial_poses"],
                         registered=list(d["registered"]), doubts=list(d["doubts"]), interrupted=d["interrupted"],
                         format=d["format"], unit=d["unit"], origin=tuple(d["origin"]), report=d["report"])


def map_survey(survey, *, out=None, poses=None, names: Sequence[str] | None = None, **settings) -> MappingResult:
    """Maps a survey: a path (a folder of uos, PCD, PLY, KITTI, LAS/LAZ scans, or an E57 file) or a
    list of (N, 3) arrays (in `unit`, default m; `poses`: initial 4x4 T_world_scan each, `names`).
    With `out`, writes what `minemap map SURVEY --out OUT` writes, the same files bit for bit (and
    map.laz). Settings: every `minemap map` option (minemap.options()), e.g. mode="simultaneous"."""
    out = None if out is None else os.fspath(out)
    if isinstance(survey, (str, os.PathLike)):
        if poses is not None or names is not None:
            raise ValueError("poses and names go with scans given as arrays; a survey folder has its own "
                             "(initial_poses=FILE gives others)")
        args = _option_args({"quiet": True, **settings}, "map_survey")
        d = _core.map_survey(os.fspath(survey), None, None, None, "m", args, out)
    else:
        unit = settings.pop("unit", None) or "m"
        args = _option_args({"quiet": True, **settings}, "map_survey")
        scans = list(survey)
        if poses is not None and len(poses) != len(scans):
            raise ValueError(f"poses: {len(poses)} poses for {len(scans)} scans")
        if names is not None and len(names) != len(scans):
            raise ValueError(f"names: {len(names)} names for {len(scans)} scans")
        d = _core.map_survey(None, scans, poses, None if names is None else list(names), unit, args, out)
    return _mapping_result(d)


def read_survey(path, **settings) -> Survey:
    """Reads a survey folder (or an E57 file) as `minemap map` reads it. Settings: unit,
    initial_poses, reference_poses, points_per_slice, no_slice_detection, right_handed_to_3dtk."""
    d = _core.read_survey(os.fspath(path), _option_args(settings, "read_survey"))
    scans = d["scans"]
    return Survey(format=d["format"], unit=d["unit"], origin=tuple(d["origin"]), names=[s["name"] for s in scans],
                  sources=[s["source"] for s in scans], points=[s["points"] for s in scans],
                  poses=np.stack([s["pose"] for s in scans]),
                  slice_offsets=[None if s["slice_offsets"] is None else np.asarray(s["slice_offsets"], np.uint32)
                                 for s in scans],
                  truth=d["truth"], warnings=list(d["warnings"]))


def simulate(out, *, scans: int | None = None, seed: int | None = None, loop: float | None = None,
             step_m: float | None = None, control: int | None = None, control_targets: int | None = None,
             control_blunder_m: float | None = None) -> Path:
    """Writes the built-in simulated mine survey (uos, with truth/) into `out`, as `minemap simulate`
    (its defaults: the whole 250 m drive, seed 1, straight, 4 m steps); `control` stations and
    `control_targets` targets write out/control.txt and out/control_truth.tum. Returns `out`."""
    args = ["simulate", "--out", os.fspath(out)]
    for name, value in (("--scans", scans), ("--seed", seed), ("--loop", loop), ("--step-m", step_m),
                        ("--control", control), ("--control-targets", control_targets),
                        ("--control-blunder-m", control_blunder_m)):
        if value is not None:
            args += [name, str(value)]
    code = _core.run_cli(args)
    if code != 0:
        raise RuntimeError(f"minemap simulate exited {code}")
    return Path(out)


# ---- the outputs the C++ core leaves to the package: map.laz, and the poses back into E57 -------------

def _to_right_handed_z_up(points: np.ndarray) -> np.ndarray:
    """3DTK's left-handed frame (x right, y up, z forward) to x forward, y left, z up."""
    return np.stack([points[:, 2], -points[:, 0], points[:, 1]], axis=1)


def _write_extra_outputs(out_dir: str, run: dict) -> None:
    """Called by the command line (and map_survey with out) after its own outputs, signals blocked:
    map.laz (metres, right-handed z up, LAS offset = the survey's origin: georeferenced surveys come
    back in their own coordinates), and for E57 surveys each source file with its scans' registered
    poses (OUT/<file name>.e57)."""
    out = Path(out_dir)
    metres_per_unit = 0.01 if run["unit"] == "cm" else 1.0
    points = run["map_points"] * metres_per_unit
    origin = np.asarray(run["origin"], dtype=np.float64) * metres_per_unit
    if run["frame"] == "3dtk":  # uos, or --right-handed-to-3dtk: the survey's reader says (io::Survey::frame_3dtk)
        points, origin = _to_right_handed_z_up(points), _to_right_handed_z_up(origin[None, :])[0]
    grid = crs.wkt(run["epsg"])
    formats.write_laz(out / "map.laz", points, unit="m", origin=origin, scan_index=run["map_scan_index"], wkt=grid)
    if run["format"] == "e57" and not run["interrupted"]:  # a partial run leaves the E57 alone
        by_file: dict[str, list[int]] = {}
        for i, source in enumerate(run["sources"]):
            by_file.setdefault(source.split("#", 1)[0], []).append(i)
        for path, indices in by_file.items():
            formats.write_e57_poses(path, out / Path(path).name, [run["poses"][i] for i in indices],
                                    origin=np.asarray(run["origin"], dtype=np.float64))


_core.set_foreign_survey_reader(formats.read_foreign_survey)
_core.set_extra_outputs(_write_extra_outputs)
_core.set_export_writer(exports.write)


def export(out, to, *, frame: str = "z-up", voxel_cm: float = 0.0, scans=None) -> dict:
    """Writes the registered survey of the finished map in `out` (its report.json) to the file `to`,
    every point of every scan with its attributes and scan index, as `minemap export OUT --to TO`:
    .ply, .las, .laz, .copc.laz or .e57. frame="z-up" (metres, right-handed, z up) or "survey" (the
    survey's own frame and unit); voxel_cm > 0 thins each scan; scans: names (default: every
    registered scan). Returns {"scans", "points", "attributes", "completed", "warnings"}."""
    return exports.export(out, to, frame=frame, voxel_cm=voxel_cm, scans=scans)
