"""Levels of detail: resample / refit sets, the manifest, QEM baselines, borders."""

from __future__ import annotations

import io
import json
import time

import numpy as np
import plyfile
import pytest
from _grids import mm_grid

import asrbf_mesh as am
from asrbf_mesh._frame import sampling_spacing
from asrbf_mesh._lod import (
    MIN_LEVEL_SAMPLES,
    LodLevel,
    lod_set,
    network_file_bytes,
    ply_bytes,
    resample_spacings,
)
from asrbf_mesh.errors import AsrbfError, ConfigError
from asrbf_mesh.evaluate import QEM_BASELINES, _simplify, write_lod_set

NX, NY = 60, 50
LEVEL_KEYS = {"index", "path", "method", "vertices", "faces", "bytes", "mean_pct", "rms_pct",
              "hausdorff_pct", "seconds", "n_neurons", "d_min", "network_path", "mesh_bytes",
              "footprint_bytes", "spacing_abs", "border_offset_abs"}


def boundary_vertices(faces: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    return np.unique(uniq[count == 1])


def franke_scan(syn, notch: bool = True) -> am.Scan:
    """A 60 x 50 range grid of Franke's function in mm (x 100-180, y 20-80, z 5-30).

    With ``notch``, the faces within 25 mm of the corner (180, 80) are cut away, so the
    border is curved and concave; unreferenced points are dropped.
    """
    pts, faces = mm_grid(syn.franke, NX, NY)
    if notch:
        c = pts[faces].mean(axis=1)
        faces = faces[np.hypot(c[:, 0] - 180, c[:, 1] - 80) > 25]
        used = np.unique(faces)
        pts, faces = pts[used], np.searchsorted(used, faces)
    return am.Scan(pts, faces)


@pytest.fixture(scope="module")
def scan(syn) -> am.Scan:
    return franke_scan(syn)


@pytest.fixture(scope="module")
def resampled(scan) -> list[LodLevel]:
    return lod_set(scan, levels=3, method="resample", seed=0)


@pytest.fixture(scope="module")
def refitted(scan) -> list[LodLevel]:
    return lod_set(scan, levels=3, method="refit", seed=0)


@pytest.fixture(scope="module")
def written(scan, resampled, tmp_path_factory):
    out = tmp_path_factory.mktemp("lod_resample")
    return out, write_lod_set(scan, resampled, out, compare_qem=True)


@pytest.fixture(scope="module")
def written_refit(scan, refitted, tmp_path_factory):
    out = tmp_path_factory.mktemp("lod_refit")
    return out, write_lod_set(scan, refitted, out)


# ----------------------------------------------------------------------------- lod_set


def test_resample_levels_share_one_network(resampled: list[LodLevel]) -> None:
    assert [lv.index for lv in resampled] == [0, 1, 2]
    assert all(lv.method == "resample" for lv in resampled)
    net = resampled[0].network
    assert net is not None and all(lv.network is net for lv in resampled)
    assert len({lv.network_bytes for lv in resampled}) == 1
    assert all(lv.n_neurons == net.n_neurons for lv in resampled)
    spacing = [lv.spacing_abs for lv in resampled]
    np.testing.assert_allclose(np.diff(np.log2(spacing)), 1.0)  # the grid doubles
    faces = [lv.mesh.n_faces for lv in resampled]
    assert faces[0] > 3 * faces[1] > 9 * faces[2] > 0


def test_resample_level_zero_of_a_scan_about_as_wide_as_long(scan, resampled) -> None:
    # the Franke grid's own spacing (1.22 mm across y) is within a tenth of the unit
    # square's spacing times the geometric mean of the extents (1.17 mm): level 0 at the
    # latter, the levels doubling
    net = resampled[0].network
    s0 = net.info["spacing"] * float(np.sqrt(net.frame.scale[0] * net.frame.scale[1]))
    own = sampling_spacing((scan.points @ net.frame.rotation)[:, :2])
    assert 0.9 * own < s0 < own
    np.testing.assert_allclose([lv.spacing_abs for lv in resampled],
                               resample_spacings(s0, own, 3))
    np.testing.assert_allclose([lv.spacing_abs for lv in resampled], [s0, 2 * s0, 4 * s0])


def test_resample_level_zero_of_an_elongated_scan(syn) -> None:
    # a grid four times as long as wide, spacing 1 both ways: the unit square's spacing
    # (along the long side) times the geometric mean of the extents is half the scan's
    # spacing; level 0 stays at the scan's own, with about as many vertices as points
    pts, faces = mm_grid(syn.franke, 121, 31)
    pts[:, 0] = 100 + (pts[:, 0] - pts[:, 0].min()) / np.ptp(pts[:, 0]) * 120
    pts[:, 1] = 20 + (pts[:, 1] - pts[:, 1].min()) / np.ptp(pts[:, 1]) * 30
    scan = am.Scan(pts, faces)
    levels = lod_set(scan, levels=3, seed=0)
    assert levels[0].spacing_abs == pytest.approx(1.0)
    assert levels[0].mesh.n_vertices <= 1.1 * len(pts)
    assert levels[1].spacing_abs == pytest.approx(2.0)
    assert levels[2].spacing_abs > 2.4
    assert levels[0].mesh.n_faces > levels[1].mesh.n_faces > levels[2].mesh.n_faces


def test_resample_spacings_rule() -> None:
    assert resample_spacings(1.0, 0.9, 1) == [1.0]
    np.testing.assert_allclose(resample_spacings(1.0, 0.9, 4), [1, 2, 4, 8])
    np.testing.assert_allclose(resample_spacings(0.95, 1.0, 3), [0.95, 1.9, 3.8])
    np.testing.assert_allclose(resample_spacings(0.5, 1.0, 3), [1, 2, 2.5])  # step 1.25
    got = resample_spacings(0.4, 1.0, 5)
    np.testing.assert_allclose(got[:2], [1, 2])
    assert got[-1] == pytest.approx(6.4) and np.all(np.diff(np.log(got[1:])) > np.log(1.25))


def test_refit_levels_get_coarser_and_smaller_networks(refitted: list[LodLevel]) -> None:
    d = [lv.d_min for lv in refitted]
    np.testing.assert_allclose(np.array(d) / d[0], [1, 2, 4])
    assert d[0] == pytest.approx(refitted[0].network.info["d_min"])
    k = [lv.n_neurons for lv in refitted]
    assert k[0] > k[1] > k[2] > 0
    nbytes = [lv.network_bytes for lv in refitted]
    assert nbytes[0] > nbytes[1] > nbytes[2]
    assert len({id(lv.network) for lv in refitted}) == 3
    faces = [lv.mesh.n_faces for lv in refitted]
    assert faces[0] > faces[1] > faces[2] > 0
    np.testing.assert_allclose(np.diff(np.log2([lv.spacing_abs for lv in refitted])), 1.0)
    assert all(lv.seconds > 0 for lv in refitted)


def test_refit_with_given_d_mins_and_base_resolution(scan) -> None:
    levels = lod_set(scan, levels=2, method="refit", d_mins=[0.05, 0.1], base_resolution=41)
    assert [lv.d_min for lv in levels] == [0.05, 0.1]
    assert [lv.network.info["d_min"] for lv in levels] == [0.05, 0.1]
    for level, n in zip(levels, (41, 21), strict=True):  # x is the longer side (80 mm)
        assert_grid_columns(scan, level.mesh, n)


def assert_grid_columns(scan, mesh: am.Mesh, n: int) -> None:
    """Every one of the ``n`` grid columns is used; other x are border nodes on the scan."""
    x = np.round(mesh.vertices[:, 0], 9)
    grid = np.round(np.linspace(scan.points[:, 0].min(), scan.points[:, 0].max(), n), 9)
    assert np.isin(grid, x).all() and np.isin(x, grid).mean() > 0.9


def test_resample_of_a_given_network_and_base_resolution(scan, resampled) -> None:
    net = resampled[0].network
    levels = lod_set(scan, levels=2, net=net, base_resolution=33)
    shipped = levels[0].network  # the network as the set ships it: compact, read back
    assert shipped is levels[1].network and shipped.n_neurons == net.n_neurons
    np.testing.assert_allclose(shipped.centers, net.centers, atol=5e-5)
    np.testing.assert_allclose(shipped.weights, net.weights, rtol=1e-3, atol=1e-7)
    assert_grid_columns(scan, levels[0].mesh, 33)
    assert_grid_columns(scan, levels[1].mesh, 17)


def test_same_seed_same_levels(scan, resampled) -> None:
    again = lod_set(scan, levels=3, method="resample", seed=0)
    for a, b in zip(again, resampled, strict=True):
        np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
        np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)


def test_without_footprint_the_whole_square_is_meshed(scan, resampled) -> None:
    level = lod_set(scan, levels=1, net=resampled[0].network, footprint=False)[0]
    nx = len(np.unique(np.round(level.mesh.vertices[:, 0], 9)))
    ny = len(np.unique(np.round(level.mesh.vertices[:, 1], 9)))
    assert level.mesh.n_vertices == nx * ny  # the notch is meshed too
    assert level.mesh.n_faces > resampled[0].mesh.n_faces


def test_holes_stay_open_unless_fill_holes(syn, resampled) -> None:
    base = franke_scan(syn)
    c = base.points[base.faces].mean(axis=1)
    keep = np.hypot(c[:, 0] - 130, c[:, 1] - 45) > 8  # a hole of radius 8 mm
    holed = am.Scan(base.points, base.faces[keep])
    net = resampled[0].network
    open_ = lod_set(holed, levels=2, net=net)
    filled = lod_set(holed, levels=2, net=net, fill_holes=True)
    for a, b in zip(open_, filled, strict=True):
        da = np.hypot(*(a.mesh.vertices[:, :2] - [130, 45]).T)
        db = np.hypot(*(b.mesh.vertices[:, :2] - [130, 45]).T)
        assert db.min() < 2.0 < 4.0 < da.min()  # the fill reaches the centre; open: not
        assert a.mesh.n_faces < b.mesh.n_faces


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"levels": 0}, "levels must be an integer >= 1"),
    ({"fill_holes": 1}, "fill_holes must be True or False"),
    ({"fill_holes": True, "footprint": False}, "fill_holes applies with footprint=True"),
    ({"method": "bogus"}, "method must be one of resample, refit"),
    ({"d_mins": [0.01, 0.02]}, "d_mins applies to method 'refit' only"),
    ({"method": "refit", "levels": 2, "d_mins": [0.02]}, r"one D_min per level \(2\), got 1"),
    ({"method": "refit", "levels": 2, "d_mins": [0.04, 0.02]}, "must not decrease"),
    ({"method": "refit", "levels": 2, "d_mins": [0.0, 0.02]}, "positive finite numbers"),
    ({"method": "refit", "levels": 2, "d_mins": "ab"}, "d_mins must be a sequence"),
    ({"method": "refit", "levels": 6, "d_mins": None}, "exceed D_max"),
    ({"base_resolution": 1}, "base_resolution must be an integer >= 2"),
    ({"footprint": "yes"}, "footprint must be True or False"),
    ({"net": "model.asrbf"}, "net must be a Network"),
])
def test_lod_set_rejects_bad_arguments(scan, kwargs, message) -> None:
    if kwargs.get("d_mins", 0) is None:  # 6 levels from an automatic d0 ~ 0.034 pass 0.4
        kwargs = {"method": "refit", "levels": 6}
    with pytest.raises(ConfigError, match=message):
        lod_set(scan, **kwargs)


# ----------------------------------------------------------------------------- borders


def test_borders_stay_on_the_scan_border(scan, written, written_refit) -> None:
    for _, manifest in (written, written_refit):
        for row in manifest["levels"]:
            # every border vertex of a level is within one grid cell of the scan's border
            assert row["border_offset_abs"] <= 1.0 * row["spacing_abs"]
    # and the scan's border, the notch included, is followed: no scan border vertex is
    # more than a cell and a half from the level's border
    for level in lod_set(scan, levels=3, method="resample", seed=0):
        b_scan = scan.points[boundary_vertices(scan.faces), :2]
        b_lev = level.mesh.vertices[boundary_vertices(level.mesh.faces), :2]
        d = np.min(np.linalg.norm(b_scan[:, None] - b_lev[None], axis=2), axis=1)
        assert d.max() <= 1.5 * level.spacing_abs


# ----------------------------------------------------------------------------- manifest


def test_errors_grow_with_coarseness(written, written_refit) -> None:
    for _, manifest in (written, written_refit):
        rms = [row["rms_pct"] for row in manifest["levels"]]
        mean = [row["mean_pct"] for row in manifest["levels"]]
        haus = [row["hausdorff_pct"] for row in manifest["levels"]]
        assert rms[0] < rms[1] < rms[2]
        assert mean[0] < mean[2] and haus[0] < haus[2]
        assert all(0 < m <= r <= h for m, r, h in zip(mean, rms, haus, strict=True))
        assert rms[0] < 0.5  # % of the diagonal: the fine level fits Franke well


def test_manifest_is_consistent_with_the_files(written, resampled) -> None:
    out, manifest = written
    assert json.loads((out / "manifest.json").read_text()) == manifest
    assert manifest["format"] == "asrbf-lod" and manifest["method"] == "resample"
    assert manifest["metro"]["reference"] == "scan mesh"
    shared = manifest["network"]
    assert shared["path"] == "network.asrbf" and shared["shared_by_levels"] == [0, 1, 2]
    assert shared["bytes"] == (out / "network.asrbf").stat().st_size
    assert shared["n_neurons"] == resampled[0].n_neurons
    for row, level in zip(manifest["levels"], resampled, strict=True):
        assert LEVEL_KEYS <= set(row)
        assert row["path"] == f"level_{level.index}.ply"
        mesh = am.load_scan(out / row["path"])
        assert (mesh.n_points, mesh.n_faces) == (row["vertices"], row["faces"])
        assert (row["vertices"], row["faces"]) == (level.mesh.n_vertices, level.mesh.n_faces)
        assert row["network_path"] == "network.asrbf"
        assert row["bytes"] == shared["bytes"] == level.network_bytes
        assert row["mesh_bytes"] == ply_bytes(row["vertices"], row["faces"])
        assert 0 < row["footprint_bytes"] < row["bytes"]
    net = am.Network.load(out / "network.asrbf")
    assert net.n_neurons == resampled[0].n_neurons and net.log is None


def test_refit_manifest_has_one_network_per_level(written_refit, refitted) -> None:
    out, manifest = written_refit
    assert manifest["network"] is None and manifest["qem"] == []
    for row, level in zip(manifest["levels"], refitted, strict=True):
        assert row["network_path"] == f"level_{level.index}.asrbf"
        assert row["bytes"] == (out / row["network_path"]).stat().st_size == level.network_bytes
        assert am.Network.load(out / row["network_path"]).n_neurons == row["n_neurons"]
        assert row["d_min"] == pytest.approx(level.d_min)


def test_qem_baselines_match_the_face_counts(written, scan) -> None:
    out, manifest = written
    qem = manifest["qem"]
    assert len(qem) == 2 * len(manifest["levels"])
    border = scan.points[boundary_vertices(scan.faces)]
    for row in qem:
        assert LEVEL_KEYS <= set(row) and row["method"] in QEM_BASELINES
        level = manifest["levels"][row["index"]]
        assert row["target_faces"] == level["faces"]
        if row["reached"]:
            assert abs(row["faces"] - row["target_faces"]) <= 0.01 * row["target_faces"] + 2
        elif row["target_faces"] >= scan.n_faces:  # level 0 is finer than the scan
            assert "the scan mesh itself" in row["note"] and row["faces"] == scan.n_faces
        else:  # the preserved border puts a floor under the face count
            assert "border preserved" in row["note"] and row["faces"] > row["target_faces"]
        assert row["bytes"] == row["mesh_bytes"] == ply_bytes(row["vertices"], row["faces"])
        assert row["n_neurons"] is None and row["network_path"] is None
        mesh = am.load_scan(out / row["path"])
        assert mesh.n_faces == row["faces"]
        # the border is preserved: every scan border vertex is still a vertex
        d = np.min(np.linalg.norm(border[:, None] - mesh.points[None], axis=2), axis=1)
        assert d.max() < 1e-9
        assert row["border_offset_abs"] < 1e-9
        assert row["rms_pct"] < level["rms_pct"] * 10  # QEM keeps scan vertices: accurate


def test_qem_with_a_target_above_the_scan_returns_the_scan(scan, tmp_path) -> None:
    fine = lod_set(scan, levels=1, base_resolution=200)
    assert fine[0].mesh.n_faces > scan.n_faces
    manifest = write_lod_set(scan, fine, tmp_path, compare_qem=True, metro=False)
    for row in manifest["qem"]:
        assert row["faces"] == scan.n_faces and not row["reached"]
        assert "the scan mesh itself" in row["note"]
        assert row["rms_pct"] is None  # metro=False
    assert manifest["levels"][0]["hausdorff_pct"] is None


def test_point_cloud_scan(scan, tmp_path) -> None:
    cloud = am.Scan(scan.points)
    levels = lod_set(cloud, levels=2)
    manifest = write_lod_set(cloud, levels, tmp_path)
    assert manifest["metro"]["reference"] == "scan points"
    assert all(row["border_offset_abs"] is None for row in manifest["levels"])
    assert manifest["levels"][0]["rms_pct"] < manifest["levels"][1]["rms_pct"]
    with pytest.raises(AsrbfError, match="compare_qem needs a scan with faces"):
        write_lod_set(cloud, levels, tmp_path / "qem", compare_qem=True)


def test_write_rejects_bad_outputs(scan, resampled, tmp_path) -> None:
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    with pytest.raises(AsrbfError, match="not a directory"):
        write_lod_set(scan, resampled, a_file)
    with pytest.raises(AsrbfError, match="non-empty list of LodLevel"):
        write_lod_set(scan, [], tmp_path)
    with pytest.raises(AsrbfError, match="level indices must be unique"):
        write_lod_set(scan, [resampled[0], resampled[0]], tmp_path)
    # the scan's own file is never overwritten
    am.save_mesh(scan, tmp_path / "level_0.ply")
    src = am.load_scan(tmp_path / "level_0.ply")
    before = (tmp_path / "level_0.ply").read_bytes()
    with pytest.raises(AsrbfError, match="refusing to overwrite the input"):
        write_lod_set(src, resampled[:1], tmp_path, metro=False)
    assert (tmp_path / "level_0.ply").read_bytes() == before


# ----------------------------------------------------------------------------- sizes, QEM


def test_ply_bytes_is_the_size_of_a_float32_ply() -> None:
    v = np.zeros(7, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    f = np.empty(4, dtype=[("vertex_indices", "O")])
    for i in range(4):
        f["vertex_indices"][i] = np.array([0, 1, 2], np.int32)
    data = plyfile.PlyData(
        [plyfile.PlyElement.describe(v, "vertex"),
         plyfile.PlyElement.describe(f, "face", val_types={"vertex_indices": "i4"},
                                     len_types={"vertex_indices": "u1"})],
        text=False, byte_order="<")
    buf = io.BytesIO()
    data.write(buf)
    assert ply_bytes(7, 4) == len(buf.getvalue())


def test_network_file_bytes_is_the_written_size(resampled, tmp_path) -> None:
    net = resampled[0].network
    assert network_file_bytes(net) == resampled[0].network_bytes
    full = net.save(tmp_path / "full.asrbf").stat().st_size
    assert network_file_bytes(net) < full  # float32, no learning log


def test_fast_decimate_reaches_the_target_and_keeps_the_border(scan) -> None:
    mesh = scan.to_mesh()
    free = _simplify.fast_decimate(mesh, target_faces=600, preserve_border=False)
    assert abs(free.n_faces - 600) <= 6
    kept = _simplify.fast_decimate(mesh, target_faces=600, preserve_border=True)
    border = scan.points[boundary_vertices(scan.faces)]
    d = np.min(np.linalg.norm(border[:, None] - kept.vertices[None], axis=2), axis=1)
    assert d.max() < 1e-9
    assert kept.n_faces >= 600
    same = _simplify.fast_decimate(mesh, target_faces=10 * mesh.n_faces)
    assert same.n_faces == mesh.n_faces
    with pytest.raises(ConfigError, match="target_faces must be an integer >= 1"):
        _simplify.fast_decimate(mesh, target_faces=0)
    with pytest.raises(AsrbfError, match="mesh has no faces"):
        _simplify.fast_decimate(am.Mesh(mesh.vertices, np.empty((0, 3))), target_faces=5)


# ----------------------------------------------------------------------------- face map


@pytest.mark.slow
def test_face_map_lod_set(tmp_path) -> None:
    scan = am.load_scan(am.face_map_path())
    levels = lod_set(scan, levels=4, method="resample", seed=0)
    manifest = write_lod_set(scan, levels, tmp_path, compare_qem=True)
    rows = manifest["levels"]
    faces = [r["faces"] for r in rows]
    assert faces == sorted(faces, reverse=True) and len(set(faces)) == 4
    assert all(r["rms_pct"] < 0.3 for r in rows[:3])  # the network's own error dominates
    assert rows[3]["rms_pct"] > rows[0]["rms_pct"]
    # within two grid cells of the scan's border: every cell touching the scan is kept and
    # its outer nodes end on the scan's nearest sample; a ramp torn at a slit or a hole's
    # cliff (_surface_gaps) ends its sheet on the sheet's nearest sample, and the grid node
    # left on the other side can stand a little farther (level 0: 2.4 cells, at a rough
    # spot of the scan's where the network's grid triangles stand half a unit off it;
    # 2.85 since the tails' border rule moved the network: at the rim of one of the face
    # map's natural holes, level 0's rim stands 2.85 cells in from the scan's)
    assert all(r["border_offset_abs"] <= 2.0 * r["spacing_abs"] for r in rows[1:])
    assert rows[0]["border_offset_abs"] <= 3.0 * rows[0]["spacing_abs"]
    for q in manifest["qem"]:
        assert q["reached"] or q["note"]
    # QEM with a preserved border stops near 4,100 faces on the face map's ragged border
    floors = [q["faces"] for q in manifest["qem"] if q["target_faces"] < 4000]
    assert all(f > 4000 for f in floors)


def test_too_many_levels_are_refused_up_front(scan) -> None:
    """levels=10**9 ran 90 s, then overflowed; levels past the grid's 4 samples were copies."""

    t = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^levels must be at most (\d+) for this scan") as info:
        lod_set(scan, levels=10**9)
    assert time.perf_counter() - t < 30
    most = int(str(info.value).split("at most ", 1)[1].split()[0])
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match=f"at most {most} "):
        lod_set(scan, levels=most + 1)
    levels = lod_set(scan, levels=most, footprint=False)
    frame = levels[0].network.frame
    short = float(frame.scale[:2].min())
    coarsest = levels[-1].spacing_abs
    assert round(short / coarsest) + 1 >= MIN_LEVEL_SAMPLES
    with pytest.raises(ConfigError, match="levels must be at most"):
        lod_set(scan, levels=10**9, method="refit")
    t = time.perf_counter()  # with a base resolution too: before any spacing is listed
    with pytest.raises(ConfigError, match="levels must be at most"):
        lod_set(scan, levels=10**9, base_resolution=40)
    assert time.perf_counter() - t < 30


def _terraces(across: bool) -> am.Scan:
    """Two flat terraces (z = 0 for x < 30, z = 8 beyond) on a 60 x 40 grid of spacing 1;
    ``across``: the scan has its steep triangles down the step, else a gap there."""
    y, x = np.mgrid[0:40, 0:60].astype(float)
    z = np.where(x < 30, 0.0, 8.0)
    idx = np.arange(x.size).reshape(x.shape)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.vstack([np.stack([a, b, d], -1).reshape(-1, 3),
                      np.stack([a, d, c], -1).reshape(-1, 3)])
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    if not across:
        tris = tris[np.ptp(pts[tris, 2], axis=1) == 0]
    return am.Scan(pts, tris)


@pytest.mark.parametrize("across", [False, True])
def test_a_level_is_open_across_an_occlusion_gap_and_walled_down_a_cliff(across) -> None:
    scan = _terraces(across)
    net = am.fit(scan, seed=0, progress=False)
    assert net.n_pieces == 2
    level = lod_set(scan, levels=2, net=net, seed=0)[1]  # cells wider than the gap
    v, f = level.mesh.vertices, level.mesh.faces
    walls = np.ptp(v[f, 2], axis=1) > 3.0 * level.spacing_abs
    if across:  # the scan has surface down the step: the wall stands for it
        assert walls.sum() >= 2 * 20
    else:  # the scan is open there, and so is the level
        assert not walls.any()
        # the same level with every wall (reconstruct's default) is closed across the gap
        full = am.reconstruct(net, footprint=scan, spacing_abs=level.spacing_abs,
                              coverage="any")
        assert (np.ptp(full.vertices[full.faces, 2], axis=1) > 3.0).sum() >= 2 * 20
