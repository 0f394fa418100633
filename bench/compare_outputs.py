#!/usr/bin/env python3
"""Compares what two minemap builds write, file for file: the proof that a change which should
change no output (a redesign) changes none.

usage: bench/compare_outputs.py BASE_MINEMAP CANDIDATE_MINEMAP [--work DIR] [--cases REGEX]
                                [--shared DIR] [--keep]

Each case (a survey and the options of `minemap map`, or `minemap watch` fed the same survey) runs
once per program into WORK/<case>/{base,candidate}. Every file the base wrote must exist in the
candidate's folder with the same bytes; report.json is compared as JSON, where `timings_s` (wall
clocks) and `version` are left out, minemap.log without its version line and with wall times blanked, as are watch.json's match_s and times_s; a field only the candidate writes is listed as new, not as a difference.
A file only the candidate writes is listed as new; report.json's four settings that became options
(REPLACED) are listed as replaced. The surveys: the simulated drive (24 scans) in
the three presets on the CPU and on OpenCL (PoCL here), a loop survey (loops closed), the real
pairs of ../shared/data (fast_gicp_pair, mine_jinchuan_pcr; one unregistered), KITTI 07 and `watch` of the 24 scans.
Exit status 1 when any case differs. About 3 minutes on 2 cores.
"""
import argparse
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys


def cases(work, shared):
    sim24 = work / "surveys" / "sim24"
    loop = work / "surveys" / "loop80"
    surveys = {
        sim24: ["simulate", "--out", str(sim24), "--scans", "24"],
        loop: ["simulate", "--out", str(loop), "--loop", "80"],
    }
    out = []
    for preset in ("default", "simultaneous", "paper"):
        for backend in ("cpu", "opencl"):
            out.append((f"sim24-{preset}-{backend}", ["map", str(sim24), "--preset", preset, "--backend", backend]))
    out.append(("loop80-default-cpu", ["map", str(loop), "--backend", "cpu"]))
    out.append(("loop80-default-opencl", ["map", str(loop), "--backend", "opencl"]))
    out.append(("fast_gicp-default-cpu", ["map", str(shared / "fast_gicp_pair"), "--backend", "cpu"]))
    out.append(("jinchuan-default-cpu", ["map", str(shared / "mine_jinchuan_pcr"), "--backend", "cpu"]))
    out.append(("jinchuan-wide-cpu", ["map", str(shared / "mine_jinchuan_pcr"), "--backend", "cpu",
                                      "--max-pair-dist-cm", "200", "--accept-doubtful"]))
    out.append(("kitti07-default-cpu", ["map", str(shared / "kitti07_sequence"), "--backend", "cpu"]))
    out.append(("kitti07-graph-opencl", ["map", str(shared / "kitti07_sequence"), "--backend", "opencl",
                                         "--initial-poses", str(shared / "kitti07_sequence" / "graph.txt")]))
    out.append(("fast_gicp-unregistered-cpu", ["map", str(shared / "fast_gicp_pair"), "--backend", "cpu",
                                               "--max-pair-dist-cm", "0.5", "--write-unregistered"]))
    out.append(("sim24-pairwise-cpu", ["map", str(sim24), "--mode", "pairwise", "--backend", "cpu"]))
    out.append(("sim24-watch-cpu", ["watch", str(sim24), "--backend", "cpu", "--scans", "24", "--poll-ms", "10"]))
    return surveys, out


# report.json's settings before 2026-12 held 16 hand-picked values; since, every option under its
# keyword name. These four were derived values and are now the options they came from.
REPLACED = {"settings.accelerate": "settings.plain_icp", "settings.dense_models": "settings.sparse_models",
            "settings.filter": "settings.no_filter", "settings.refine_max_pair_dist_cm": "settings.refine_fraction"}

# Wall-clock fields of watch.json (each scan's match time, the stage times): they vary run to run.
WALL_CLOCK_KEYS = {"match_s", "times_s"}


def compare_json(base, candidate, path=""):
    """Differences between two JSON values; fields only in `candidate` are returned as new."""
    differences, new = [], []
    if isinstance(base, dict) and isinstance(candidate, dict):
        for key in base:
            if (path == "" and key in ("timings_s", "memory_mb", "version")) or key in WALL_CLOCK_KEYS:
                continue
            where = f"{path}.{key}" if path else key
            if key not in candidate:
                if where in REPLACED and REPLACED[where].split(".")[-1] in candidate:
                    new.append(f"{where} (replaced by {REPLACED[where]})")
                else:
                    differences.append(f"{where}: missing in the candidate")
                continue
            d, n = compare_json(base[key], candidate[key], where)
            differences += d
            new += n
        new += [f"{path}.{key}" if path else key for key in candidate if key not in base]
        return differences, new
    if isinstance(base, list) and isinstance(candidate, list) and len(base) == len(candidate):
        for i, (b, c) in enumerate(zip(base, candidate)):
            d, n = compare_json(b, c, f"{path}[{i}]")
            differences += d
            new += n
        return differences, new
    if base != candidate:
        differences.append(f"{path}: {json.dumps(base)[:80]} != {json.dumps(candidate)[:80]}")
    return differences, new


def normalised_log(text):
    """minemap.log without its first line (the build's version) and with wall times blanked."""
    lines = text.splitlines()[1:]
    return [re.sub(r"\d+(\.\d+)? s\b", "T s", line) for line in lines]


def run(program, args, cwd):
    return subprocess.run([program, *args], cwd=cwd, capture_output=True, text=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base")
    parser.add_argument("candidate")
    parser.add_argument("--work", default="out/compare-outputs")
    parser.add_argument("--cases", default=".")
    parser.add_argument("--shared", default=str(pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "data"))
    parser.add_argument("--keep", action="store_true", help="keep the output folders of equal cases")
    parser.add_argument("--verbose", action="store_true", help="list every new field")
    args = parser.parse_args()
    work = pathlib.Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    base, candidate = os.path.abspath(args.base), os.path.abspath(args.candidate)
    surveys, all_cases = cases(work, pathlib.Path(args.shared))
    for folder, simulate in surveys.items():
        if not folder.exists():
            subprocess.run([base, *simulate], check=True, capture_output=True)
    env_note = []
    failed = 0
    for name, map_args in all_cases:
        if not re.search(args.cases, name):
            continue
        folder = work / name
        shutil.rmtree(folder, ignore_errors=True)
        codes = {}
        for label, program in (("base", base), ("candidate", candidate)):
            # Both write to the same path (it is in report.json's command line and minemap.log),
            # then the folder is renamed.
            out = folder / "out"
            result = run(program, [*map_args, "--out", str(out)], work)
            codes[label] = result.returncode
            if out.exists():
                out.rename(folder / label)
        problems, new = [], []
        if codes["base"] != codes["candidate"]:
            problems.append(f"exit {codes['base']} != {codes['candidate']}")
        base_files = sorted(p.relative_to(folder / "base") for p in (folder / "base").rglob("*") if p.is_file())
        cand_files = sorted(p.relative_to(folder / "candidate") for p in (folder / "candidate").rglob("*")
                            if p.is_file())
        for rel in base_files:
            b, c = folder / "base" / rel, folder / "candidate" / rel
            if not c.exists():
                problems.append(f"{rel}: missing in the candidate")
            elif rel.name == "minemap.log":
                if normalised_log(b.read_text()) != normalised_log(c.read_text()):
                    problems.append(f"{rel}: lines differ (beyond the version and wall times)")
            elif rel.name in ("report.json", "watch.json"):
                d, n = compare_json(json.loads(b.read_text()), json.loads(c.read_text()))
                problems += [f"{rel}: {x}" for x in d]
                new += [f"{rel}: {x}" for x in n]
            elif b.read_bytes() != c.read_bytes():
                problems.append(f"{rel}: bytes differ")
        new += [f"{rel} (file)" for rel in cand_files if rel not in base_files]
        status = "same" if not problems else "DIFFERENT"
        if len(new) > 8 and not args.verbose:
            new = new[:4] + [f"... {len(new) - 4} more (--verbose lists them)"]
        print(f"{name}: {status} (exit {codes['base']}; {len(base_files)} files)"
              + (f"; new in the candidate: {', '.join(new)}" if new else ""))
        for p in problems[:20]:
            print(f"    {p}")
        if problems:
            failed += 1
        elif not args.keep:
            shutil.rmtree(folder)
    print("all cases give the same outputs" if failed == 0 else f"{failed} case(s) differ")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
