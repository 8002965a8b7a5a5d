"""Throughput of ``asrbf batch`` over 40 scans: 1 and 2 local workers, and an external cluster.

Run from the repository root:  python scripts/bench_batch.py [--seeds 0-7] [--task fit]

The face map and the four bunny scans, each with 8 seeds (40 jobs), plus one corrupt
file, through ``asrbf batch`` (a fresh output folder per run):

1. a local cluster of 1 worker, then of 2 workers (``--workers``);
2. a separately started ``dask scheduler`` and two ``dask worker`` processes (one
   thread each) on localhost, used with ``--scheduler``.

Each run must report the corrupt file and succeed on the 40 others. Writes the ``batch``
section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import BUNNIES, BUNNY_DIR, machine, table, write_section  # noqa: E402

import asrbf_mesh as am  # noqa: E402
from asrbf_mesh._batch import parse_seeds  # noqa: E402


def asrbf_batch(inputs: list[str], out: Path, extra: list[str]) -> tuple[dict, float]:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "batch", *inputs, "-o",
                           str(out), "--json", *extra], capture_output=True, text=True)
    secs = time.perf_counter() - t0
    if done.returncode not in (0, 1):
        raise SystemExit(f"asrbf batch failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return json.loads(done.stdout), secs


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--task", default="fit")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="asrbf-bench-batch-"))
    inputs = [str(am.face_map_path())] + [str(BUNNY_DIR / f"{b}.ply") for b in BUNNIES
                                          if (BUNNY_DIR / f"{b}.ply").exists()]
    corrupt = work / "corrupt.ply"
    corrupt.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\n"
                        b"property float x\nproperty float y\nproperty float z\nend_header\n"
                        + bytes(100))
    inputs.append(str(corrupt))
    common = ["--task", args.task, "--seeds", args.seeds]
    rows, runs = [], {}

    def record(label: str, summary: dict, secs: float, workers: int) -> None:
        recs = summary["records"]
        ok = [r for r in recs if r["status"] == "ok"]
        bad = [r for r in recs if r["status"] != "ok"]
        assert [r["input"] for r in bad] == [str(corrupt)] * len(bad), bad
        busy = sum(r["seconds"] for r in recs if r.get("seconds"))
        rows.append([label, workers, len(recs), len(ok), len(bad), f"{secs:.0f}",
                     f"{60 * len(recs) / secs:.1f}", f"{busy:.0f}", summary["restarts"]])
        runs[label] = {"seconds": secs, "files": len(recs), "ok": len(ok), "failed": len(bad),
                       "task_seconds": busy, "error": bad[0]["error"] if bad else None}
        print(label, rows[-1], flush=True)

    for w in (1, 2):
        out = work / f"local{w}"
        summary, secs = asrbf_batch(inputs, out, [*common, "--workers", str(w)])
        record(f"local cluster, {w} worker{'s' if w > 1 else ''}", summary, secs, w)

    # an external cluster: dask scheduler + 2 dask workers on localhost
    port = free_port()
    env = os.environ | {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                        "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    dask = str(Path(sys.executable).with_name("dask"))
    procs = [subprocess.Popen([dask, "scheduler", "--port", str(port), "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    time.sleep(3)
    procs.append(subprocess.Popen([dask, "worker", f"tcp://127.0.0.1:{port}", "--nworkers", "2",
                                   "--nthreads", "1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
    try:
        time.sleep(5)
        summary, secs = asrbf_batch(inputs, work / "external",
                                    [*common, "--scheduler", f"tcp://127.0.0.1:{port}"])
        record("external: dask scheduler + dask worker --nworkers 2", summary, secs, 2)
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=30)
    err = next(iter(runs.values()))["error"]
    n_seeds = len(parse_seeds(args.seeds))
    body = "\n".join([
        "## Batch processing on dask.distributed", "",
        f"`python scripts/bench_batch.py --seeds {args.seeds} --task {args.task}` "
        f"({machine()}). `asrbf batch --task {args.task}` over the face map and the four "
        f"bunny scans with seeds {args.seeds} ({len(inputs) - 1} files × {n_seeds} seeds = "
        f"{(len(inputs) - 1) * n_seeds} jobs) plus one corrupt PLY (× {n_seeds}); one thread "
        "per worker. Wall time includes starting the cluster (local runs) and every file's "
        "loading; *task s* sums the tasks' own times.", "",
        table(["run", "workers", "jobs", "ok", "failed", "wall s", "jobs / min", "task s",
               "worker restarts"], rows), "",
        f"Every run reported the corrupt file (\"{err}\") and finished the other jobs.",
    ])
    write_section("batch", body)
    print(body)
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
