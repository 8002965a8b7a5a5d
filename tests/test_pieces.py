"""Piecewise networks: one network per smooth piece, one model type (asrbf_mesh.Network)."""

from __future__ import annotations

import json
import pickle
import warnings
import zipfile

import numpy as np
import pytest
from _grids import grid_faces, height_grid

import asrbf_mesh as am
from asrbf_mesh._pieces import piece_seed

NX, NY = 60, 30  # a range grid of unit spacing; the cliff runs along x = 30


def cliff(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth surface raised by ten spacings where x >= 30 (a vertical cliff)."""
    return 2.0 * np.sin(x / 9.0) * np.cos(y / 7.0) + np.where(x >= 29.5, 10.0, 0.0)


def cliff_scan(fragment: bool = False) -> am.Scan:
    pts, faces = height_grid(cliff, NX, NY, x=(0.0, NX - 1.0), y=(0.0, NY - 1.0))
    if fragment:  # a floating 5 x 2 fragment beside the grid, 30 up: a small piece
        fx, fy = np.meshgrid(np.arange(5.0) + NX + 4, np.arange(2.0) + 5)
        frag = np.c_[fx.ravel(), fy.ravel(), np.full(10, 30.0)]
        pts, faces = np.vstack([pts, frag]), np.vstack([faces, grid_faces(5, 2) + len(pts)])
    return am.Scan(pts, faces)


@pytest.fixture(scope="module")
def fitted() -> tuple[am.Scan, am.Network]:
    scan = cliff_scan()
    return scan, am.fit(scan, seed=0, progress=False)


def test_pieces_fit_the_cliff_far_better_than_one_network(fitted) -> None:
    scan, net = fitted
    assert net.n_pieces == 2 and net.info["n_pieces"] == 2
    single = am.fit(scan, seed=0, pieces=1, progress=False)
    assert single.n_pieces == 1 and single.piece_map is None
    assert net.info["ebar"] < 0.3 * single.info["ebar"]  # measured 0.0017 vs 0.0144
    assert net.n_neurons == sum(p.n_neurons for p in net.pieces) < single.n_neurons
    assert net.info["n_points"] == scan.n_points
    assert net.compression_ratio() == scan.n_points / net.n_neurons


def test_every_point_is_evaluated_by_its_piece(fitted) -> None:
    scan, net = fitted
    labels = (scan.points[:, 0] >= 29.5).astype(np.int64)
    hf = am.to_height_field(scan.points)
    np.testing.assert_array_equal(net.piece_at(hf.xy, unit=True), labels)
    f = net.evaluate(hf.xy, unit=True)
    assert np.mean(np.abs(f - hf.z)) == pytest.approx(net.info["ebar"], rel=1e-12)
    np.testing.assert_array_equal(f, net.evaluate(hf.xy, unit=True, piece=labels))
    # a given piece evaluates there, whatever the map says
    left = net.evaluate(hf.xy[labels == 1], unit=True, piece=0)
    assert np.abs(left - hf.z[labels == 1]).mean() > 0.2
    assert net.pieces[0].info["n_points"] + net.pieces[1].info["n_points"] == scan.n_points


def test_the_joined_parameters_are_the_pieces(fitted) -> None:
    _, net = fitted
    np.testing.assert_array_equal(
        net.widths, np.concatenate([p.widths for p in net.pieces]))
    assert net.centers.shape == (net.n_neurons, 2) and not net.centers.flags.writeable
    assert net.stats().n_neurons == net.n_neurons
    with pytest.raises(am.ConfigError, match="one a0 per piece"):
        _ = net.a0
    # neurons come from learning (its log) and from the tail refinement (piece info)
    tails = sum(p.info.get("tail_neurons", 0) for p in net.pieces)
    assert net.log is None and net.log_counters()["added"] + tails >= net.n_neurons


def test_same_seed_same_bytes_and_a_file_round_trip(fitted, tmp_path) -> None:
    scan, net = fitted
    again = am.fit(scan, seed=0, progress=False)
    a, b = net.save(tmp_path / "a.asrbf"), again.save(tmp_path / "b.asrbf")
    assert a.read_bytes() == b.read_bytes()
    back = am.Network.load(a)
    assert back.n_pieces == 2 and back.piece_map is not None
    hf = am.to_height_field(scan.points)
    np.testing.assert_array_equal(back.evaluate(hf.xy), net.evaluate(hf.xy))
    np.testing.assert_array_equal(back.pieces[1].log.rms, net.pieces[1].log.rms)
    with zipfile.ZipFile(a) as zf:
        assert {"a0.npy", "piece_neurons.npy", "piece_map.npy"} <= set(zf.namelist())
    p = pickle.loads(pickle.dumps(net))
    np.testing.assert_array_equal(p.evaluate(hf.xy), net.evaluate(hf.xy))
    other = am.fit(scan, seed=1, progress=False)
    assert other.pieces[0].info["seed"] != net.pieces[0].info["seed"]
    assert net.pieces[0].info["seed"] == piece_seed(0, 0) != piece_seed(0, 1)


def test_pieces_on_two_threads_give_the_same_bytes_as_one_after_another(
        fitted, tmp_path, monkeypatch) -> None:
    import asrbf_mesh._pieces as P

    scan, net = fitted
    calls = []
    real = P.parallel_pieces
    monkeypatch.setattr(P, "parallel_pieces", lambda: calls.append(1) or real())
    threaded = am.fit(scan, seed=0, progress=False)
    assert calls  # two learned pieces: the question was asked
    monkeypatch.setattr(P, "parallel_pieces", lambda: False)
    serial = am.fit(scan, seed=0, progress=False)
    a = threaded.save(tmp_path / "threaded.asrbf").read_bytes()
    assert a == serial.save(tmp_path / "serial.asrbf").read_bytes()
    assert a == net.save(tmp_path / "net.asrbf").read_bytes()


def test_a_one_piece_scan_learns_as_the_single_network_then_refines(tmp_path) -> None:
    pts, faces = height_grid(lambda x, y: np.sin(x / 9.0) * np.cos(y / 7.0), 40, 30)
    scan = am.Scan(pts, faces)
    auto = am.fit(scan, seed=3, progress=False)
    single = am.fit(scan, seed=3, pieces="1", progress=False)
    assert auto.n_pieces == 1
    # the same learning, bit for bit; then the default model refines its tails
    np.testing.assert_array_equal(auto.log.n_neurons, single.log.n_neurons)
    np.testing.assert_array_equal(auto.log.rms, single.log.rms)
    assert auto.info["ebar"] <= single.info["ebar"]
    # without a polish there is no refinement either: the paper's network exactly
    raw = [am.fit(scan, seed=3, pieces=p, polish="none", progress=False) for p in ("auto", 1)]
    assert (raw[0].save(tmp_path / "a.asrbf").read_bytes()
            == raw[1].save(tmp_path / "b.asrbf").read_bytes())


def test_a_piece_of_several_too_large_for_dense_normal_equations_keeps_its_polish(
        monkeypatch) -> None:
    # a polish with sparse normal equations gets no tails in a scan of several pieces (a
    # second sparse solve cost as much as the polish); a scan of one piece gets them,
    # solved and dropped from the sparse equations, and pays for them (an SRTM tile,
    # 6,552 neurons, had been fitted by the single network itself)
    import asrbf_mesh._pieces as pieces_mod
    from asrbf_mesh import _polish

    monkeypatch.setattr(_polish, "DENSE_MAX", 8)
    refined = []
    real = pieces_mod.refine_tails

    def spy(sub, cfg, a0, centers, widths, weights, d_min, polished=None, *args, **kw):
        got = real(sub, cfg, a0, centers, widths, weights, d_min, polished, *args, **kw)
        refined.append((kw.get("no_more", False), got[1],
                        got[0][3] is weights or np.array_equal(got[0][3], weights)))
        return got

    monkeypatch.setattr(pieces_mod, "refine_tails", spy)
    am.fit(cliff_scan(), seed=0, progress=False)
    several = [r for r in refined if not r[0]]
    assert len(several) >= 2 and all(r[1] == 0 and r[2] for r in several)

    pts, faces = height_grid(lambda x, y: np.sin(x / 9.0) * np.cos(y / 7.0), 40, 30)
    scan = am.Scan(pts, faces)
    auto = am.fit(scan, seed=3, progress=False)
    single = am.fit(scan, seed=3, pieces="1", progress=False)
    assert auto.n_pieces == 1
    assert auto.n_neurons < single.n_neurons and auto.info["ebar"] < single.info["ebar"]


def test_a_tiny_fragment_gets_a_constant_piece() -> None:
    scan = cliff_scan(fragment=True)
    net = am.fit(scan, seed=0, progress=False)
    assert net.n_pieces == 3
    frag = net.pieces[2]
    hf = am.to_height_field(scan.points)
    assert frag.n_neurons == 0 and frag.a0 == pytest.approx(hf.z[-10:].mean())
    assert frag.info["constant"] is True
    assert net.n_neurons == net.pieces[0].n_neurons + net.pieces[1].n_neurons
    assert net.info["n_points"] == NX * NY + 10


def test_a_fragment_gets_as_few_neurons_as_fit_it_and_a_flat_one_a_constant() -> None:
    from asrbf_mesh._pieces import SMALL_NEURONS, small_piece

    cfg = am.FitConfig()
    x, y = np.meshgrid(np.linspace(0.4, 0.43, 5), np.linspace(0.6, 0.61, 4))
    xy = np.c_[x.ravel(), y.ravel()]
    frame = am.to_height_field(np.c_[xy, xy[:, 0]]).frame
    tilted = am.HeightField(xy, 0.5 + 2.0 * (xy[:, 0] - 0.4), frame, 0.01, 0.0)
    piece = small_piece(tilted, cfg, {"n_points": 20})
    assert 1 <= piece.n_neurons < SMALL_NEURONS and piece.info["constant"] is False
    err = np.abs(piece.eval_unit(xy, cfg.support)[0] - tilted.z)
    assert err.mean() < 0.2 * np.abs(tilted.z - tilted.z.mean()).mean()
    assert err.max() < cfg.error_threshold < np.abs(tilted.z - tilted.z.mean()).max()
    # one neuron fewer does not fit every point within E
    fewer = small_piece(tilted, cfg.replace(max_neurons=piece.n_neurons - 1), {"n_points": 20})
    assert fewer.n_neurons < piece.n_neurons
    assert np.abs(fewer.eval_unit(xy, cfg.support)[0] - tilted.z).max() > cfg.error_threshold
    # a fragment no three neurons fit within E: the count with the lowest mean error
    rough = am.HeightField(xy, 0.5 + 0.05 * np.sin(300.0 * xy[:, 0] + 500.0 * xy[:, 1]),
                           frame, 0.01, 0.0)
    piece = small_piece(rough, cfg, {"n_points": 20})
    err = np.abs(piece.eval_unit(xy, cfg.support)[0] - rough.z)
    assert 1 <= piece.n_neurons <= SMALL_NEURONS and err.max() > cfg.error_threshold
    assert err.mean() < np.abs(rough.z - rough.z.mean()).mean()  # closer than the constant
    for k in range(1, piece.n_neurons):  # and than fewer neurons
        fewer = small_piece(rough, cfg.replace(max_neurons=k), {"n_points": 20})
        assert np.abs(fewer.eval_unit(xy, cfg.support)[0] - rough.z).mean() > err.mean()
    flat = am.HeightField(xy, 0.5 + 1e-4 * xy[:, 0], frame, 0.01, 0.0)  # within E
    assert small_piece(flat, cfg, {"n_points": 20}).n_neurons == 0
    one = am.HeightField(xy[:2], tilted.z[:2], frame, 0.01, 0.0)  # two points: a constant
    assert small_piece(one, cfg, {"n_points": 2}).n_neurons == 0


def test_the_tails_are_refined_to_the_threshold(monkeypatch) -> None:
    import asrbf_mesh._pieces as P

    # a narrow ridge the sequential learning leaves behind (D_min keeps neurons apart)
    pts, faces = height_grid(lambda x, y: np.sin(x / 9.0) + np.exp(-((x - 20.3) / 2.0) ** 2),
                             40, 30, x=(0.0, 39.0), y=(0.0, 29.0))
    scan = am.Scan(pts, faces)

    def across(net: am.Network) -> np.ndarray:  # the error across the surface, unit depth
        hf = am.to_height_field(pts)
        g = net.gradient(hf.xy, unit=True) * (hf.frame.scale[2] / hf.frame.scale[:2])
        return np.abs(net.evaluate(hf.xy, unit=True) - hf.z) / np.sqrt(1 + (g * g).sum(1))

    refined = am.fit(scan, seed=0, progress=False)
    monkeypatch.setattr(P, "TAIL_ROUNDS", 0)
    plain = am.fit(scan, seed=0, progress=False)
    e = am.FitConfig().error_threshold
    assert refined.info["tail_neurons"] > 0 == plain.info["tail_neurons"]
    # three rounds take the worst points from 4 E to the threshold (0.6 E); the neurons
    # dropped after them and the last round leave them under 1.5 x the threshold or about
    assert np.percentile(across(plain), 99.9) > 3 * e
    assert np.percentile(across(refined), 99.9) <= 1.5 * e
    assert refined.info["ebar"] < plain.info["ebar"]


def test_the_tails_do_not_chase_a_depth_cameras_quanta(monkeypatch) -> None:
    import asrbf_mesh._pieces as P
    from asrbf_mesh._segment import depth_quanta

    # a smooth surface whose depths come in levels 1/80 of its depth range apart: a
    # surface through them misses each level by up to half a quantum, above 0.6 E
    q = 1.0 / 80
    pts, faces = height_grid(lambda x, y: 0.5 + 0.45 * np.sin(x / 7.0) * np.cos(y / 5.0),
                             50, 40, x=(0.0, 49.0), y=(0.0, 39.0))
    pts[:, 2] = np.round(pts[:, 2] / q) * q
    scan = am.Scan(pts, faces)
    quanta = depth_quanta(am.to_height_field(pts).z)
    assert quanta is not None and quanta.at(np.array([0.5]))[0] == pytest.approx(
        q / np.ptp(pts[:, 2]), rel=1e-6)
    import asrbf_mesh._fit as F

    # (one piece: its tails must pay for themselves by as many neurons dropped; here
    # they may not, to show what they would chase)
    monkeypatch.setattr(F, "refine_tails",
                        lambda *a, **k: P.refine_tails(*a, **{**k, "no_more": False}))
    aware = am.fit(scan, seed=0, progress=False, error_threshold=0.005)
    monkeypatch.setattr(P, "TAIL_QUANTA", 0.0)
    chasing = am.fit(scan, seed=0, progress=False, error_threshold=0.005)
    assert chasing.info["tail_neurons"] > aware.info["tail_neurons"]
    # no point needs a tail here: the idle neurons still go, within the noise's budget
    monkeypatch.setattr(P, "TAIL_QUANTA", 1.5)
    monkeypatch.setattr(P, "IDLE_NOISE_SHARE", 0.0)
    kept = am.fit(scan, seed=0, progress=False, error_threshold=0.005)
    assert aware.info["tail_neurons"] == 0 == kept.info["tail_neurons"]
    assert aware.n_neurons < 0.7 * kept.n_neurons
    assert aware.info["ebar"] < 1.1 * kept.info["ebar"]


def test_a_lone_miss_is_no_tail_where_depths_come_in_levels() -> None:
    from asrbf_mesh._grid_knn import point_grid
    from asrbf_mesh._pieces import TAIL_SUPPORT, _supported

    # a 20 x 20 grid: one point off alone (a flying pixel), a 3 x 3 patch off together,
    # a point off the other way from the patch's centre's neighbours, and a point whose
    # neighbours miss by less than the threshold
    x, y = np.meshgrid(np.arange(20.0), np.arange(20.0))
    xy = np.c_[x.ravel(), y.ravel()]
    res = np.zeros(400)
    lone, patch, edge = 3 * 20 + 3, [i * 20 + j for i in (10, 11, 12) for j in (10, 11, 12)], 25
    res[lone] = 5.0
    res[patch] = 2.0
    res[11 * 20 + 13] = -2.0  # beside the patch, the other side
    res[[r * 20 + c for r in (0, 1, 2) for c in (4, 5, 6)]] = 0.5  # under the threshold
    res[edge] = 2.0
    at = np.array([lone, 11 * 20 + 11, 10 * 20 + 10, 11 * 20 + 13, edge])
    got = _supported(xy, res, at, 1.0, point_grid(xy))
    assert TAIL_SUPPORT == 3
    # the patch's centre has 8 off with it, its corner 3; the lone point and the one
    # off the other way none; the point among misses under the threshold none
    assert got.tolist() == [False, True, True, False, False]
    limit = np.full(400, 1.0)
    limit[patch] = 3.0  # a threshold per point (quanta): the patch's points now within
    assert not _supported(xy, res, at[1:2], limit, point_grid(xy))[0]


def test_the_noise_bound_the_tails_skip_on_holds() -> None:
    # refine_tails skips measuring the errors across when the depth errors' upper median
    # cannot raise the threshold: MAD(x) <= sorted(y)[n // 2] for 0 <= x <= y
    rng = np.random.default_rng(5)
    for n in list(range(1, 40)) + [4096, 4097]:
        y = np.abs(rng.standard_normal(n)) * rng.choice([1e-6, 1.0, 1e3])
        x = y / np.sqrt(1.0 + rng.random(n) * rng.choice([0.0, 1.0, 100.0]))
        mad = np.median(np.abs(x - np.median(x)))
        assert mad <= np.partition(y, n // 2)[n // 2]


def test_a_given_segmentation_is_used() -> None:
    scan = cliff_scan()
    seg = am.segment(scan, min_piece_points=2000)  # both pieces small: none learns
    net = am.fit(scan, pieces=seg, progress=False)
    assert net.n_pieces == 2 and all(p.log is None for p in net.pieces)
    assert net.n_neurons <= 6  # a constant or up to three neurons each (small_piece)


def test_outliers_are_left_out_of_the_pieces() -> None:
    scan = cliff_scan()
    pts = np.vstack([scan.points, [[10.0, 10.0, 1e6]]])
    with pytest.warns(am.OutlierWarning):
        net = am.fit(am.Scan(pts, scan.faces), seed=0, progress=False)
    clean = am.fit(scan, seed=0, progress=False)
    assert net.info["outliers"] == 1 and net.n_pieces == 2
    assert net.info["ebar"] == pytest.approx(clean.info["ebar"], rel=1e-9)


@pytest.mark.parametrize("kw, match", [
    ({"pieces": 2}, "^pieces must be one of"), ({"pieces": "many"}, "^pieces must be one of"),
    ({"order": lambda rng: rng.permutation(NX * NY)}, "order applies to a single network")])
def test_bad_arguments_raise_config_error(kw: dict, match: str) -> None:
    with pytest.raises(am.ConfigError, match=match):
        am.fit(cliff_scan(), progress=False, **kw)


def test_a_segmentation_of_another_scan_or_axis_is_refused() -> None:
    scan = cliff_scan()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = am.segment(cliff_scan(fragment=True))
        along_x = am.segment(scan, view_axis="x")
    with pytest.raises(am.ConfigError, match="segmentation has 1,810 points"):
        am.fit(scan, pieces=other)
    with pytest.raises(am.ConfigError, match="view axis 'x'"):
        am.fit(scan, pieces=along_x)


def test_a_piecewise_model_needs_a_map_naming_its_pieces(fitted) -> None:
    _, net = fitted
    with pytest.raises(am.ConfigError, match="needs a PieceMap"):
        am.Network.from_pieces(net.pieces, net.frame, net.config)
    with pytest.raises(am.ConfigError, match="non-empty sequence of Piece"):
        am.Network.from_pieces([], net.frame, net.config)
    with pytest.raises(am.ConfigError, match="piece must be in"):
        net.evaluate(np.zeros((2, 2)), piece=np.array([0, 2]))


def test_reconstruct_meshes_each_piece_and_walls_between_them(fitted) -> None:
    scan, net = fitted
    mesh = am.reconstruct(net, footprint=scan)
    single = am.fit(scan, seed=0, pieces=1, progress=False)
    ramp = am.reconstruct(single, footprint=scan)
    # no vertex halfway up the cliff: every vertex is on one of the two levels
    def off_levels(m: am.Mesh) -> int:
        z = m.vertices[:, 2] - 2.0 * np.sin(m.vertices[:, 0] / 9.0) * np.cos(
            m.vertices[:, 1] / 7.0)
        return int(np.sum(np.minimum(np.abs(z), np.abs(z - 10.0)) > 1.0))
    assert off_levels(mesh) == 0 < off_levels(ramp)
    # the wall closes the seam: every edge is shared by two faces but the outer border's
    def edge_use(m: am.Mesh) -> np.ndarray:
        edges = np.sort(m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        return np.unique(edges, axis=0, return_counts=True)[1]
    assert edge_use(mesh).max() == 2
    # the same outer border as the single network's mesh, plus the wall's two ends
    assert np.sum(edge_use(mesh) == 1) == np.sum(edge_use(ramp) == 1) + 2


def test_a_format_1_file_still_loads(tmp_path) -> None:
    import io
    import json

    net = am.fit(cliff_scan(), seed=0, pieces=1, progress=False)
    meta = {"format": "asrbf-network", "format_version": 1, "dtype": "float64",
            "frame": net.frame.to_dict(), "config": net.config.to_dict(),
            "info": {"n_points": 1800}, "log_counters": None}
    members = {"meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
               "a0": np.array([net.a0]), "centers": net.centers, "widths": net.widths,
               "weights": net.weights}
    path = tmp_path / "v1.asrbf"
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in members.items():
            buf = io.BytesIO()
            np.save(buf, arr, allow_pickle=False)
            zf.writestr(f"{name}.npy", buf.getvalue())
    back = am.Network.load(path)
    assert back.n_pieces == 1 and back.a0 == net.a0 and back.info == {"n_points": 1800}
    q = np.random.default_rng(0).random((50, 2))
    np.testing.assert_array_equal(back.evaluate(q, unit=True), net.evaluate(q, unit=True))


def test_the_command_line_fits_pieces_and_info_shows_them(tmp_path, capsys) -> None:
    from asrbf_mesh.cli import main

    scan = cliff_scan()
    path = tmp_path / "cliff.ply"
    am.save_mesh(am.Mesh(scan.points, scan.faces), path)
    assert main(["fit", str(path), "-o", str(tmp_path / "a.asrbf"), "--json"]) == 0
    auto = json.loads(capsys.readouterr().out)
    assert main(["fit", str(path), "-o", str(tmp_path / "b.asrbf"), "--pieces", "1",
                 "--json"]) == 0
    single = json.loads(capsys.readouterr().out)
    assert auto["n_pieces"] == 2 and single["n_pieces"] == 1
    assert auto["ebar"] < single["ebar"] and len(auto["pieces"]) == 2
    assert main(["info", str(tmp_path / "a.asrbf")]) == 0
    assert "pieces             2 (900 / 900 points)" in capsys.readouterr().out
    assert main(["fit", str(path), "-o", str(tmp_path / "c.asrbf"), "--stream",
                 "--json"]) == 0
    streamed = json.loads(capsys.readouterr().out)
    assert streamed["n_pieces"] == 1 and "not segmented" in streamed["pieces"]


def test_coverage_any_keeps_a_fragment_narrower_than_a_cell() -> None:
    from asrbf_mesh._igl import point_mesh_distance

    scan = cliff_scan(fragment=True)  # a 5 x 2 fragment beside the grid
    net = am.fit(scan, seed=0, progress=False)
    frag = scan.points[-10:]
    coarse = {cov: am.reconstruct(net, spacing_abs=8.0, footprint=scan, coverage=cov)
              for cov in ("centre", "any")}
    # with either coverage: with "any" on its cells, with "centre" (it owns no cell
    # centre at this grid) as a patch of its own samples on its own network
    for cov in ("centre", "any"):
        assert point_mesh_distance(frag, coarse[cov]).max() < 1.0
    grid = am.reconstruct(net, spacing_abs=8.0, footprint=am.Scan(scan.points[:-10],
                                                                  scan.faces[:-8]))
    assert grid.n_vertices < coarse["centre"].n_vertices  # the patch's samples
    # the cells reaching past the border end on the scan: no vertex beyond its samples
    v = coarse["any"].vertices
    assert v[:, 0].max() <= scan.points[:, 0].max() + 1e-9
    assert v[:, 1].max() <= scan.points[:, 1].max() + 1e-9
    with pytest.raises(am.ConfigError, match="^coverage must be one of"):
        am.reconstruct(net, footprint=scan, coverage="all")


def test_compact_files_are_a_quarter_and_evaluate_within_their_rounding(fitted,
                                                                        tmp_path) -> None:
    scan, net = fitted
    lean = net.without_logs()
    full = lean.save(tmp_path / "f64.asrbf")
    small = lean.save(tmp_path / "compact.asrbf", compact=True)
    back = am.Network.load(small)
    with zipfile.ZipFile(small) as zf:
        assert zf.getinfo("centers.npy").file_size < zf.getinfo("widths.npy").file_size * 3
    assert small.stat().st_size < full.stat().st_size
    np.testing.assert_allclose(back.centers, net.centers, atol=3e-5)
    np.testing.assert_allclose(back.widths, net.widths, rtol=5e-4)
    hf = am.to_height_field(scan.points)
    assert np.abs(back.evaluate(hf.xy, unit=True) - net.evaluate(hf.xy, unit=True)).max() < 2e-3
    again = lean.save(tmp_path / "again.asrbf", compact=True)
    assert again.read_bytes() == small.read_bytes()


def test_the_piece_map_refines_its_cells_until_the_points_agree() -> None:
    from asrbf_mesh._piece_map import MIN_AGREEMENT, PieceMap

    rng = np.random.default_rng(0)
    uv = rng.random((4000, 2))
    labels = (uv[:, 0] + 0.01 * np.sin(40 * uv[:, 1]) > 0.5).astype(np.int64)  # wavy cut
    spacing = 0.02
    pm = PieceMap.of_points(uv, labels, spacing)
    share = np.mean(pm.piece_at(uv) == labels)
    assert pm.cell < spacing and (share >= MIN_AGREEMENT or pm.cell < 0.4 * spacing)
    coarse = PieceMap._raster(uv, labels, spacing)
    assert np.mean(coarse.piece_at(uv) == labels) < share


def _fit_bytes(scan: am.Scan) -> tuple[int, bytes]:
    net = am.fit(scan, seed=0, progress=False)
    q = np.random.default_rng(1).random((20_000, 2))
    parts = [net.evaluate(q, unit=True).tobytes()]
    for p in net.pieces:
        parts += [np.float64(p.a0).tobytes(), p.centers.tobytes(), p.widths.tobytes(),
                  p.weights.tobytes()]
    return net.n_pieces, b"".join(parts)


def test_a_child_forked_after_a_fit_fits_the_same_bytes() -> None:
    # numba's OpenMP layer kills a forked child at its first parallel kernel when the
    # parent ran one: a forked child runs that work on its own pool of threads instead
    import multiprocessing as mp

    scan = cliff_scan()
    ref = _fit_bytes(scan)  # the parent runs its parallel kernels
    assert ref[0] >= 2
    with mp.get_context("fork").Pool(1) as pool:
        got = pool.apply_async(_fit_bytes, (scan,)).get(timeout=300)
    assert got == ref


def _one_piece_grid(k: int) -> tuple[np.ndarray, am.Network, am.Network]:
    """A 100 x 100 grid of sin(k pi x) cos(k pi y), its single network and pieces (seed 0)."""
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    pts = np.c_[x.ravel(), y.ravel(), (np.sin(k * np.pi * x) * np.cos(k * np.pi * y)).ravel()]
    single = am.fit(pts, seed=0, pieces=1, progress=False)
    auto = am.fit(pts, seed=0, progress=False)
    assert auto.n_pieces == 1
    return pts, single, auto


def test_one_smooth_piece_is_no_worse_than_the_single_network() -> None:
    # a steep smooth grid: one piece, so the default model is the single network with its
    # tails refined; weak neurons pruned before the polish (the old rule) raised E-bar
    # 0.00201 -> 0.00252
    _, single, auto = _one_piece_grid(3)
    assert auto.info["ebar"] <= 1.01 * single.info["ebar"]
    assert auto.n_neurons <= single.n_neurons


def test_a_noisy_smooth_piece_does_not_chase_its_noise() -> None:
    # noise of 1.2 % of the depth range: 7 % of the points missed the tail threshold,
    # lone, and the tails chased them (K 1,475 -> 2,422, farther from the true surface:
    # 0.0080 against 0.0052 of the range); with the support they must now have, the
    # default model has fewer neurons than the single network and is as close to the truth
    rng = np.random.default_rng(0)
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    truth = np.sin(x) * np.cos(y)
    pts = np.c_[x.ravel(), y.ravel(), (truth + 0.01 * rng.standard_normal(x.shape)).ravel()]
    single = am.fit(pts, seed=0, pieces=1, progress=False)
    auto = am.fit(pts, seed=0, progress=False)
    assert auto.n_pieces == 1
    assert auto.n_neurons < single.n_neurons and auto.info["tail_neurons"] < 50
    assert auto.info["ebar"] <= single.info["ebar"]

    def off(net) -> float:
        return float(np.sqrt(np.mean((net.evaluate(pts[:, :2]) - truth.ravel()) ** 2)))

    assert off(auto) <= 1.01 * off(single)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_scan_of_one_piece_gets_no_more_neurons_from_its_tails(seed) -> None:
    # a scan of one piece learns as the single network; its tails then trade neurons:
    # each added is paid for by one dropped, or the polished network stays (a synthetic
    # bone seen from above, one piece: 1,746 -> 2,317 neurons before, past the dense
    # normal equations where nothing was dropped)
    from asrbf_mesh._config import FitConfig
    from asrbf_mesh._frame import to_height_field
    from asrbf_mesh._pieces import refine_tails
    from asrbf_mesh._polish import polish_weights

    rng = np.random.default_rng(seed)
    x, y = (a.ravel().astype(np.float64) for a in np.meshgrid(np.arange(40), np.arange(40)))
    hf = to_height_field(np.c_[x, y, 4.0 * np.sin(0.1 * x) * np.cos(0.07 * y)])
    cfg = FitConfig().replace(error_threshold=0.001)
    k = 30
    pr = polish_weights(hf.xy, hf.z, 0.0, rng.random((k, 2)), np.full(k, 0.2),
                        rng.normal(0.0, 0.05, k), cfg.support, cfg.polish_ridge)
    before = np.abs(hf.z - am.Network(pr.a0, pr.centers, pr.widths, pr.weights, hf.frame,
                                      cfg).evaluate(hf.xy, unit=True)).mean()
    grown, added = refine_tails(hf, cfg, pr.a0, pr.centers, pr.widths, pr.weights, 0.05, pr)
    assert len(grown[2]) > k and added > 0  # tails alone: more neurons
    (a0, c, w, a), added = refine_tails(hf, cfg, pr.a0, pr.centers, pr.widths, pr.weights,
                                        0.05, pr, no_more=True)
    after = np.abs(hf.z - am.Network(a0, c, w, a, hf.frame, cfg).evaluate(hf.xy, unit=True))
    if added:
        assert len(w) < k and after.mean() < before
    else:
        assert len(w) == k and np.array_equal(a, pr.weights)


def test_a_one_piece_drop_that_raises_the_mean_error_is_made_again_smaller(monkeypatch) -> None:
    # a smooth surface without noise, one piece: its drop (436 of 1,399 neurons) kept the
    # sum of squares below the polished network's, but raised the mean error by 2 %, and
    # the polished network (the single network's: as many neurons, the same error) stayed;
    # the drop made again within a quarter of its budget pays
    import asrbf_mesh._pieces as pieces_mod

    pts, single, auto = _one_piece_grid(2)
    assert auto.n_neurons < 0.9 * single.n_neurons
    assert auto.info["ebar"] < single.info["ebar"]
    monkeypatch.setattr(pieces_mod, "RETRY_SHARES", ())
    once = am.fit(pts, seed=0, progress=False)  # no second drop: the polished network
    assert once.n_neurons == single.n_neurons and once.info["ebar"] == single.info["ebar"]


def _half_cylinder(n: int = 41):
    """A range grid of a cylinder's side seen across its axis: steep at both borders."""
    from asrbf_mesh._frame import to_height_field

    x, y = np.meshgrid(np.linspace(-0.95, 0.95, n), np.linspace(0.0, 2.0, n))
    pts = np.c_[x.ravel(), y.ravel(), np.sqrt(1.0 - x.ravel() ** 2)]
    return to_height_field(pts)


def test_the_tails_see_a_border_point_as_far_as_its_depth_error_when_the_surface_ends() -> None:
    # the perpendicular from a point at the border, onto a surface that falls away
    # outward, lands past the border where a mesh has no surface: the point is its whole
    # depth error from it; a point inside, or a miss on the other side, by the cosine
    from asrbf_mesh._grid_knn import point_grid
    from asrbf_mesh._piece import Piece
    from asrbf_mesh._tail_shapes import across as _across
    from asrbf_mesh._tail_shapes import data_shape as _data_shape

    hf = _half_cylinder()
    grid = point_grid(hf.xy)
    scale = np.asarray(hf.frame.scale, dtype=np.float64)
    shape = _data_shape(hf, grid, np.arange(hf.n_points), scale)
    u = hf.xy[:, 0]
    left, right = u < u.min() + 1e-9, u > u.max() - 1e-9
    bottom, top = hf.xy[:, 1] < 1e-9, hf.xy[:, 1] > hf.xy[:, 1].max() - 1e-9
    inner = ~(left | right | bottom | top)
    assert np.all(shape[inner, 1:] == 0.0)
    side = (left | right) & ~(bottom | top)
    assert np.allclose(shape[left & side, 1:], [-1.0, 0.0], atol=1e-9)
    assert np.allclose(shape[right & side, 1:], [1.0, 0.0], atol=1e-9)
    # one wide neuron over the middle, weighted to be steep at the borders: the depth
    # falls off toward both sides, as the cylinder's; misses of either sign
    piece = Piece(0.0, np.array([[0.5, 0.5]]), np.array([0.7]), np.array([5.0]))
    res = np.where(np.arange(hf.n_points) % 2 == 0, 0.01, -0.01)
    fresh = np.full((hf.n_points, 3), np.nan)
    ratio = scale[2] / scale[:2]

    def cosine(at):  # the error across the surface
        g = piece.eval_unit(hf.xy[at], 3.0, True)[1] * ratio
        return 0.01 / np.sqrt(1.0 + np.minimum((g * g).sum(axis=1), shape[at, 0]))

    at = np.flatnonzero(side)
    grad = piece.eval_unit(hf.xy[at], 3.0, True)[1][:, 0]
    off = _across(piece, hf, res, at, scale, 3.0, grid, fresh)
    past = grad * res[at] * np.sign(shape[at, 1]) > 0
    assert past.any() and (~past).any()
    assert np.allclose(off[past], 0.01)  # the whole depth error
    assert np.allclose(off[~past], cosine(at[~past])) and np.all(off[~past] < 0.006)
    inside = np.flatnonzero(inner)
    assert np.allclose(_across(piece, hf, res, inside, scale, 3.0, grid, fresh), cosine(inside))
    # a point in no scan triangle (a flying pixel) is no surface's border
    loose = np.ones(hf.n_points, dtype=bool)
    assert np.allclose(_across(piece, hf, res, at, scale, 3.0, grid, fresh, loose), cosine(at))


def test_a_reconstruction_stays_on_the_samples_where_the_surface_falls_away() -> None:
    # a cylinder's side seen across its axis, with noise: its borders fall away steeply;
    # the network missed the border rows by about E and the reconstruction ended short
    # of them (scan -> mesh 99.9th percentile 0.33-0.46 % of the diagonal, seeds 0-2;
    # 0.23-0.26 since the tails take such points' whole depth error)
    from asrbf_mesh._igl import point_mesh_distance

    n = 61
    x, y = np.meshgrid(np.linspace(-0.97, 0.97, n), np.linspace(0.0, 2.0, n))
    z = np.sqrt(1.0 - x**2) * (1.0 + 0.1 * np.sin(3.0 * y))
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()
                + np.random.default_rng(0).normal(0.0, 0.002, n * n)]
    scan = am.Scan(pts, grid_faces(n, n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net = am.fit(scan, seed=0, progress=False)
    mesh = am.reconstruct(net, footprint=scan)
    d = point_mesh_distance(pts, mesh) / scan.bbox_diagonal
    assert np.percentile(d, 99.9) < 0.003


def test_the_tails_take_the_data_shapes_measured_beside_the_learning() -> None:
    # measured in chunks beside the learning, stopped at any chunk: the same shapes as
    # the tails measure point by point, and the same network whether it ran or not
    import threading

    import asrbf_mesh._pieces as P
    import asrbf_mesh._tail_shapes as S
    from asrbf_mesh._config import FitConfig
    from asrbf_mesh._grid_knn import point_grid
    from asrbf_mesh._polish import polish_weights

    hf = _half_cylinder(61)
    scale = np.asarray(hf.frame.scale, dtype=np.float64)
    whole = S.data_shape(hf, point_grid(hf.xy), np.arange(hf.n_points), scale)
    done = S.DataShapes(hf)
    done.run()
    grid, shape = done.take()
    assert np.array_equal(shape, whole) and grid[0].shape == point_grid(hf.xy)[0].shape

    unstarted = S.DataShapes(hf)
    assert unstarted.take() is None
    unstarted.run()  # stopped before it began: measures nothing
    assert unstarted.take() is None

    old = S.SHAPE_CHUNK
    S.SHAPE_CHUNK = 500
    try:
        part = S.DataShapes(hf)
        calls = []
        real = S.data_shape

        def counted(*args):  # stop it from inside its third chunk
            calls.append(1)
            if len(calls) == 3:
                threading.Thread(target=lambda: setattr(part, "_stop", True)).start()
            return real(*args)

        S.data_shape = counted
        try:
            part.run()
        finally:
            S.data_shape = real
        _, got = part.take()
        measured = ~np.isnan(got[:, 0])
        assert 0 < measured.sum() < hf.n_points and np.array_equal(got[measured],
                                                                   whole[measured])
    finally:
        S.SHAPE_CHUNK = old

    failed = S.DataShapes(hf)  # a failure beside the learning stops it quietly
    S.data_shape = lambda *args: 1 / 0
    try:
        failed.run()
    finally:
        S.data_shape = real
    assert np.isnan(failed.take()[1]).all()

    cfg = FitConfig().replace(error_threshold=0.002)
    rng = np.random.default_rng(3)
    k = 40
    pr = polish_weights(hf.xy, hf.z, 0.0, rng.random((k, 2)), np.full(k, 0.15),
                        rng.normal(0.0, 0.05, k), cfg.support, cfg.polish_ridge)
    args = (hf, cfg, pr.a0, pr.centers, pr.widths, pr.weights, 0.03, pr)
    plain = P.refine_tails(*args)
    for shapes in (done, part, unstarted, failed):
        given = P.refine_tails(*args, shapes=shapes)
        assert given[1] == plain[1] > 0
        assert all(np.array_equal(a, b) for a, b in zip(given[0][1:], plain[0][1:],
                                                          strict=True))


def test_a_one_piece_scan_past_the_dense_equations_gets_its_tails_by_strips(monkeypatch) -> None:
    # a scan of one piece whose network is past the dense normal equations (an elevation
    # tile: 6,552 neurons) was fitted by the single network itself; its tails are now
    # solved and dropped strip by strip from the sparse equations (the limits lowered
    # here so that a small grid takes that path)
    import scipy.sparse as sparse

    import asrbf_mesh._polish as P

    g = np.linspace(0.0, 1.0, 80)
    x, y = np.meshgrid(g, g)
    rng = np.random.default_rng(0)
    z = np.sin(3 * np.pi * x) * np.cos(2 * np.pi * y) + 0.003 * rng.standard_normal(x.shape)
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    for name, value in (("DENSE_MAX", 200), ("IDLE_MAX_NEURONS", 199), ("TILE_ABOVE", 100),
                        ("TILE_NEURONS", 60)):
        monkeypatch.setattr(P, name, value)
    seen = []
    tiled = P._solve_and_drop_tiled
    monkeypatch.setattr(P, "_solve_and_drop_tiled",
                        lambda xy, z, ata, *a, **k: seen.append(sparse.issparse(ata))
                        or tiled(xy, z, ata, *a, **k))
    single = am.fit(pts, seed=0, pieces=1, progress=False)
    auto = am.fit(pts, seed=0, progress=False)
    assert single.n_neurons > 200 and auto.n_pieces == 1 and seen and all(seen)
    assert auto.n_neurons < single.n_neurons and auto.info["ebar"] < single.info["ebar"]
    assert auto.info["tail_neurons"] > 0
