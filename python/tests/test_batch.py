"""`minemap batch` on a real Dask LocalCluster: a worker killed mid-survey, bad input, resuming."""

import filecmp
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import default_sigint, run_cli
from distributed import Client, LocalCluster

from minemap.batch import batch, main

# The mapper batch runs. None: batch's default, `python -m minemap` (the installed package).
# A list, e.g. [os.environ["MINEMAP_CLI"]]: the C++ program itself (development).
COMMAND = None
MAPPER = COMMAND or [sys.executable, "-m", "minemap"]  # the same, run directly to compare
SCANS = 12  # about 1 s a map with one thread: time to kill a worker mid-survey
# Measured: the only keys of report.json that differ between two runs of one survey (wall clocks, and
# how each run was asked for).
VOLATILE = {"timings_s", "memory_mb", "command_line", "run_options"}


@pytest.fixture(scope="module")
def surveys(tmp_path_factory):
    """Four simulated surveys, and each mapped directly by the mapper batch runs."""
    root = tmp_path_factory.mktemp("batch")
    paths = []
    for seed in range(1, 5):
        path = root / "surveys" / f"mine{seed}"
        run_cli("simulate", "--out", path, "--scans", SCANS, "--seed", seed)
        subprocess.run([*MAPPER, "map", str(path), "--out", str(root / "direct" / path.name),
                        "--threads", "1", "--quiet"], check=True)
        paths.append(path)
    return paths


def assert_same_map(got, want):
    names = sorted(p.name for p in want.iterdir())
    assert sorted(p.name for p in got.iterdir()) == names
    for name in names:
        if name == "minemap.log":  # the run's console output: times and paths differ
            continue
        if name == "report.json":
            a, b = (json.loads((d / name).read_text()) for d in (got, want))
            assert {k: v for k, v in a.items() if k not in VOLATILE} == \
                   {k: v for k, v in b.items() if k not in VOLATILE}
        else:
            assert filecmp.cmp(got / name, want / name, shallow=False), name


def read(path):
    try:
        return path.read_bytes()
    except OSError:  # the process has gone
        return b""


def state(pid):
    """(state, parent pid) from /proc/PID/stat; a zombie or a process gone counts as dead"""
    fields = read(Path(f"/proc/{pid}/stat")).rsplit(b")", 1)[-1].split()
    return (fields[0].decode(), int(fields[1])) if fields and fields[0] != b"Z" else ("", 0)


def children(pid):
    return [int(p.name) for p in Path("/proc").glob("[0-9]*") if state(p.name)[1] == pid]


def alive(pid):
    return bool(state(pid)[0])


def test_worker_killed_mid_survey(surveys, tmp_path):
    out = tmp_path / "out"
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        result = {}
        runner = threading.Thread(target=lambda: result.update(batch(
            surveys, out, scheduler=cluster.scheduler_address, command=COMMAND,
            progress=False)))
        runner.start()
        # Kill a worker once its mapper runs: the nanny restarts it, Dask runs the task again.
        deadline = time.monotonic() + 60
        victim = None
        while victim is None and time.monotonic() < deadline:
            pids = client.run(os.getpid)
            for address, keys in client.processing().items():
                mappers = children(pids.get(address, -1)) if keys else []
                if mappers:
                    victim = pids[address], mappers[0]
                    break
            time.sleep(0.01)
        assert victim, "no mapper seen running"
        worker, mapper = victim
        # `map SURVEY`: the worker also holds a queued task, so the running one is named here.
        args = Path(f"/proc/{mapper}/cmdline").read_bytes().split(b"\0")
        running = Path(os.fsdecode(args[args.index(b"map") + 1])).name
        os.kill(worker, signal.SIGKILL)
        deadline = time.monotonic() + 10
        while alive(mapper) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(mapper), "the mapper outlived its worker"
        runner.join(timeout=150)
        assert not runner.is_alive()

    for survey in surveys:
        assert_same_map(out / survey.name, survey.parent.parent / "direct" / survey.name)
    assert not list(out.glob(".*tmp-*"))
    summary = json.loads((out / "batch.json").read_text())
    assert summary == result
    assert summary["totals"]["done"] == 4
    assert [r["status"] for r in summary["surveys"]] == ["done"] * 4
    killed = next(r for r in summary["surveys"] if Path(r["survey"]).name == running)
    assert killed["attempts"] >= 2


def test_bad_survey_fails_alone_and_rerun_skips_done(surveys, tmp_path, monkeypatch):
    if COMMAND:
        monkeypatch.setenv("MINEMAP_BATCH_COMMAND", " ".join(COMMAND))
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "scan000.3d").write_bytes(b"garbage\n1 2\n")
    out = tmp_path / "out"
    args = [str(surveys[0]), str(bad), str(surveys[1]), "--out", str(out), "--workers", "2",
            "--no-progress"]
    assert main(args) == 1
    summary = json.loads((out / "batch.json").read_text())
    assert [r["status"] for r in summary["surveys"]] == ["done", "failed", "done"]
    failed = summary["surveys"][1]
    assert failed["exit_code"] not in (0, 13, None) and failed["stderr"]
    assert f"exit code: {failed['exit_code']}" in (out / "bad.failed.txt").read_text()
    assert not (out / "bad").exists()
    mtimes = {s.name: (out / s.name / "report.json").stat().st_mtime_ns for s in surveys[:2]}

    assert main(args) == 1
    summary = json.loads((out / "batch.json").read_text())
    assert [r["status"] for r in summary["surveys"]] == ["skipped", "failed", "skipped"]
    assert mtimes == {s.name: (out / s.name / "report.json").stat().st_mtime_ns
                      for s in surveys[:2]}
    # All done: nothing to map, no cluster started.
    assert main([str(surveys[0]), str(surveys[1]), "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert summary["totals"]["skipped"] == 2 and summary["workers"] is None


def test_duplicate_names_refused_up_front(tmp_path, capsys):
    a, b = tmp_path / "a" / "mine", tmp_path / "b" / "mine"
    assert main([str(a), str(b), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert str(a) in err and str(b) in err
    assert not (tmp_path / "out").exists()


def test_survey_that_kills_its_worker_fails_after_retries(surveys, tmp_path):
    out = tmp_path / "out"
    # A mapper that kills its worker: Dask runs it again on a fresh one, then gives up.
    summary = batch(surveys[:1], out, workers=1, retries=1, progress=False,
                    command=["sh", "-c", "kill -9 $PPID", "sh"])
    [record] = summary["surveys"]
    assert record["status"] == "failed" and record["stderr"] == ["worker died 2 times"]
    assert "worker died 2 times" in (out / f"{surveys[0].name}.failed.txt").read_text()
    assert not list(out.glob(".*tmp-*"))


def test_ctrl_c_stops_everything_and_keeps_finished_surveys(surveys, tmp_path):
    out = tmp_path / "out"
    env = dict(os.environ, **({"MINEMAP_BATCH_COMMAND": " ".join(COMMAND)} if COMMAND else {}))
    # Its own process group, signalled whole as a terminal's Ctrl-C is: batch, workers, mappers.
    proc = subprocess.Popen([sys.executable, "-m", "minemap", "batch", *map(str, surveys),
                             "--out", str(out), "--workers", "2", "--no-progress"],
                            env=env, start_new_session=True, stderr=subprocess.DEVNULL, preexec_fn=default_sigint)
    deadline = time.monotonic() + 60
    while not (out.is_dir() and any((d / "report.json").exists() for d in out.iterdir())):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    summary = json.loads((out / "batch.json").read_text())
    assert summary["interrupted"] and summary["totals"]["interrupted"] >= 1, summary
    for record in summary["surveys"]:
        assert record["status"] in ("done", "interrupted"), summary
        assert (out / Path(record["survey"]).name / "report.json").exists() == \
               (record["status"] == "done"), summary
    assert not list(out.glob(".*tmp-*"))
    time.sleep(0.5)  # PDEATHSIG is delivered as the workers exit
    assert not [p for p in Path("/proc").glob("[0-9]*/cmdline")
                if str(out).encode() in read(p)], "a mapper outlived the batch"
