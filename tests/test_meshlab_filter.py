"""meshlab_filter: asrbf filters on pymeshlab.MeshSet, discovery, binding, scripts."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
from _grids import mm_grid

import asrbf_mesh as am
import meshlab_filter as mf
from asrbf_mesh.errors import AsrbfError
from meshlab_filter._bridge import NetworkCache, layer_scan

NX, NY = 41, 31  # a 2 mm grid over x in [100, 180], y in [20, 80]
BIG, SMALL = ((130.0, 50.0), 6.0), ((160.0, 40.0), 4.0)  # hole centre and radius, mm
BIG_PCT, SMALL_PCT = 16.65, 11.10  # the holes' sizes in % of the scan's diagonal
ALL = mf.filter_list()


def bump(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.exp(-((u - 0.45) ** 2 + (v - 0.55) ** 2) / 0.15**2)


def bump_arrays(holes=(BIG, SMALL)) -> tuple[np.ndarray, np.ndarray]:
    """A gridded bump in mm (z = 5 + 20 bump) with the faces of round holes removed."""
    pts, faces = mm_grid(bump, NX, NY)
    centroid = pts[faces].mean(axis=1)[:, :2]
    keep = np.ones(len(faces), dtype=bool)
    for centre, radius in holes:
        keep &= np.linalg.norm(centroid - centre, axis=1) > radius
    return pts, faces[keep]


def new_ms(points_only: bool = False, label: str = "bump") -> pymeshlab.MeshSet:
    pts, faces = bump_arrays()
    ms = pymeshlab.MeshSet()
    mesh = (pymeshlab.Mesh(vertex_matrix=pts) if points_only
            else pymeshlab.Mesh(vertex_matrix=pts, face_matrix=faces.astype(np.int32)))
    ms.add_mesh(mesh, label)
    return ms


def labels(ms: pymeshlab.MeshSet) -> list[str]:
    return [ms.mesh(i).label() for i in range(ms.mesh_number())]


@pytest.fixture
def ms() -> pymeshlab.MeshSet:
    return new_ms()


@pytest.fixture
def registered():
    mf.register()
    yield
    mf.unregister()


def pymeshlab_message(call) -> str:
    with pytest.raises(Exception) as info:  # noqa: PT011 - any pymeshlab error, for its text
        call()
    return str(info.value)


# ----------------------------------------------------------------------------- discovery


def test_filter_list_names_follow_pymeshlab_prefixes_and_shadow_nothing() -> None:
    assert ALL == sorted(["generate_surface_reconstruction_asrbf", "meshing_close_holes_asrbf",
                          "generate_lod_set_asrbf",
                          "compute_scalar_by_asrbf_residual_per_vertex", "get_metro_distance"])
    prefixes = {name.split("_")[0] for name in pymeshlab.filter_list()}
    for name in ALL:
        assert name.split("_")[0] in prefixes
        assert name not in pymeshlab.filter_list()


@pytest.mark.parametrize("name", ALL)
def test_every_parameter_prints_with_type_default_and_description(name, capsys) -> None:
    mf.print_filter_parameter_list(name)
    out = capsys.readouterr().out
    assert out.startswith(f"{name} filter - list of parameter names:\n")
    spec = mf.FILTERS[name]
    for p in spec.params:
        assert f"\t{p.name} : {p.type_name} = {p.default_text}\n" in out
        first_words = " ".join(p.description.split()[:4])
        assert first_words in " ".join(out.split())
    assert spec.summary.split(":")[0] in (mf._filters._method(name).__doc__ or "")


def test_printed_types_and_defaults_read_like_pymeshlab(capsys) -> None:
    mf.print_filter_parameter_list("meshing_close_holes_asrbf")
    out = capsys.readouterr().out
    assert "\tmaxholesize : PercentageValue = 100%\n" in out
    assert "\tselected : bool = False\n" in out
    assert "\tviewaxis : str = 'z'\n" in out
    mf.print_filter_list()
    listed = capsys.readouterr().out.splitlines()
    assert [line.split(" : ")[0] for line in listed] == ALL


def test_discovery_passes_pymeshlab_filters_on(ms, capfd) -> None:
    mf.print_filter_parameter_list("meshing_close_holes")
    assert "maxholesize : int = 30" in capfd.readouterr().out
    assert (mf.filter_parameter_values(ms, "meshing_close_holes")
            == ms.filter_parameter_values("meshing_close_holes"))
    with pytest.raises(pymeshlab.PyMeshLabException, match="nope filter not found"):
        mf.print_filter_parameter_list("nope")


def test_filter_parameter_values_resolve_defaults_on_the_meshset(ms) -> None:
    diag = float(np.linalg.norm(np.ptp(bump_arrays()[0], axis=0)))
    vals = mf.filter_parameter_values(ms, "meshing_close_holes_asrbf")
    assert vals == {"maxholesize": pytest.approx(diag), "selected": False,
                    "newfaceselected": True, "seed": 0, "pieces": 0, "viewaxis": 0}
    ms.add_mesh(ms.current_mesh(), "copy")
    vals = mf.filter_parameter_values(ms, "get_metro_distance")
    assert vals["sampledmesh"] == 1 and vals["targetmesh"] == 0
    for name in ALL:
        assert set(mf.filter_parameter_values(ms, name)) == {
            p.name for p in mf.FILTERS[name].params}


# ----------------------------------------------------------------------------- errors


@pytest.mark.parametrize("name", ALL)
def test_unknown_parameter_has_pymeshlabs_wording(ms, name) -> None:
    theirs = pymeshlab_message(lambda: ms.apply_filter("meshing_close_holes", foo=1))
    with pytest.raises(pymeshlab.PyMeshLabException) as info:
        mf.apply_filter(ms, name, foo=1)
    assert str(info.value) == theirs.replace("meshing_close_holes", name)
    assert isinstance(info.value, AsrbfError)
    assert ms.mesh_number() == 1  # nothing ran


@pytest.mark.parametrize("name", ALL)
def test_empty_meshset_has_pymeshlabs_wording(name) -> None:
    empty = pymeshlab.MeshSet()
    theirs = pymeshlab_message(lambda: empty.apply_filter("meshing_close_holes"))
    with pytest.raises(pymeshlab.PyMeshLabException) as info:
        mf.apply_filter(empty, name)
    assert str(info.value) == theirs.replace("meshing_close_holes", name)
    with pytest.raises(pymeshlab.PyMeshLabException, match="requires at least one mesh"):
        mf.filter_parameter_values(empty, name)


def test_unknown_filter_is_pymeshlabs_error(ms) -> None:
    theirs = pymeshlab_message(lambda: ms.apply_filter("no_such_filter"))
    with pytest.raises(pymeshlab.PyMeshLabException) as info:
        mf.apply_filter(ms, "no_such_filter")
    assert str(info.value) == theirs


_BAD_TYPES = {"bool": "yes", "int": 1.5, "float": "x", "enum": 2.5, "length": 5.0, "mesh": "0"}
_WRONG_TYPES = [(name, p.name, _BAD_TYPES[p.kind]) for name in ALL
                for p in mf.FILTERS[name].params]


@pytest.mark.parametrize(("name", "param", "value"), _WRONG_TYPES)
def test_every_parameter_refuses_a_wrong_type(ms, name, param, value) -> None:
    with pytest.raises(pymeshlab.PyMeshLabException, match=f"^Parameter {param}: must be "):
        mf.apply_filter(ms, name, **{param: value})
    assert ms.mesh_number() == 1


def test_a_length_as_a_bare_number_has_pymeshlabs_wording(ms) -> None:
    theirs = pymeshlab_message(
        lambda: ms.generate_surface_reconstruction_ball_pivoting(ballradius=3.0))
    with pytest.raises(pymeshlab.PyMeshLabException) as info:
        mf.apply_filter(ms, "meshing_close_holes_asrbf", maxholesize=3.0)
    assert str(info.value) == theirs.replace("ballradius", "maxholesize")


@pytest.mark.parametrize(("name", "params", "match"), [
    ("generate_lod_set_asrbf", {"levels": 0}, "levels: must be >= 1, got 0"),
    ("generate_lod_set_asrbf", {"targetfacenum": -5}, r"targetfacenum: must be >= 1 \(or 0\)"),
    ("generate_surface_reconstruction_asrbf", {"resolution": 1}, "resolution: must be >= 2"),
    ("generate_surface_reconstruction_asrbf", {"margin": -0.1}, "margin: must be >= 0"),
    ("generate_surface_reconstruction_asrbf", {"margin": float("nan")}, "must be finite"),
    ("meshing_close_holes_asrbf", {"maxholesize": pymeshlab.PercentageValue(0)},
     "maxholesize: must be > 0, got '0%'"),
    ("meshing_close_holes_asrbf", {"maxholesize": pymeshlab.PureValue(-1.0)},
     "maxholesize: must be > 0, got -1.0"),
    ("compute_scalar_by_asrbf_residual_per_vertex", {"seed": -1}, "seed: must be >= 0"),
    ("get_metro_distance", {"samplenum": -1}, "samplenum: must be >= 1"),
    ("get_metro_distance", {"targetmesh": -1}, "targetmesh: must be >= 0, got -1"),
    ("get_metro_distance", {"targetmesh": 7}, "^Mesh ID 7 not found in MeshSet.$"),
    ("get_metro_distance", {"sampledmesh": 9}, "^Mesh ID 9 not found in MeshSet.$"),
])
def test_values_out_of_range_are_refused(ms, name, params, match) -> None:
    with pytest.raises(mf.MeshlabFilterError, match=match):
        mf.apply_filter(ms, name, **params)


def test_enums_take_a_name_or_an_index_like_pymeshlab(ms) -> None:
    with pytest.raises(pymeshlab.InvalidEnumException,
                       match="^Enum 'nope' not found. Possible values are 'surface'; "
                             "'footprint'; 'hull'; 'full'; ") as info:
        mf.apply_filter(ms, "generate_surface_reconstruction_asrbf", mode="nope")
    assert isinstance(info.value, pymeshlab.PyMeshLabException)
    with pytest.raises(mf.InvalidEnumError):
        mf.apply_filter(ms, "generate_lod_set_asrbf", method=5)
    mf.apply_filter(ms, "generate_surface_reconstruction_asrbf", mode=3, resolution=11)
    lo, hi = ms.current_mesh().vertex_matrix().min(0), ms.current_mesh().vertex_matrix().max(0)
    assert np.allclose([lo[0], lo[1], hi[0], hi[1]], [100, 20, 180, 80])  # 'full'


def test_a_failing_fit_is_one_line_and_names_the_filter() -> None:
    tiny = pymeshlab.MeshSet()
    tiny.add_mesh(pymeshlab.Mesh(vertex_matrix=np.eye(3) + 1.0,
                                 face_matrix=np.array([[0, 1, 2]], dtype=np.int32)))
    with pytest.raises(mf.MeshlabFilterError,
                       match=r"^Failed to apply filter: generate_lod_set_asrbf: a fit needs "
                             r"at least \d+ points, got 3$"):
        mf.apply_filter(tiny, "generate_lod_set_asrbf")


# ----------------------------------------------------------------------------- filters


def test_reconstruction_adds_the_network_surface_as_a_new_layer(ms) -> None:
    res = mf.apply_filter(ms, "generate_surface_reconstruction_asrbf")
    assert labels(ms) == ["bump", "bump (asrbf surface)"]
    assert ms.current_mesh_id() == res["mesh_id"] == 1
    m = ms.current_mesh()
    assert (m.vertex_number(), m.face_number()) == (res["vertices"], res["faces"])
    v = m.vertex_matrix()
    truth = 5 + 20 * bump((v[:, 0] - 100) / 80, (v[:, 1] - 20) / 60)
    assert np.abs(v[:, 2] - truth).max() < 0.5  # mm, on a 20 mm bump
    n = m.vertex_normal_matrix()
    assert (n[:, 2] > 0).all()  # facing the scanner
    assert ms.mesh(0).face_number() == len(bump_arrays()[1])  # the source is untouched


def test_reconstruction_modes_and_margin(ms) -> None:
    full = mf.apply_filter(ms, "generate_surface_reconstruction_asrbf", mode="full",
                           resolution=21, margin=0.25)
    v = ms.current_mesh().vertex_matrix()
    assert np.ptp(v[:, 0]) == pytest.approx(80 * 1.5)
    assert len(np.unique(np.round(v[:, 0], 6))) == 21  # the resolution counts the margin
    ms.set_current_mesh(0)
    hull = mf.apply_filter(ms, "generate_surface_reconstruction_asrbf", mode="hull",
                           resolution=21)
    ms.set_current_mesh(0)
    foot = mf.apply_filter(ms, "generate_surface_reconstruction_asrbf", resolution=21)
    assert foot["faces"] <= hull["faces"] <= full["faces"]
    assert mf.cache.info()["size"] >= 1


def test_reconstruction_of_a_point_set() -> None:
    cloud = new_ms(points_only=True)
    res = mf.apply_filter(cloud, "generate_surface_reconstruction_asrbf", resolution=30)
    assert res["faces"] > 1000 and cloud.current_mesh().face_number() == res["faces"]


def test_close_holes_fills_both_holes_in_a_new_layer(ms) -> None:
    pts, faces = bump_arrays()
    res = mf.apply_filter(ms, "meshing_close_holes_asrbf")
    assert res["closed_holes"] == res["holes_found"] == 2 and res["holes_skipped"] == []
    assert labels(ms) == ["bump", "bump (asrbf filled)"] and ms.current_mesh_id() == 1
    m = ms.current_mesh()
    v, f = m.vertex_matrix(), m.face_matrix()
    assert np.array_equal(v[: len(pts)], pts) and np.array_equal(f[: len(faces)], faces)
    assert (len(v) - len(pts), len(f) - len(faces)) == (res["new_vertices"], res["new_faces"])
    q = m.vertex_scalar_array()
    assert (q[len(pts):] == 1).all() and (q[: len(pts)] == 0).all()
    assert m.face_scalar_array().sum() == res["new_faces"]
    sel = m.face_selection_array()
    assert sel[len(faces):].all() and not sel[: len(faces)].any()
    truth = 5 + 20 * bump((v[len(pts):, 0] - 100) / 80, (v[len(pts):, 1] - 20) / 60)
    assert np.abs(v[len(pts):, 2] - truth).max() < 0.3  # mm
    # no hole left: every boundary edge lies on the outer border
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    rim = v[edges[count == 1]].reshape(-1, 3)
    on_border = (np.isclose(rim[:, 0], 100) | np.isclose(rim[:, 0], 180)
                 | np.isclose(rim[:, 1], 20) | np.isclose(rim[:, 1], 80))
    assert on_border.all()
    assert ms.mesh(0).face_number() == len(faces)  # the source is untouched


@pytest.mark.parametrize("size", [pymeshlab.PercentageValue(14), pymeshlab.PureValue(14.0)])
def test_close_holes_maxholesize_leaves_larger_holes_open(ms, size) -> None:
    res = mf.apply_filter(ms, "meshing_close_holes_asrbf", maxholesize=size,
                          newfaceselected=False)
    assert res["closed_holes"] == 1
    (skipped,) = res["holes_skipped"]
    assert skipped["size_pct"] == pytest.approx(BIG_PCT, abs=0.01)
    assert "larger than max_hole_size" in skipped["reason"]
    assert ms.current_mesh().selected_face_number() == 0


def test_close_holes_selected_only_fills_holes_with_a_selected_rim_face(ms) -> None:
    ms.compute_selection_by_condition_per_face(condselect="(x0 > 150) && (x0 < 170)")
    res = mf.apply_filter(ms, "meshing_close_holes_asrbf", selected=True)
    assert res["closed_holes"] == 1
    assert res["holes_skipped"][0]["reason"] == "no selected face on its rim (selected=True)"
    assert res["holes_skipped"][0]["size_pct"] == pytest.approx(BIG_PCT, abs=0.01)
    m = ms.current_mesh()
    new = m.vertex_matrix()[len(bump_arrays()[0]):]
    assert len(new) == res["new_vertices"] > 0
    assert np.linalg.norm(new[:, :2] - SMALL[0], axis=1).max() < SMALL[1] + 1
    assert m.vertex_scalar_array().sum() == res["new_vertices"]
    assert m.face_matrix().max() < m.vertex_number()


def test_close_holes_needs_faces() -> None:
    with pytest.raises(mf.MeshlabFilterError, match="has no faces"):
        mf.apply_filter(new_ms(points_only=True), "meshing_close_holes_asrbf")


def test_lod_set_adds_one_named_layer_per_level(ms) -> None:
    res = mf.apply_filter(ms, "generate_lod_set_asrbf", levels=3)
    assert labels(ms)[1:] == [f"bump (asrbf LOD {i})" for i in range(3)]
    assert res["mesh_ids"] == [1, 2, 3] and ms.current_mesh_id() == 3
    assert res["faces"][0] > res["faces"][1] > res["faces"][2]
    assert [ms.mesh(i).face_number() for i in res["mesh_ids"]] == res["faces"]


def test_lod_set_targetfacenum_and_refit(ms) -> None:
    res = mf.apply_filter(ms, "generate_lod_set_asrbf", levels=2, targetfacenum=1500)
    assert res["faces"][0] == pytest.approx(1500, rel=0.15)
    ms.set_current_mesh(0)
    res = mf.apply_filter(ms, "generate_lod_set_asrbf", levels=2, method="refit",
                          footprint=False, targetfacenum=800)
    assert res["faces"][0] == pytest.approx(800, rel=0.15) and res["faces"][1] < 800


def test_residual_is_vertex_quality_in_place(ms) -> None:
    pts, faces = bump_arrays()
    res = mf.apply_filter(ms, "compute_scalar_by_asrbf_residual_per_vertex")
    assert ms.mesh_number() == 1  # in place, like MeshLab's per-vertex quality filters
    net = am.fit(am.Scan(pts, faces), seed=0, progress=False)
    r = pts[:, 2] - net.evaluate(pts[:, :2])
    m = ms.current_mesh()
    assert np.allclose(m.vertex_scalar_array(), np.abs(r), rtol=0, atol=1e-12)
    assert np.allclose(m.vertex_custom_scalar_attribute_array("asrbf_residual"), r, atol=1e-12)
    assert res["max"] == pytest.approx(np.abs(r).max())
    assert res["RMS"] == pytest.approx(np.sqrt(np.mean(r**2)))
    # again, signed: the attribute exists already and is refreshed
    mf.apply_filter(ms, "compute_scalar_by_asrbf_residual_per_vertex", signed=True)
    assert np.allclose(ms.current_mesh().vertex_scalar_array(), r, atol=1e-12)
    assert (ms.current_mesh().vertex_scalar_array() < 0).any()


def test_residual_of_a_point_set_and_the_current_mesh_is_restored() -> None:
    cloud = new_ms(points_only=True)
    cloud.add_mesh(cloud.current_mesh(), "other", set_as_current=False)
    mf.apply_filter(cloud, "compute_scalar_by_asrbf_residual_per_vertex", viewaxis="pca")
    assert cloud.current_mesh_id() == 0
    assert cloud.mesh(0).has_vertex_scalar()
    assert cloud.mesh(0).vertex_scalar_array().max() < 1.0  # mm, on a 20 mm bump


def test_metro_returns_hausdorff_keys_and_asrbf_figures(ms) -> None:
    pts, faces = bump_arrays()
    moved = pts + [0.0, 0.0, 0.5]
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=moved, face_matrix=faces.astype(np.int32)),
                "moved")
    theirs = ms.get_hausdorff_distance(sampledmesh=1, targetmesh=0, samplenum=1000,
                                       maxdist=pymeshlab.PercentageValue(50),
                                       sampleface=True, samplevert=True, sampleedge=False,
                                       samplefauxedge=False, savesample=False)
    quality = ms.mesh(1).vertex_scalar_array().copy()
    ours = mf.apply_filter(ms, "get_metro_distance", samplenum=1000)  # current: "moved"
    assert list(ours) == sorted(theirs) and set(ours) == set(theirs)
    assert isinstance(ours["n_samples"], int)
    assert ours["diag_mesh_0"] == pytest.approx(theirs["diag_mesh_0"], rel=1e-6)
    assert ours["diag_mesh_1"] == pytest.approx(theirs["diag_mesh_1"], rel=1e-6)
    # pymeshlab also samples the unreferenced vertices (inside the holes); Metro does not
    assert ours["max"] == pytest.approx(0.5) and theirs["max"] > 5.0
    direct = am.evaluate.metro(am.Mesh(moved, faces), am.Mesh(pts, faces), samples=1000)
    assert (ours["max"], ours["mean"], ours["RMS"], ours["n_samples"]) == (
        direct.hausdorff, direct.mean, direct.rms, direct.n_samples)
    assert ours["min"] == min(direct.a_to_b.min, direct.b_to_a.min)
    assert np.array_equal(ms.mesh(1).vertex_scalar_array(), quality)  # savequality=False


def test_metro_savequality_and_point_set_target(ms) -> None:
    mf.apply_filter(ms, "generate_lod_set_asrbf", levels=2)  # ids 1, 2; current 2
    res = mf.apply_filter(ms, "get_metro_distance", samplenum=500, savequality=True)
    q = ms.mesh(2).vertex_scalar_array()
    assert 0 < q.max() <= res["max"] and q.min() >= 0
    assert ms.current_mesh_id() == 2
    pts, _ = bump_arrays()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=pts), "points")  # id 3
    one_way = mf.apply_filter(ms, "get_metro_distance", sampledmesh=1, targetmesh=3)
    assert one_way["n_samples"] == len(pts)
    with pytest.raises(mf.MeshlabFilterError, match="sampled mesh 3 has no faces"):
        mf.apply_filter(ms, "get_metro_distance", sampledmesh=3, targetmesh=1)


# ----------------------------------------------------------------------------- the cache


def test_filters_on_one_layer_fit_once_and_a_changed_layer_refits(ms) -> None:
    mf.cache.clear()
    mf.apply_filter(ms, "compute_scalar_by_asrbf_residual_per_vertex")
    mf.apply_filter(ms, "generate_lod_set_asrbf", levels=1)
    ms.set_current_mesh(0)
    mf.apply_filter(ms, "meshing_close_holes_asrbf")
    assert mf.cache.info()["misses"] == 1 and mf.cache.info()["hits"] == 2
    ms.set_current_mesh(0)
    mf.apply_filter(ms, "compute_scalar_by_asrbf_residual_per_vertex", seed=1)  # other fit
    ms.set_current_mesh(0)
    ms.compute_coord_by_function(x="x", y="y", z="z + 1", onselected=False)  # moved in place
    mf.apply_filter(ms, "compute_scalar_by_asrbf_residual_per_vertex")
    other = new_ms()  # same content, another MeshSet
    mf.apply_filter(other, "compute_scalar_by_asrbf_residual_per_vertex")
    assert mf.cache.info()["misses"] == 4 and mf.cache.info()["hits"] == 2


def test_cache_is_bounded_and_forgets_dead_meshsets() -> None:
    cache = NetworkCache(maxsize=2)
    sets = [new_ms() for _ in range(3)]
    nets = [cache.network(s, 0, layer_scan(s.current_mesh()), seed=0, view_axis="z")
            for s in sets]
    assert len(cache) == 2 and cache.info()["misses"] == 3
    assert cache.network(sets[2], 0, layer_scan(sets[2].current_mesh()), seed=0,
                         view_axis="z") is nets[2]
    del sets[1:]
    cache.network(sets[0], 0, layer_scan(sets[0].current_mesh()), seed=0, view_axis="z")
    assert len(cache) == 1  # the dead MeshSets' entries are gone
    cache.clear()
    assert cache.info() == {"hits": 0, "misses": 0, "size": 0, "maxsize": 2}


# ----------------------------------------------------------------------------- binding


def test_import_binds_nothing() -> None:
    code = ("import pymeshlab, meshlab_filter as mf; "
            "print(any(hasattr(pymeshlab.MeshSet, n) for n in mf.filter_list()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[1], check=True)
    assert out.stdout.strip() == "False"


def test_register_binds_methods_and_unregister_removes_them(ms, registered) -> None:
    assert mf.register() == ALL  # again: harmless
    res = ms.meshing_close_holes_asrbf(maxholesize=pymeshlab.PercentageValue(14))
    assert res["closed_holes"] == 1
    assert "maxholesize : PercentageValue" in ms.meshing_close_holes_asrbf.__doc__
    assert ms.get_metro_distance.__name__ == "get_metro_distance"
    with pytest.raises(pymeshlab.PyMeshLabException, match="Parameter foo not found"):
        ms.generate_lod_set_asrbf(foo=1)
    with pytest.raises(TypeError):
        ms.generate_lod_set_asrbf(3)
    assert mf.unregister() == ALL
    assert not any(hasattr(pymeshlab.MeshSet, n) for n in ALL)
    assert mf.unregister() == []


def test_register_never_shadows_a_pymeshlab_name(monkeypatch) -> None:
    def theirs(self, **kwargs):
        return {"pymeshlab": True}

    monkeypatch.setattr(pymeshlab.MeshSet, "get_metro_distance", theirs, raising=False)
    with pytest.warns(RuntimeWarning, match="does not shadow it"):
        bound = mf.register()
    try:
        assert "get_metro_distance" not in bound and len(bound) == len(ALL) - 1
        assert pymeshlab.MeshSet.get_metro_distance is theirs
    finally:
        mf.unregister()
    assert pymeshlab.MeshSet.get_metro_distance is theirs


# ----------------------------------------------------------------------------- scripts


def test_run_script_mixes_pymeshlab_and_asrbf_filters(ms) -> None:
    steps = [
        {"filter": "meshing_remove_duplicate_faces", "comment": "pymeshlab's own"},
        {"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "14%"}},
        {"filter": "get_metro_distance", "params": {"targetmesh": 0, "samplenum": 500}},
        {"filter": "get_topological_measures"},
    ]
    out = mf.run_script(ms, steps)
    assert [s["filter"] for s in out] == [s["filter"] for s in steps]
    assert out[0]["result"] == {}
    assert out[1]["result"]["closed_holes"] == 1
    assert out[2]["result"]["max"] < SMALL[1]  # the fill against the scan's hole
    assert "number_holes" in out[3]["result"]
    json.dumps(out, allow_nan=False)


@pytest.mark.parametrize("value", ["14%", {"percentage": 14}, {"abs": 14.0}])
def test_script_length_spellings(ms, value) -> None:
    (step,) = mf.run_script(ms, [{"filter": "meshing_close_holes_asrbf",
                                  "params": {"maxholesize": value}}])
    assert step["result"]["closed_holes"] == 1


def test_script_values_for_pymeshlab_filters() -> None:
    cloud = new_ms(points_only=True)
    mf.run_script(cloud, [
        {"filter": "compute_normal_for_point_clouds",
         "params": {"k": 10, "smoothiter": 0, "flipflag": True, "viewpos": [140, 50, 500]}},
        {"filter": "generate_surface_reconstruction_ball_pivoting",
         "params": {"ballradius": {"percentage": 3}, "clustering": 20.0, "creasethr": 90.0,
                    "deletefaces": False}},
    ])
    assert cloud.current_mesh().face_number() > 1000
    assert (cloud.current_mesh().vertex_normal_matrix()[:, 2] > 0).mean() > 0.9


@pytest.mark.parametrize(("step", "match"), [
    ("oops", "a step must be an object with a \"filter\" name, got \"oops\""),
    ({"params": {}}, "a step must be an object with a \"filter\" name"),
    ({"filter": "get_metro_distance", "parms": {}}, r"unknown key\(s\) parms"),
    ({"filter": "get_metro_distance", "params": [1]}, "\"params\" must be an object"),
    ({"filter": "meshing_close_holes_typo"}, "unknown filter 'meshing_close_holes_typo'"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"foo": 1}},
     r"\(meshing_close_holes_asrbf\): Parameter foo not found for filter "
     r"meshing_close_holes_asrbf. Please check the documentation.$"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": 5}},
     "maxholesize: a length: write \"5%\" or {\"percentage\": 5}"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "five%"}},
     "a percentage like '5%'.*got 'five%'"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "200%"}},
     r"maxholesize must be a percentage in \(0, 100\], got '200%'"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "-5%"}},
     "maxholesize must be a finite length > 0"),
    ({"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": {"percentage": 150}}},
     r"maxholesize must be a percentage in \(0, 100\]"),
    ({"filter": "meshing_close_holes", "params": {"refineholeedgelen": {"pct": 3}}},
     "an object value must be {\"percentage\": number} or {\"abs\": number}"),
    ({"filter": "compute_normal_for_point_clouds", "params": {"viewpos": ["a"]}},
     "a list must hold numbers"),
    ({"filter": "generate_lod_set_asrbf", "params": {"levels": "3"}},
     r"\(generate_lod_set_asrbf\): Parameter levels: must be an int"),
])
def test_malformed_scripts_are_refused_before_anything_runs(ms, step, match) -> None:
    steps = [{"filter": "meshing_close_holes_asrbf"}, step]  # step 1 would add a layer
    with pytest.raises(mf.ScriptError, match="^step 2") as info:
        mf.run_script(ms, steps)
    assert info.match(match)
    assert isinstance(info.value, pymeshlab.PyMeshLabException)
    assert isinstance(info.value, AsrbfError)
    assert ms.mesh_number() == 1 and "\n" not in str(info.value)
    with pytest.raises(mf.ScriptError, match="a script must be a JSON list of steps, got dict"):
        mf.run_script(ms, step if isinstance(step, dict) else {"filter": step})


def test_a_failing_step_names_its_number_and_filter(ms) -> None:
    steps = [{"filter": "meshing_close_holes_asrbf"},
             {"filter": "meshing_close_holes", "params": {"maxholesize": "x"}}]
    with pytest.raises(mf.ScriptError, match=r"^step 2 \(meshing_close_holes\): "):
        mf.run_script(ms, steps)
    assert ms.mesh_number() == 2  # step 1 ran
    with pytest.raises(mf.ScriptError, match=r"^step 1 \(get_metro_distance\): Mesh ID 5 "):
        mf.run_script(ms, [{"filter": "get_metro_distance", "params": {"targetmesh": 5}}])


# ----------------------------------------------------------------------------- files


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    pts, faces = bump_arrays()
    src = am.save_mesh(am.Mesh(pts, faces), tmp_path / "bump.ply")
    script = tmp_path / "fill.json"
    script.write_text(json.dumps([
        {"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "14%"}},
        {"filter": "meshing_remove_unreferenced_vertices"},
    ]))
    return {"src": src, "script": script, "out": tmp_path / "out.ply", "dir": tmp_path}


def test_run_script_file_saves_the_current_mesh_atomically(files) -> None:
    before = files["src"].read_bytes()
    res = mf.run_script_file(files["script"], files["src"], files["out"])
    assert files["src"].read_bytes() == before  # the input never changes
    json.dumps(res, allow_nan=False)
    assert res["steps"][0]["result"]["closed_holes"] == 1
    assert res["saved"]["label"] == "bump.ply (asrbf filled)" and res["meshes"] == 2
    back = am.load_scan(files["out"])
    assert back.n_faces == res["saved"]["faces"] == len(bump_arrays()[1]) + \
        res["steps"][0]["result"]["new_faces"]
    assert sorted(p.name for p in files["dir"].iterdir()) == ["bump.ply", "fill.json",
                                                              "out.ply"]


def test_run_script_file_errors_are_one_line_naming_the_file(files) -> None:
    src, script, out, d = files["src"], files["script"], files["out"], files["dir"]
    cases = [
        ((d / "none.json", src, out), f"^{d / 'none.json'}: no such file$"),
        ((script, d / "none.ply", out), f"^{d / 'none.ply'}: no such file$"),
        ((script, src, src), "refusing to overwrite the input file"),
        ((script, src, d / "missing" / "o.ply"), "does not exist"),
    ]
    bad_json = d / "bad.json"
    bad_json.write_text("[{\"filter\": ")
    cases.append(((bad_json, src, out), f"^{bad_json}: not a JSON filter script"))
    failing = d / "failing.json"
    failing.write_text(json.dumps([{"filter": "get_metro_distance",
                                    "params": {"targetmesh": 3}}]))
    cases.append(((failing, src, out), f"^{failing}: step 1 \\(get_metro_distance\\): "
                                       "Mesh ID 3 not found"))
    cases.append(((script, src, d / "out.unknown"), "out.unknown: cannot save"))
    garbage = d / "garbage.ply"
    garbage.write_bytes(b"not a ply at all")
    cases.append(((script, garbage, out), f"^{garbage}: cannot load"))
    for args, match in cases:
        with pytest.raises(AsrbfError, match=match) as info:
            mf.run_script_file(*args)
        assert "\n" not in str(info.value)
    assert not out.exists()
    assert not [p for p in os.listdir(d) if p.startswith(".")]  # no temporary file left


def test_cli_filter_script(capsys, files) -> None:
    from asrbf_mesh.cli import main

    argv = ["filter-script", files["script"], files["src"], "-o", files["out"]]
    assert main([str(a) for a in argv]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"ran 2 steps of {files['script']} on {files['src']}; wrote ")
    assert err == ""
    first = files["out"].read_bytes()
    files["out"].unlink()
    assert main([str(a) for a in argv] + ["--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [s["filter"] for s in res["steps"]] == ["meshing_close_holes_asrbf",
                                                   "meshing_remove_unreferenced_vertices"]
    assert files["out"].read_bytes() == first  # same input, same output, byte for byte


@pytest.mark.parametrize("case", ["missing_script", "same_path", "failing_step"])
def test_cli_filter_script_errors(capsys, files, case: str) -> None:
    from asrbf_mesh.cli import main

    script, src, out = files["script"], files["src"], files["out"]
    if case == "missing_script":
        script, match = files["dir"] / "none.json", "none.json: no such file"
    elif case == "same_path":
        out, match = src, "refusing to overwrite the input file"
    else:
        script = files["dir"] / "failing.json"
        script.write_text(json.dumps([{"filter": "meshing_close_holes_asrbf",
                                       "params": {"maxholesize": 5}}]))
        match = "step 1"
    code = main(["filter-script", str(script), str(src), "-o", str(out)])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    assert len(err.splitlines()) == 1 and err.startswith("asrbf: error: ")
    assert match in err
    assert not files["out"].exists()


# ----------------------------------------------------------------------------- a session


@pytest.mark.slow
def test_a_pymeshlab_users_session_on_the_face_map(tmp_path, registered) -> None:
    mf.cache.clear()
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(am.face_map_path()))
    filled = ms.meshing_close_holes_asrbf(maxholesize=pymeshlab.PercentageValue(5))
    assert filled["closed_holes"] >= 10
    ms.set_current_mesh(0)  # the scan again: its network is cached
    lod = ms.generate_lod_set_asrbf(levels=3)
    assert mf.cache.info()["misses"] == 1 and mf.cache.info()["hits"] == 1
    assert ms.current_mesh().label() == "face000.ply (asrbf LOD 2)"
    d = ms.get_metro_distance(targetmesh=0, samplenum=20000)
    assert d["RMS"] < 0.01 * d["diag_mesh_1"] and d["max"] < 0.1 * d["diag_mesh_1"]
    ms.save_current_mesh(str(tmp_path / "face_lod2.ply"))
    assert am.load_scan(tmp_path / "face_lod2.ply").n_faces == lod["faces"][2]
    assert ms.mesh(1).label() == "face000.ply (asrbf filled)"
    assert ms.mesh(0).face_number() == am.load_scan(am.face_map_path()).n_faces
