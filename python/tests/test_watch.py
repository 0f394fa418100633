"""`minemap watch`: a survey fed into a folder scan by scan (as a robot writes them) is mapped as it
arrives, with complete outputs after each scan, and ends as `minemap map` of the same folder ends;
a restart resumes without matching again; scans out of order are refused."""
import json
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from conftest import cli_path, run_cli

SCANS = 6


def deliver(source: Path, target: Path, index: int):
    """Scan `index` as a scanner writes it: points first, then truth, then the pose file (which
    makes it complete: the rule `watch` documents)."""
    name = f"scan{index:03d}"
    (target / "truth").mkdir(parents=True, exist_ok=True)
    shutil.copy(source / f"{name}.3d", target / f"{name}.3d")
    shutil.copy(source / "truth" / f"{name}.pose", target / "truth" / f"{name}.pose")
    shutil.copy(source / f"{name}.pose", target / f"{name}.pose")


def scans_in(out: Path) -> int:
    """Scans in the outputs once both report.json and the state (written after it) show them."""
    try:
        counts = {len(json.loads((out / name).read_text())["scans"]) for name in ("report.json", "watch.json")}
        return counts.pop() if len(counts) == 1 else 0
    except (FileNotFoundError, json.JSONDecodeError, KeyError):
        return 0  # not written yet (each file is replaced atomically: never half-written)


def wait_for(condition, process, timeout_s=60.0):
    deadline = time.monotonic() + timeout_s
    while not condition():
        if process.poll() is not None:
            raise AssertionError(f"watch exited {process.returncode}: {process.stderr.read()}")
        if time.monotonic() > deadline:
            raise AssertionError("timed out waiting for watch")
        time.sleep(0.05)


def watch(survey: Path, out: Path, *args) -> subprocess.Popen:
    return subprocess.Popen([str(cli_path()), "watch", str(survey), "--out", str(out), "--threads", "2",
                             "--poll-ms", "50", *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def assert_same_as_map(survey: Path, live: Path, tmp_path: Path):
    """`minemap map` of the same folder writes the same files, bit for bit (report.json: but its times)."""
    offline = tmp_path / "offline"
    run_cli("map", survey, "--out", offline, "--threads", 2, "--quiet")
    for path in sorted(offline.iterdir()):
        if path.name == "minemap.log":  # the run's console output: times and paths differ
            continue
        if path.name == "report.json":
            a, b = (json.loads(p.read_text()) for p in (path, live / "report.json"))
            for key in ("timings_s", "memory_mb", "command_line", "run_options"):  # wall clocks; how each run was asked for
                a.pop(key), b.pop(key)
            assert a == b
        else:
            assert path.read_bytes() == (live / path.name).read_bytes(), path.name


def test_scans_fed_one_by_one_are_mapped_as_they_arrive(small_survey, tmp_path):
    survey, out = tmp_path / "survey", tmp_path / "live"
    survey.mkdir()
    process = watch(survey, out, "--scans", SCANS)
    try:
        for k in range(SCANS):
            deliver(small_survey, survey, k)
            if k + 1 < SCANS:
                # After each scan: a complete, consistent state with every scan so far.
                wait_for(lambda: scans_in(out) == k + 1, process)
                report = json.loads((out / "report.json").read_text())
                assert [s["name"] for s in report["scans"]] == [f"scan{i:03d}" for i in range(k + 1)]
                assert (out / f"scan{k:03d}.frames").exists() and (out / "map.ply").exists()
                assert len(json.loads((out / "watch.json").read_text())["scans"]) == k + 1
                assert not list(out.glob("*.tmp*"))
        stdout, stderr = process.communicate(timeout=120)
    finally:
        process.kill()
    assert process.returncode == 0, stderr
    assert "finishing the map of 6 scans" in stdout
    assert_same_as_map(survey, out, tmp_path)


def test_a_restart_resumes_without_matching_again(small_survey, tmp_path):
    survey, out = tmp_path / "survey", tmp_path / "live"
    shutil.copytree(small_survey, survey)
    first = run_cli("watch", survey, "--out", out, "--scans", 3, "--threads", 2)
    assert "scan002: read" in first.stdout and "scan003" not in first.stdout
    second = run_cli("watch", survey, "--out", out, "--scans", SCANS, "--threads", 2)
    assert "resumed from" in second.stdout and "3 scans matched before" in second.stdout
    assert "scan000: read" not in second.stdout and "scan003: read" in second.stdout
    assert_same_as_map(survey, out, tmp_path)
    # Other mapping options cannot continue this run.
    other = run_cli("watch", survey, "--out", out, "--voxel-cm", 20, "--scans", SCANS, check=False)
    assert other.returncode == 10 and "other mapping options" in other.stderr


def test_ctrl_c_finishes_the_map(small_survey, tmp_path):
    survey, out = tmp_path / "survey", tmp_path / "live"
    survey.mkdir()
    for k in range(3):
        deliver(small_survey, survey, k)
    process = watch(survey, out)
    try:
        wait_for(lambda: scans_in(out) == 3, process)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 0, stderr
    assert "finishing the map of 3 scans" in stdout
    assert_same_as_map(survey, out, tmp_path)


def test_a_scan_out_of_order_is_refused(small_survey, tmp_path):
    survey, out = tmp_path / "survey", tmp_path / "live"
    survey.mkdir()
    for k in (0, 1, 3):
        deliver(small_survey, survey, k)
    process = watch(survey, out)
    try:
        wait_for(lambda: scans_in(out) == 3, process)
        deliver(small_survey, survey, 2)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 10, stderr
    assert "scan002" in stderr and "arrived after scan003 was matched" in stderr
