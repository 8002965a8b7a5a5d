"""Batch processing of many scans on dask.distributed (``asrbf batch``).

One task per (file, seed): a worker receives the path, calls the same task function as
the single-file command (:mod:`asrbf_mesh.tasks`: ``fit`` / ``fill_holes`` / ``lod`` /
``compare``, with the options validated before any job was submitted) and writes
its outputs and a ``record.json`` into ``OUTDIR/<name>/``; only the small record comes
back through the scheduler, never a mesh. A file that fails is recorded with its one-line
error and the batch goes on. By default a local cluster of single-threaded worker
processes (numba, OpenMP and BLAS pinned to one thread each) runs the tasks; give
``scheduler="tcp://HOST:PORT"`` to use a running cluster.

At most one task per worker is in flight, so that a worker which has run
``tasks_per_worker`` tasks can be restarted (its native libraries' leaks dropped) before
it gets the next one; tasks are idempotent (outputs are written atomically), so a task
lost with a worker is simply run again.

Install with ``pip install 'asrbf-mesh[batch]'``.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ._atomic import atomic_path, check_output_dir
from ._io import SUPPORTED_SCAN_FORMATS
from ._validate import check_int, jsonable, strict_json
from ._validate import progress as progress_bar
from .errors import AsrbfError, ConfigError

__all__ = ["TASKS", "Job", "expand_inputs", "parse_seeds", "plan_jobs", "run_job",
           "run_batch", "summary_table"]

#: Tasks a batch can run, and the file or folder each writes in the job's folder.
TASKS = {"fit": "network.asrbf", "fill-holes": "filled.ply", "lod": "lod",
         "compare": "compare"}
#: Environment of the worker processes: one thread for every native library.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1"}


@dataclass(frozen=True)
class Job:
    """One task of a batch: a scan, a seed, where the outputs go, the task's options.

    ``options`` are keyword arguments of the task function (:mod:`asrbf_mesh.tasks`),
    as ``(name, value)`` pairs, already validated.
    """

    path: str
    task: str
    seed: int
    out_dir: str
    options: tuple[tuple[str, Any], ...] = field(default=())

    @property
    def record_path(self) -> Path:
        """The job's ``record.json``."""
        return Path(self.out_dir) / "record.json"

    @property
    def output(self) -> Path:
        """The file or folder the task writes."""
        return Path(self.out_dir) / TASKS[self.task]


# --------------------------------------------------------------------------- planning


def expand_inputs(inputs: Iterable[str]) -> list[Path]:
    """Files, folders (their scan files) and glob patterns to a sorted list of files.

    Raises
    ------
    AsrbfError
        An input that matches nothing.
    """
    import glob

    files: list[Path] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.iterdir()
                           if q.is_file() and q.suffix.lower() in SUPPORTED_SCAN_FORMATS)
            if not found:
                raise AsrbfError(f"{item}: no scan files in this folder "
                                 f"({', '.join(SUPPORTED_SCAN_FORMATS)})")
            files += found
        elif any(c in item for c in "*?["):
            found = sorted(Path(q) for q in glob.glob(item) if Path(q).is_file())
            if not found:
                raise AsrbfError(f"{item}: no file matches this pattern")
            files += found
        else:
            files.append(p)  # a missing file is the job's error, recorded like any other
    return list(dict.fromkeys(files))


def parse_seeds(text: str) -> list[int]:
    """``"0"``, ``"0,3,5"`` or ``"0-7"`` to a list of seeds.

    >>> parse_seeds("0-3"), parse_seeds("2,5")
    ([0, 1, 2, 3], [2, 5])
    """
    try:
        seeds: list[int] = []
        for part in text.split(","):
            a, _, b = part.strip().partition("-")
            seeds += list(range(int(a), int(b) + 1)) if b else [int(a)]
    except ValueError:
        raise ConfigError(f"seeds must look like 0, 0,3,5 or 0-7; got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"seeds must be non-negative integers; got {text!r}")
    return list(dict.fromkeys(seeds))


def plan_jobs(files: Sequence[Path], out_dir: Path, task: str, seeds: Sequence[int],
              options: Mapping[str, Any] | None = None) -> list[Job]:
    """One job per file and seed, each with its own output folder.

    A folder is named after the file's stem (``-s<seed>`` appended when several seeds
    run); stems that collide take their parent folder's name in front. ``options`` are
    keyword arguments of the task function, checked here with
    :func:`asrbf_mesh.tasks.check_options` (the batch sets the seed itself).

    Raises
    ------
    ConfigError
        An unknown task or a bad option: before any job runs.
    """
    from . import tasks

    if task not in TASKS:
        raise ConfigError(f"task must be one of {', '.join(TASKS)}; got {task!r}")
    options = dict(options or {})
    if "seed" in options:
        raise ConfigError("seed is set by the batch (seeds), not by the task options")
    tasks.check_options(task, **options)
    stems: dict[str, list[Path]] = {}
    for f in files:
        stems.setdefault(f.stem, []).append(f)
    names = {}
    for stem, group in stems.items():
        for f in group:
            names[f] = stem if len(group) == 1 else f"{f.parent.name}_{stem}"
    if len(set(names.values())) != len(names):
        twice = sorted({v for v in names.values() if list(names.values()).count(v) > 1})
        raise AsrbfError(f"{out_dir}: several inputs would write to {twice[0]}/: rename them "
                         "or run them in separate batches")
    return [Job(str(f), task, s, str(out_dir / (names[f] if len(seeds) == 1
                                              else f"{names[f]}-s{s}")),
                tuple(options.items()))
            for f in files for s in seeds]


# --------------------------------------------------------------------------- one job


def _pin_threads() -> None:
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)  # for libraries not loaded yet
    import numba

    numba.set_num_threads(1)  # numba may have started with more (an external worker)


def run_job(job: Job) -> dict[str, Any]:
    """Run one job (on a worker) and return its record, also written to ``record.json``.

    Never raises for a bad input: the record's ``status`` is ``"error"`` and ``error``
    the one-line message ``asrbf`` would print. ``result`` is the dict the task returns
    (what ``asrbf TASK --json`` prints).
    """
    from . import tasks

    _pin_threads()
    t0 = time.perf_counter()
    try:
        w = __import__("distributed").get_worker()
        worker, worker_name = w.address, w.name
    except (ImportError, ValueError):
        worker = worker_name = None
    import numba

    record: dict[str, Any] = {"input": job.path, "task": job.task, "seed": job.seed,
                              "out_dir": job.out_dir, "worker": worker,
                              "worker_name": worker_name, "pid": os.getpid(),
                              "numba_threads": numba.get_num_threads()}
    try:
        Path(job.out_dir).mkdir(parents=True, exist_ok=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a worker has no one to show them to
            result = tasks.COMMANDS[job.task](job.path, job.output, seed=job.seed,
                                              **dict(job.options))
        record |= {"status": "ok", "error": None, "result": jsonable(result),
                   "outputs": [str(job.output)]}
    except AsrbfError as exc:
        record |= {"status": "error", "error": tasks.error_line(exc), "result": None,
                   "outputs": []}
    except MemoryError:
        record |= {"status": "error", "error": "out of memory (the input is too large for "
                   "this machine; a fit needs about 120 bytes per point, see 'Memory of a "
                   "fit' in BENCHMARKS.md)", "result": None, "outputs": []}
    except Exception as exc:  # a failure of one file must not stop the batch
        first = str(exc).splitlines()[0] if str(exc) else ""
        record |= {"status": "error", "error": f"{type(exc).__name__}: {first}",
                   "result": None, "outputs": []}
    record["seconds"] = time.perf_counter() - t0
    try:
        with atomic_path(job.record_path) as tmp:
            tmp.write_text(strict_json(record, indent=1))
    except (AsrbfError, OSError):
        pass  # the record still reaches the summary
    return record


def _done(job: Job) -> dict[str, Any] | None:
    """Return the job's earlier record if it succeeded and its outputs still exist."""
    try:
        rec = json.loads(job.record_path.read_text())
    except (OSError, ValueError):
        return None
    if rec.get("status") != "ok" or not all(Path(p).exists() for p in rec.get("outputs", [])):
        return None
    return rec | {"skipped": True}


# --------------------------------------------------------------------------- the batch


@dataclass
class BatchResult:
    """Records of every job (in job order), restarts of workers, wall time."""

    records: list[dict[str, Any]]
    restarts: int
    seconds: float
    workers: int

    @property
    def failed(self) -> int:
        """Jobs whose status is ``"error"``."""
        return sum(r["status"] != "ok" for r in self.records)

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the records and the totals."""
        return asdict(self) | {"failed": self.failed, "files": len(self.records)}


def _cluster(workers: int, scheduler: str | None):
    """Return a client on the scheduler or on a new local cluster, and what to close."""
    try:
        import distributed
    except ImportError:
        raise AsrbfError("asrbf batch needs dask.distributed: "
                         "pip install 'asrbf-mesh[batch]'") from None
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except OSError as exc:
            raise AsrbfError(f"{scheduler}: cannot reach the dask scheduler "
                             f"({str(exc).splitlines()[0]})") from None
        return client, [client]
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None,
                                       env=dict(WORKER_ENV), silence_logs=40)
    client = distributed.Client(cluster)
    return client, [client, cluster]


def run_batch(jobs: Sequence[Job], *, workers: int = 2, scheduler: str | None = None,
              skip_existing: bool = False, tasks_per_worker: int = 50,
              progress: bool | None = None, client: Any = None) -> BatchResult:
    """Run jobs on a dask cluster, one task per job, and collect their records.

    Parameters
    ----------
    jobs : sequence of Job
        From :func:`plan_jobs`.
    workers : int
        Worker processes of the local cluster (ignored with ``scheduler``/``client``).
    scheduler : str, optional
        Address of a running dask scheduler, ``tcp://HOST:PORT``.
    skip_existing : bool
        Reuse the record of a job that succeeded before and whose outputs exist.
    tasks_per_worker : int
        Restart a worker after this many tasks.
    progress : bool, optional
        A progress bar over the jobs on stderr (default: on a terminal).
    client : distributed.Client, optional
        Use this client (and its cluster) instead of making one.

    Returns
    -------
    BatchResult
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers must be an integer >= 1, got {workers!r}")
    check_int(tasks_per_worker, "tasks_per_worker", 1)
    t0 = time.perf_counter()
    for parent in sorted({Path(j.out_dir).parent for j in jobs}):
        check_output_dir(parent)
    records: list[dict[str, Any] | None] = [_done(j) if skip_existing else None for j in jobs]
    todo = [i for i, r in enumerate(records) if r is None]
    bar = progress_bar(len(jobs), progress, "batch", unit="file", delay=0.0,
                       initial=len(jobs) - len(todo))
    restarts = 0
    closers: list[Any] = []
    if client is None and todo:
        client, closers = _cluster(workers, scheduler)
    try:
        if todo:
            restarts = _run(client, jobs, todo, records, tasks_per_worker, bar)
    finally:
        if bar is not None:
            bar.close()  # type: ignore[attr-defined]
        for c in closers:
            with contextlib.suppress(Exception):
                c.close()
    return BatchResult([r for r in records if r is not None], restarts,
                       time.perf_counter() - t0, workers if scheduler is None else 0)


def _run(client: Any, jobs: Sequence[Job], todo: list[int],
         records: list[dict[str, Any] | None], tasks_per_worker: int, bar: Any) -> int:
    """Run the jobs ``todo`` with one task in flight per worker; return the restarts."""
    from distributed import as_completed

    names = [w.get("name") for w in client.scheduler_info()["workers"].values()]
    n_workers = max(1, len(names))
    restarts = 0
    runs: dict[str, int] = {}
    pending = iter(todo)
    futures = {}
    for i in pending:
        # one first task per worker, by name: left to the scheduler, a busy machine could
        # queue two first tasks on one worker (one process running two tasks)
        name = names[len(futures)] if len(futures) < len(names) else None
        where = {} if name is None else {"workers": [name], "allow_other_workers": True}
        futures[client.submit(run_job, jobs[i], pure=False, **where)] = i
        if len(futures) >= n_workers:
            break
    queue = as_completed(list(futures))
    for fut in queue:
        i = futures.pop(fut)
        try:
            rec = fut.result()
        except Exception as exc:  # the worker died: record it, go on
            rec = {"input": jobs[i].path, "task": jobs[i].task, "seed": jobs[i].seed,
                   "out_dir": jobs[i].out_dir, "status": "error", "outputs": [],
                   "error": f"worker lost: {type(exc).__name__}: "
                            f"{str(exc).splitlines()[0] if str(exc) else ''}",
                   "result": None, "seconds": None, "worker": None, "worker_name": None}
        records[i] = rec
        if bar is not None:
            bar(1)
        addr, name = rec.get("worker"), rec.get("worker_name")
        nxt = next(pending, None)
        if addr is not None:
            runs[addr] = runs.get(addr, 0) + 1
            if runs[addr] >= tasks_per_worker and nxt is not None:
                with contextlib.suppress(Exception):  # a worker without a nanny stays
                    client.restart_workers([addr], timeout=60)
                    restarts += 1
                runs.pop(addr, None)
        if nxt is not None:
            # to the worker just freed (by name: a restarted worker keeps its name, not its
            # address), so that a worker due for a restart never picks up a task before it
            where = {} if name is None else {"workers": [name], "allow_other_workers": True}
            f = client.submit(run_job, jobs[nxt], pure=False, **where)
            futures[f] = nxt
            queue.add(f)
    return restarts


# --------------------------------------------------------------------------- summary


def _figures(rec: dict[str, Any]) -> str:
    res = rec.get("result") or {}
    if rec["task"] == "fit":
        return f"K {res.get('n_neurons', 0):,}, E̅ {res.get('ebar', float('nan')):.5f}"
    if rec["task"] == "compare":
        a, s = res.get("asrbf", {}), res.get("som", {})
        return f"RMS % ours {a.get('rms_pct', float('nan')):.3f}, SOM " \
               f"{s.get('rms_pct', float('nan')):.3f}"
    if rec["task"] == "fill-holes":
        return f"holes filled {res.get('holes_filled', 0)} of {res.get('holes_found', 0)}"
    return f"levels {len(res.get('levels', []))}" if isinstance(res, dict) else ""


def summary_table(result: BatchResult) -> str:
    """Return a Markdown table of the records: file, seed, status, seconds, figures."""
    rows = ["| file | seed | status | seconds | figures / error |", "|---|---|---|---|---|"]
    for r in result.records:
        status = "ok (skipped)" if r.get("skipped") else r["status"]
        secs = f"{r['seconds']:.1f}" if r.get("seconds") is not None else ""
        what = _figures(r) if r["status"] == "ok" else (r.get("error") or "")
        rows.append(f"| {r['input']} | {r['seed']} | {status} | {secs} | {what} |")
    ok = len(result.records) - result.failed
    rows.append("")
    rows.append(f"{ok} of {len(result.records)} ok, {result.failed} failed, "
                f"{result.restarts} worker restarts, {result.seconds:.1f} s")
    return "\n".join(rows)
