"""asrbf batch on dask.distributed: records, failures, reruns, worker recycling, tasks."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _grids import height_grid

import asrbf_mesh as am
from asrbf_mesh._batch import (
    Job,
    expand_inputs,
    parse_seeds,
    plan_jobs,
    run_batch,
    summary_table,
)
from asrbf_mesh.errors import AsrbfError, ConfigError

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40,
                                       env={"NUMBA_NUM_THREADS": "1"})
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("batch_in")
    out = {}
    for i in range(3):
        rng = np.random.default_rng(i)
        xy = rng.random((1500, 2)) * 40
        out[f"s{i}"] = d / f"s{i}.npy"
        np.save(out[f"s{i}"], np.c_[xy, 2 * np.sin(xy[:, 0] / 6) + 0.1 * xy[:, 1]])
    out["bad"] = d / "bad.xyz"
    out["bad"].write_text("1 2 3\nfoo bar baz\n")
    # a small range grid with a hole, as a mesh: for fill-holes, lod and compare
    g = 36
    yy, xx = np.mgrid[0:g, 0:g].astype(float)
    keep = (xx - 18) ** 2 + (yy - 17) ** 2 > 16
    mesh = am.Mesh(*height_grid(lambda x, y: 3 * np.sin(x / 7) * np.cos(y / 9), g, g,
                                x=(0, g - 1), y=(0, g - 1), valid=keep))
    out["grid"] = d / "grid.ply"
    am.save_mesh(mesh, out["grid"])
    return out


# ----------------------------------------------------------------------------- planning


def test_parse_seeds() -> None:
    assert parse_seeds("0") == [0]
    assert parse_seeds("0-3") == [0, 1, 2, 3]
    assert parse_seeds("5, 2,5") == [5, 2]
    for bad in ("", "a", "3-x", "-1"):
        with pytest.raises(ConfigError, match="seeds"):
            parse_seeds(bad)


def test_plan_jobs_names_folders_by_stem_seed_and_parent(tmp_path: Path) -> None:
    a, b = tmp_path / "x" / "scan.ply", tmp_path / "y" / "scan.ply"
    c = tmp_path / "x" / "other.npy"
    jobs = plan_jobs([a, b, c], tmp_path / "out", "fit", [0])
    assert [Path(j.out_dir).name for j in jobs] == ["x_scan", "y_scan", "other"]
    jobs = plan_jobs([c], tmp_path / "out", "lod", [1, 2], {"levels": 2})
    assert [Path(j.out_dir).name for j in jobs] == ["other-s1", "other-s2"]
    assert jobs[0].output == tmp_path / "out" / "other-s1" / "lod"
    assert (jobs[0].seed, jobs[0].options) == (1, (("levels", 2),))
    with pytest.raises(AsrbfError, match="several inputs would write to"):
        plan_jobs([tmp_path / "x" / "s.ply", tmp_path / "x" / "s.npy"], tmp_path, "fit", [0])
    with pytest.raises(ConfigError, match="task must be one of"):
        plan_jobs([a], tmp_path, "paint", [0])
    with pytest.raises(ConfigError, match="levels must be an integer in"):
        plan_jobs([a], tmp_path, "lod", [0], {"levels": 0})
    with pytest.raises(ConfigError, match="no_such is not an option of lod"):
        plan_jobs([a], tmp_path, "lod", [0], {"no_such": 3})
    with pytest.raises(ConfigError, match="seed is set by the batch"):
        plan_jobs([a], tmp_path, "fit", [0], {"seed": 3})


def test_expand_inputs(scans: dict[str, Path]) -> None:
    folder = scans["s0"].parent
    assert expand_inputs([str(folder)]) == sorted(
        p for p in folder.iterdir() if p.suffix in (".npy", ".xyz", ".ply"))
    assert expand_inputs([str(folder / "s*.npy")]) == [scans[f"s{i}"] for i in range(3)]
    assert expand_inputs(["missing.ply"]) == [Path("missing.ply")]  # the job records it
    with pytest.raises(AsrbfError, match="no file matches"):
        expand_inputs([str(folder / "*.stl")])


# ----------------------------------------------------------------------------- running


def test_a_corrupt_file_is_recorded_and_the_others_succeed(client, scans, tmp_path) -> None:
    files = [scans["s0"], scans["bad"], scans["s1"], scans["s2"]]
    jobs = plan_jobs(files, tmp_path, "fit", [0])
    res = run_batch(jobs, client=client, progress=False)
    assert [r["status"] for r in res.records] == ["ok", "error", "ok", "ok"]
    assert res.failed == 1
    bad = res.records[1]
    assert bad["error"] == f"{scans['bad']}: cannot read XYZ: line 2: 'foo' is not a number"
    for r, job in zip(res.records, jobs, strict=True):
        assert json.loads(job.record_path.read_text())["status"] == r["status"]
        assert r["numba_threads"] == 1
    assert Path(res.records[0]["outputs"][0]).exists()
    assert res.records[0]["result"]["n_neurons"] > 0
    table = summary_table(res)
    assert "3 of 4 ok, 1 failed" in table and "is not a number" in table

    # a rerun with skip_existing does only what is missing
    again = run_batch(jobs, client=client, progress=False, skip_existing=True)
    assert [bool(r.get("skipped")) for r in again.records] == [True, False, True, True]
    assert again.records[1]["status"] == "error"
    # an output removed is redone
    Path(res.records[2]["outputs"][0]).unlink()
    third = run_batch(jobs, client=client, progress=False, skip_existing=True)
    assert [bool(r.get("skipped")) for r in third.records] == [True, False, False, True]
    assert third.records[2]["status"] == "ok"


def test_workers_are_recycled(client, scans, tmp_path) -> None:
    jobs = plan_jobs([scans["s0"]], tmp_path, "fit", [0, 1, 2, 3])
    res = run_batch(jobs, client=client, progress=False, tasks_per_worker=1)
    assert res.failed == 0
    assert res.restarts == 2  # two workers, restarted once each before more work
    pids = {r["pid"] for r in res.records}
    assert len(pids) == 4  # every task ran in a fresh process


def test_batch_output_equals_the_single_command(client, scans, tmp_path) -> None:
    jobs = plan_jobs([scans["s1"]], tmp_path / "b", "fit", [4])
    rec = run_batch(jobs, client=client, progress=False).records[0]
    single = tmp_path / "single.asrbf"
    from asrbf_mesh import cli

    assert cli.main(["fit", str(scans["s1"]), "-o", str(single), "--seed", "4",
                        "--json"]) == 0
    assert Path(rec["outputs"][0]).read_bytes() == single.read_bytes()


@pytest.mark.parametrize(("task", "options", "key"), [
    ("fill-holes", {}, "holes_filled"),
    ("lod", {"levels": 2, "metro": False}, "levels"),
    ("compare", {"som_iterations": 3000, "meshes": False, "progress": False}, "som"),
])
def test_every_task_runs(client, scans, tmp_path, task: str, options: list, key: str) -> None:
    jobs = plan_jobs([scans["grid"]], tmp_path, task, [0], options)
    rec = run_batch(jobs, client=client, progress=False).records[0]
    assert rec["status"] == "ok", rec["error"]
    assert key in rec["result"]
    assert Path(rec["outputs"][0]).exists()


def test_run_batch_rejects_bad_options(scans, tmp_path) -> None:
    jobs = [Job(str(scans["s0"]), "fit", 0, str(tmp_path / "j"))]
    with pytest.raises(ConfigError, match="workers"):
        run_batch(jobs, workers=0)
    with pytest.raises(ConfigError, match="tasks_per_worker"):
        run_batch(jobs, tasks_per_worker=0)


def test_cli_batch(scans, tmp_path) -> None:
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "batch", str(scans["s0"]),
                           str(scans["bad"]), "-o", str(out), "--workers", "1", "--json"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr  # one file failed
    summary = json.loads(done.stdout)
    assert summary["files"] == 2 and summary["failed"] == 1
    assert json.loads((out / "summary.json").read_text())["failed"] == 1
    assert "1 of 2 ok, 1 failed" in (out / "summary.md").read_text()
    bad = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "batch", str(scans["s0"]),
                          "-o", str(out), "--seeds", "x"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2
    assert bad.stderr.strip() == "asrbf: error: --seeds must look like 0, 0,3,5 or 0-7; got 'x'"


@pytest.mark.parametrize(("task", "options", "message"), [
    ("lod", "--no-such-option 3", "--task-options: unrecognized arguments: --no-such-option 3"),
    ("lod", "--levels abc", "--task-options: argument --levels: invalid int value: 'abc'"),
    ("lod", "--levels 0", "levels must be an integer in [1, 12], got 0"),
    ("fit", "--seed 3", "unrecognized arguments: --seed 3"),
    ("fit", "--chunk 8192", "chunk applies to a streamed fit only"),
    ("compare", "--lod '", "--task-options: No closing quotation"),
])
def test_cli_batch_refuses_bad_task_options_at_once(scans, tmp_path, task: str, options: str,
                                                    message: str) -> None:
    """Bad --task-options: one line and exit 2 before any cluster starts (was: 15 s, then
    "4 workers died")."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "batch", str(scans["grid"]),
                           "-o", str(tmp_path / "out"), "--task", task, "--task-options",
                           options], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("asrbf: error: "), done.stderr
    assert message in lines[0]
    assert not (tmp_path / "out").exists()
    assert time.perf_counter() - t0 < 30  # the interpreter's start; no job ran


def test_task_options_become_task_keywords() -> None:
    from asrbf_mesh.cli import task_options

    assert task_options("lod", "--levels 3 --no-metro --compare-qem") == {
        "levels": 3, "method": "resample", "compare_qem": True, "metro": False,
        "fill_holes": False, "pieces": "auto"}
    fit = task_options("fit", "--passes 2 --update gd")
    assert fit["passes"] == 2 and fit["update"] == "gd" and fit["progress"] is False
    assert task_options("compare", "")["meshes"] is True
