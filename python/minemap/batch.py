"""`minemap batch`: map many surveys on a Dask distributed cluster, one survey per task.

Each task runs `minemap map SURVEY --out OUT/.NAME.tmp-UUID --threads T --quiet MAP_ARGS...` as a
subprocess and renames the folder to OUT/NAME when it succeeds, so OUT/NAME is either absent or
complete. The client, the scheduler and every worker must see the surveys and OUT under the same
paths (docs/scaling.md).
"""

import argparse
import ctypes
import glob
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid

from . import _core

# The program's exit codes, from the C++ table (cli/exit_codes.hpp): written once.
OK = _core.exit_codes["ok"]
INTERNAL = _core.exit_codes["internal"]  # batch: some survey failed
USAGE = _core.exit_codes["usage"]        # batch: bad arguments
DOUBTFUL = _core.exit_codes["doubtful_map"]  # mapped, but a match was judged doubtful; the outputs are written
INTERRUPTED = _core.exit_codes["interrupted"]
TAIL_LINES = 20    # lines of a failed mapper's stderr kept in batch.json and NAME.failed.txt

# Mappers running on this worker, by batch run: what `_stop` kills on Ctrl-C, since cancelling a
# future does not stop a task that has started; and the runs stopped, whose tasks start nothing.
_running = {}
_stopped = set()
_running_lock = threading.Lock()


class BatchArgumentError(ValueError):
    """Bad arguments to batch(), found before anything starts (`minemap batch` exits 2)."""


def _die_with_worker():
    """A preexec_fn: the mapper gets SIGKILL when the worker thread that started it dies, so a
    killed worker leaves no orphan writing into OUT. None where prctl does not exist (not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up here: no dlopen after fork
    parent = os.getpid()

    def preexec():
        prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the worker died before prctl took effect
            os.kill(os.getpid(), signal.SIGKILL)
    return preexec


def _write_atomic(path, text):
    tmp = f"{os.path.dirname(path)}/.{os.path.basename(path)}.tmp-{uuid.uuid4().hex}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def _remove_temps(out):
    for path in glob.glob(os.path.join(glob.escape(out), ".*.tmp-*")):
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path)
        else:
            os.unlink(path)


def _map_one(survey, out, threads, map_args, command, run):
    """One survey, run on a worker. Returns a record and raises only for a fault of the engine
    (filesystem, worker), never for a mapper failure: Dask would retry it, and bad input fails
    the same way every time."""
    name = os.path.basename(survey)
    final = os.path.join(out, name)
    # An attempt whose worker died left its temp folder (removed at the end of the batch).
    attempts = 1 + len(glob.glob(os.path.join(glob.escape(out), f".{glob.escape(name)}.tmp-*")))
    record = {"survey": survey, "status": "done", "exit_code": 0, "seconds": 0.0,
              "attempts": attempts, "host": socket.gethostname()}
    if os.path.lexists(final):
        if os.path.exists(os.path.join(final, "report.json")):
            return record  # an earlier attempt finished, and its worker died before reporting it
        return {**record, "status": "failed", "exit_code": None,
                "stderr": [f"{final} is there but holds no report.json: move it away"]}
    tmp = os.path.join(out, f".{name}.tmp-{uuid.uuid4().hex}")
    os.mkdir(tmp)
    # Resolved here, not on the client: the worker's Python is the one that has minemap.
    cmd = [*(command or [sys.executable, "-m", "minemap"]), "map", survey, "--out", tmp,
           "--threads", str(threads), "--quiet", *map_args]
    start = time.monotonic()
    try:
        try:
            proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, preexec_fn=_die_with_worker())
        except OSError as e:  # no such command: the same for every survey, not worth a retry
            return {**record, "status": "failed", "exit_code": 127, "stderr": [str(e)]}
        with _running_lock:
            if run in _stopped:
                proc.kill()
            _running.setdefault(run, set()).add(proc)
        try:
            err = proc.communicate()[1].decode(errors="replace").splitlines()
        finally:
            with _running_lock:
                _running.get(run, set()).discard(proc)
        code = proc.returncode
        if code < 0:  # the kernel's OOM killer, say: the mapper says nothing itself
            err.append(f"killed by signal {-code}")
        record.update(exit_code=code, seconds=round(time.monotonic() - start, 3),
                      stderr=err[-TAIL_LINES:])
        if code not in (OK, DOUBTFUL):
            record["status"] = "failed"
            return record
        record["status"] = "done" if code == OK else "doubtful"
        try:
            os.rename(tmp, final)
        except OSError:
            if not os.path.exists(os.path.join(final, "report.json")):
                raise  # OUT/NAME is there but not ours nor complete: let the user look
            # else another attempt of this survey got there first: its result stands
        return record
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _stop(run):
    """Run on every worker on Ctrl-C: kill this run's mappers."""
    with _running_lock:
        _stopped.add(run)
        for proc in _running.pop(run, ()):
            proc.kill()


def _progress(line, final=False):
    if sys.stderr.isatty():  # redraw one line; a log gets a line per finished survey
        sys.stderr.write("\r" + line + "\x1b[K" + ("\n" if final else ""))
    elif not final:
        sys.stderr.write(line + "\n")
    sys.stderr.flush()


def batch(surveys, out, *, scheduler=None, workers=None, threads_per_survey=1, map_args=(),
          retries=3, progress=True, command=None):
    """Map every survey folder into OUT/<folder name>/ and write OUT/batch.json; returns its dict.

    scheduler: a Dask scheduler address; None starts a LocalCluster of `workers` processes
    (default: cores // threads_per_survey) for this call. retries: how often a survey is tried
    again after its task raised (a filesystem fault) and, on the LocalCluster, after its worker
    died (distributed.scheduler.allowed-failures); an outside scheduler uses its own setting.
    command: the mapper, default `python -m minemap` on the worker (env MINEMAP_BATCH_COMMAND,
    split on whitespace, overrides the default). Raises BatchArgumentError (a ValueError) for two
    surveys of one name.
    """
    import dask
    from distributed import Client, KilledWorker, LocalCluster, as_completed

    started = time.monotonic()
    if threads_per_survey < 1 or (workers is not None and workers < 1) or retries < 0:
        raise BatchArgumentError("threads_per_survey and workers must be 1 or more, retries 0 or more")
    # Absolute: the workers' working folders are not ours.
    surveys = [os.path.abspath(s) for s in surveys]
    out = os.path.abspath(out)
    names = {}
    for s in surveys:
        other = names.setdefault(os.path.basename(s), s)
        if other != s:
            raise BatchArgumentError(f"two surveys named {os.path.basename(s)}: {other} and {s}")
    if command is None and os.environ.get("MINEMAP_BATCH_COMMAND"):
        command = os.environ["MINEMAP_BATCH_COMMAND"].split()
    os.makedirs(out, exist_ok=True)
    _remove_temps(out)  # left by a killed run; one batch per OUT at a time

    records = {}
    for s in surveys:
        if os.path.exists(os.path.join(out, os.path.basename(s), "report.json")):
            records[s] = {"survey": s, "status": "skipped", "exit_code": None, "seconds": 0.0}
    todo = [s for s in surveys if s not in records]

    def counts():
        n = {k: 0 for k in ("done", "skipped", "doubtful", "failed", "interrupted")}
        for r in records.values():
            n[r["status"]] += 1
        return n

    def show(last=None, final=False):
        if progress:
            n = counts()
            finished = n["done"] + n["skipped"] + n["doubtful"]
            tail = f" ({os.path.basename(last['survey'])}: {last['status']})" if last else ""
            _progress(f"batch: {finished}/{len(surveys)} done, {n['failed']} failed{tail}", final)

    cluster = client = n_workers = None
    interrupted = False
    run = uuid.uuid4().hex[:12]
    futures = {}
    try:
        if todo:
            if scheduler is None:
                cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
                    else os.cpu_count() or 1
                # Read when the scheduler starts. allowed-failures: a task whose worker died this
                # many times more is a KilledWorker error. A death counts against every task the
                # worker holds, queued ones too; saturation 1.0 gives a worker no more surveys
                # than threads (once surveys outnumber 2x the threads; fewer are all handed out).
                n_workers = workers or max(1, cores // threads_per_survey)
                with dask.config.set({"distributed.scheduler.allowed-failures": retries,
                                      "distributed.scheduler.worker-saturation": 1.0}):
                    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1,
                                           processes=True, dashboard_address=None)
                client = Client(cluster)
            else:
                client = Client(scheduler)
            # One map, not a submit each: the scheduler queues only a task group that it sees
            # whole. pure=False and keys unique to this run: a survey maps again in a new run.
            mapped = client.map(_map_one, todo, out=out, threads=threads_per_survey,
                                map_args=list(map_args), command=command, run=run,
                                key=[(f"minemap-map-{run}", os.path.basename(s)) for s in todo],
                                retries=retries, pure=False)
            futures = {f.key: (s, f) for s, f in zip(todo, mapped)}
        show()
        for f in as_completed([f for _, f in futures.values()]) if futures else ():
            s = futures[f.key][0]  # dropped once recorded: Ctrl-C may come in between
            try:
                r = f.result()
            except KilledWorker as e:
                n = e.allowed_failures + 1
                r = {"survey": s, "status": "failed", "exit_code": None,
                     "stderr": [f"worker died {n} times"]}
            except Exception as e:  # the engine's fault after its retries: report it, go on
                r = {"survey": s, "status": "failed", "exit_code": None,
                     "stderr": [f"{type(e).__name__}: {e}"]}
            records[s] = r
            del futures[f.key]
            f.release()  # a result held on a worker would be recomputed if that worker died
            failed = os.path.join(out, os.path.basename(s) + ".failed.txt")
            if r["status"] == "failed":
                _write_atomic(failed, f"{s}\nexit code: {r['exit_code']}\n"
                              + "".join(line + "\n" for line in r.get("stderr", [])))
            elif os.path.exists(failed):
                os.unlink(failed)
            show(r)
    except KeyboardInterrupt:
        interrupted = True
        if client is not None:
            client.cancel([f for _, f in futures.values()], force=True)
            try:
                client.run(_stop, run, on_error="ignore")
            except Exception:
                pass  # the cluster is going down anyway; PDEATHSIG covers its workers
        for s, _ in futures.values():
            records[s] = {"survey": s, "status": "interrupted", "exit_code": None}
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    for s in surveys:  # finished as Ctrl-C came, its result not yet here: it is complete
        if records[s]["status"] == "interrupted" and \
                os.path.exists(os.path.join(out, os.path.basename(s), "report.json")):
            records[s] = {"survey": s, "status": "done", "exit_code": None}
    show(final=True)
    _remove_temps(out)  # of attempts whose worker died, or that Ctrl-C killed

    summary = {"out": out, "scheduler": scheduler or "LocalCluster",
               "workers": n_workers,
               "threads_per_survey": threads_per_survey, "map_args": list(map_args),
               "surveys": [records[s] for s in surveys], "totals": counts(),
               "wall_s": round(time.monotonic() - started, 3), "interrupted": interrupted}
    _write_atomic(os.path.join(out, "batch.json"), json.dumps(summary, indent=1) + "\n")
    return summary


def exit_code(summary):
    n = summary["totals"]
    if summary["interrupted"]:
        return INTERRUPTED
    if n["failed"]:
        return INTERNAL
    return DOUBTFUL if n["doubtful"] else OK


def main(argv):
    """`minemap batch SURVEYS... --out OUT [...] [-- MAP OPTIONS...]`; returns the exit code."""
    argv = list(argv)
    map_args = []
    if "--" in argv:  # split before argparse, which would take what follows as surveys
        i = argv.index("--")
        argv, map_args = argv[:i], argv[i + 1:]
    parser = argparse.ArgumentParser(
        prog="minemap batch", formatter_class=argparse.RawDescriptionHelpFormatter,
        usage="minemap batch SURVEY... --out OUT [options] [-- MAP OPTIONS...]",
        description="Map many surveys on a Dask cluster, one survey per task, each into\n"
                    "OUT/<survey folder name>/. Everything after -- goes to `minemap map`.",
        epilog="OUT/batch.json lists every survey: done, skipped (OUT/NAME/report.json was "
               f"there),\ndoubtful (mapped, exit {DOUBTFUL}), failed (its exit code and stderr, also in "
               "OUT/NAME.failed.txt).\nRunning the same command again maps only what is not "
               f"done.\n\nexit status: {OK} every survey done or skipped; {DOUBTFUL} some doubtful, none "
               f"failed;\n{INTERNAL} some failed; {USAGE} bad arguments; {INTERRUPTED} interrupted.\n\nexample:\n"
               "  minemap batch surveys/* --out maps --scheduler tcp://head:8786 -- --preset paper")
    parser.add_argument("surveys", nargs="+", metavar="SURVEY", help="survey folders")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="Dask scheduler, e.g. tcp://head:8786; its workers must see the "
                             "surveys and OUT under the same paths (default: a local cluster)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="local cluster: worker processes (default: cores // threads)")
    parser.add_argument("--threads-per-survey", type=int, default=1, metavar="N",
                        help="`minemap map --threads` of each survey (default 1)")
    parser.add_argument("--retries", type=int, default=3, metavar="N",
                        help="tries again after a worker died (local cluster; an outside "
                             "scheduler uses its allowed-failures) or a task raised (default 3)")
    parser.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, or bad arguments
        return e.code
    try:
        summary = batch(args.surveys, args.out, scheduler=args.scheduler, workers=args.workers,
                        threads_per_survey=args.threads_per_survey, map_args=map_args,
                        retries=args.retries, progress=not args.no_progress)
    except BatchArgumentError as e:
        print(f"minemap batch: {e}", file=sys.stderr)
        return USAGE
    except KeyboardInterrupt:  # before any survey started
        return INTERRUPTED
    for r in summary["surveys"]:
        if r["status"] in ("failed", "doubtful"):
            print(f"minemap batch: {r['status']}: {r['survey']} (exit code {r['exit_code']})",
                  file=sys.stderr)
    return exit_code(summary)
