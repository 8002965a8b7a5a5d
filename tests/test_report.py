"""Comparison reports: ``evaluate.report.compare``, the written pages, ``asrbf compare``/``report``.

A short SOM (``som_iterations``) keeps these fast; the SOM's own quality is tested in
``test_som.py``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay

import asrbf_mesh as am
from asrbf_mesh.cli import main
from asrbf_mesh.errors import AsrbfError
from asrbf_mesh.evaluate._report import compare, load_compare, write_compare, write_summary

METRO = ("hausdorff", "mean", "rms", "hausdorff_pct", "mean_pct", "rms_pct", "n_samples")
SOM_STEPS = 3_000


@pytest.fixture(scope="module")
def franke_scan(franke_points: np.ndarray) -> am.Scan:
    return am.Scan(franke_points, faces=Delaunay(franke_points[:, :2]).simplices)


@pytest.fixture(scope="module")
def comparison(franke_scan: am.Scan, franke_net: am.Network):
    return compare(franke_scan, net=franke_net, name="franke", som_iterations=SOM_STEPS,
                   progress=False)


@pytest.fixture(scope="module")
def written(comparison, tmp_path_factory) -> tuple[Path, dict[str, Path]]:
    out = tmp_path_factory.mktemp("cmp") / "franke"
    return out, write_compare(comparison, out)


@pytest.fixture(scope="module")
def scan_file(tmp_path_factory, franke_scan: am.Scan) -> Path:
    path = tmp_path_factory.mktemp("scan") / "franke.ply"
    am.save_mesh(franke_scan.to_mesh(), path)
    return path


@pytest.fixture(scope="module")
def net_file(tmp_path_factory, franke_net: am.Network) -> Path:
    return franke_net.save(tmp_path_factory.mktemp("net") / "franke.asrbf")


def test_compare_summary_has_the_documented_keys(comparison, franke_net: am.Network) -> None:
    d = comparison.to_dict()
    assert d["scan"] == "franke"
    assert d["n_neurons"] == franke_net.n_neurons
    assert d["n_points"] == 3600
    rows, cols = d["som_shape"]
    assert d["som_nodes"] == rows * cols
    assert abs(d["som_nodes"] - franke_net.n_neurons) <= max(rows, cols)
    for key in ("asrbf", "som"):
        assert set(METRO) <= set(d[key])
        assert all(np.isfinite(d[key][k]) for k in METRO)
        assert d[key]["n_samples"] > 0 and d[key]["faces"] > 0
    # on a smooth, holeless surface the network is far more accurate than a short SOM
    assert d["asrbf"]["rms_pct"] < d["som"]["rms_pct"]
    assert "holes" not in d and "lod" not in d
    assert set(d["seconds"]) == {"fit", "som"}


def test_write_compare_writes_a_self_contained_page(written) -> None:
    out, paths = written
    assert {"json", "markdown", "html", "asrbf_mesh", "som_mesh"} <= set(paths)
    assert all(p.is_file() and p.stat().st_size > 0 for p in paths.values())
    page = paths["html"].read_text(encoding="utf-8")
    srcs = re.findall(r'src="([^"]*)"', page)
    assert len(srcs) == 2  # renders and error maps
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert "<table>" in page and "ASRBF (ours)" in page
    md = paths["markdown"].read_text(encoding="utf-8")
    for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md):
        assert (out / link).is_file()
    assert sorted(p.name for p in (out / "img").iterdir()) == ["error_maps.png", "renders.png"]
    assert not list(out.rglob("*.tmp*"))  # atomic writes leave no temporary files


def test_load_compare_round_trips(written, comparison) -> None:
    out, paths = written
    d = load_compare(out)
    assert d == load_compare(paths["json"])
    assert d["asrbf"] == pytest.approx(comparison.to_dict()["asrbf"])


@pytest.mark.parametrize("content", [None, "{", "[1, 2]", '{"scan": "x"}'])
def test_load_compare_rejects_what_is_not_a_comparison(tmp_path: Path, content) -> None:
    p = tmp_path / "compare.json"
    if content is not None:
        p.write_text(content)
    with pytest.raises(AsrbfError, match="compare.json"):
        load_compare(tmp_path)


def test_write_summary_averages_and_counts_wins(written, tmp_path: Path) -> None:
    d = load_compare(written[0])
    worse = json.loads(json.dumps(d))
    worse["scan"] = "swapped"
    worse["asrbf"], worse["som"] = d["som"], d["asrbf"]
    paths = write_summary([d, worse], tmp_path / "summary", links=["a/report.html", None])
    s = json.loads(paths["json"].read_text())
    assert s["ours_better_on_all"] == 1
    for k in ("hausdorff_pct", "mean_pct", "rms_pct"):
        want = (d["asrbf"][k] + d["som"][k]) / 2
        assert s["average"][f"asrbf_{k}"] == pytest.approx(want)
        assert s["average"][f"som_{k}"] == pytest.approx(want)
    md = paths["markdown"].read_text()
    assert "| average |" in md and "1/2" in md and "[franke](a/report.html)" in md
    assert 'href="a/report.html"' in paths["html"].read_text()
    with pytest.raises(AsrbfError, match="no comparison"):
        write_summary([], tmp_path / "empty")


def test_compare_rejects_a_scan_without_faces(franke_points: np.ndarray,
                                              franke_net: am.Network) -> None:
    with pytest.raises(AsrbfError, match="needs a scan with faces"):
        compare(am.Scan(franke_points), net=franke_net)


# ----------------------------------------------------------------------------- CLI


def test_cli_compare_json_and_report(capsys, scan_file: Path, net_file: Path,
                                     tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    code = main(["compare", str(scan_file), "-o", str(out), "--network", str(net_file),
                 "--som-iterations", str(SOM_STEPS), "--no-meshes", "--json"])
    stdout, err = capsys.readouterr()
    assert code == 0 and err == ""
    d = json.loads(stdout)
    assert {"n_neurons", "som_nodes", "asrbf", "som", "files"} <= set(d)
    for key in ("asrbf", "som"):
        assert set(METRO) <= set(d[key])
    assert d["n_neurons"] == am.Network.load(net_file).n_neurons
    assert not (out / "asrbf_bpa.ply").exists()  # --no-meshes
    assert Path(d["files"]["html"]).is_file()

    code = main(["report", str(out), "-o", str(tmp_path / "sum")])
    stdout, err = capsys.readouterr()
    assert code == 0 and err == ""
    assert "| franke |" in stdout and "wrote" in stdout
    assert (tmp_path / "sum" / "summary.html").is_file()


def test_cli_compare_text(capsys, scan_file: Path, net_file: Path, tmp_path: Path) -> None:
    code = main(["compare", str(scan_file), "-o", str(tmp_path / "c"), "--network",
                 str(net_file), "--som-iterations", "500", "--no-meshes"])
    stdout, _ = capsys.readouterr()
    assert code == 0
    assert "ASRBF" in stdout and "SOM" in stdout and "report.html" in stdout


@pytest.mark.parametrize(("argv", "match"), [
    (["compare", "{scan}", "-o", "{tmp}/c", "--som-iterations", "0"], "--som-iterations must be"),
    (["compare", "{points}", "-o", "{tmp}/c"], "needs a scan with faces"),
    (["compare", "{scan}", "-o", "{scan}"], "is not a folder"),
    (["report", "{tmp}/nothing", "-o", "{tmp}/s"], "no such file"),
])
def test_cli_compare_and_report_user_errors(capsys, scan_file: Path, net_file: Path,
                                            franke_points: np.ndarray, tmp_path: Path,
                                            argv: list[str], match: str) -> None:
    points = tmp_path / "points.npy"
    np.save(points, franke_points)
    argv = [a.format(scan=scan_file, points=points, tmp=tmp_path) for a in argv]
    if argv[0] == "compare":
        argv += ["--network", str(net_file)]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("asrbf: error: ")
    assert match in err
