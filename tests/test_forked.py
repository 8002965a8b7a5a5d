"""Jobs on forked processes: the same results in the same order, or run here."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh import _forked
from asrbf_mesh._forked import map_forked

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"),
    reason="map_forked forks on Linux only: elsewhere it runs every job in this process")


def _square_plus(state: int, item: int) -> tuple[int, int]:
    return item * item + state, os.getpid()


def test_results_come_back_in_order_from_other_processes(monkeypatch) -> None:
    monkeypatch.setattr(_forked, "workers_available", lambda: 2)
    items = list(range(40))
    got = map_forked(_square_plus, 7, items, cost=[(i * 37) % 11 for i in items])
    assert [r[0] for r in got] == [i * i + 7 for i in items]
    assert {r[1] for r in got} - {os.getpid()}  # some ran elsewhere
    assert os.getpid() not in {r[1] for r in got}


def test_one_worker_or_few_items_run_here(monkeypatch) -> None:
    monkeypatch.setattr(_forked, "workers_available", lambda: 1)
    assert {r[1] for r in map_forked(_square_plus, 0, list(range(40)))} == {os.getpid()}
    monkeypatch.setattr(_forked, "workers_available", lambda: 4)
    assert {r[1] for r in map_forked(_square_plus, 0, list(range(5)))} == {os.getpid()}


_PARENT = os.getpid()


def _dies_elsewhere(state: None, item: int) -> int:
    if os.getpid() != _PARENT and item == 13:
        os._exit(3)  # a worker killed (a native crash, out of memory)
    return 2 * item


def test_a_dead_worker_leaves_its_jobs_to_this_process(monkeypatch) -> None:
    monkeypatch.setattr(_forked, "workers_available", lambda: 2)
    assert map_forked(_dies_elsewhere, None, list(range(30))) == [2 * i for i in range(30)]


def test_fill_holes_on_forked_processes_gives_the_same_bytes(monkeypatch) -> None:
    """Forty holes filled on two forked workers and here: the same mesh, bit for bit."""
    from _grids import height_grid

    pts, faces = height_grid(lambda x, y: 0.002 * (x - 40) ** 2 + 0.05 * y, 80, 60,
                             x=(0, 80), y=(0, 60), jitter=0.1, seed=3)
    keep = np.ones(len(pts), bool)
    for cx in np.arange(8, 80, 9.0):
        for cy in np.arange(8, 60, 11.0):
            keep &= np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) > 1.6
    faces = faces[keep[faces].all(axis=1)]
    used = np.unique(faces)
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    scan = am.Scan(pts[used], remap[faces])
    net = am.fit(scan, seed=0, progress=False)
    monkeypatch.setattr(_forked, "workers_available", lambda: 1)
    here = am.fill_holes(scan, net)
    monkeypatch.setattr(_forked, "workers_available", lambda: 2)
    forked = am.fill_holes(scan, net)
    assert here.holes_found >= 30 and here.holes_filled == here.holes_found
    assert np.array_equal(here.mesh.vertices, forked.mesh.vertices)
    assert np.array_equal(here.mesh.faces, forked.mesh.faces)
    assert here.to_dict()["holes"] == forked.to_dict()["holes"]


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (Linux's /proc)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_workers_end_with_a_killed_parent(tmp_path) -> None:
    """A parent killed mid-job (``timeout``, SIGKILL) left its forked workers running:
    one went on filling a hole for minutes on gigabytes. They now end with it."""
    import signal
    import subprocess
    import sys
    import textwrap
    import time

    pids = tmp_path / "pids"
    code = textwrap.dedent(f"""
        import os, time
        from asrbf_mesh import _forked
        _forked.workers_available = lambda: 2
        def job(state, item):
            with open({str(pids)!r}, "a") as f:
                f.write(f"{{os.getpid()}}\\n")
            time.sleep(60)
            return item
        _forked.map_forked(job, None, list(range(16)))
    """)
    parent = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (
                not pids.exists() or len(set(pids.read_text().split())) < 2):
            time.sleep(0.1)
        workers = {int(p) for p in pids.read_text().split()}
        assert len(workers) == 2 and parent.pid not in workers
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 10
    alive = workers
    while alive and time.monotonic() < deadline:
        alive = {p for p in alive if _running(p)}
        time.sleep(0.1)
    assert not alive
