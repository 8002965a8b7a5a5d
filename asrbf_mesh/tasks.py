"""The task layer: one function per ``asrbf`` command, for scripts, the CLI and batches.

Each function takes paths and keyword options (plain Python values; the defaults are
the command line's), does the work, writes the outputs, and returns exactly the dict
that ``asrbf <command> --json`` prints (strict JSON: no NaN). Bad options raise
:class:`~asrbf_mesh.errors.ConfigError` naming the option, bad data
:class:`~asrbf_mesh.errors.ScanError` / :class:`~asrbf_mesh.errors.NetworkFileError`.
Folder outputs (``lod``, ``compare``, ``report``) appear whole or not at all.

>>> from asrbf_mesh import tasks                                   # doctest: +SKIP
>>> tasks.fit("scan.ply", "scan.asrbf", seed=3)["n_neurons"]       # doctest: +SKIP
727

pymeshlab and matplotlib are imported only by the tasks that need them.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ._atomic import atomic_dir, atomic_path, check_output_dir, check_output_path
from ._config import BLENDS, PIECES, FitConfig
from ._frame import VIEW_AXES
from ._io import load_scan, save_mesh
from ._lod import METHODS as LOD_METHODS
from ._network import FORMAT_VERSION, Network
from ._surface import FOOTPRINT_MODES
from ._validate import check_bool, check_choice, check_float, check_int, check_seed, jsonable
from .errors import AsrbfError, ConfigError

__all__ = ["COMMANDS", "check_options", "compare", "fill_holes", "filter_script", "fit",
           "info", "lod", "metro", "reconstruct", "report"]

#: Most levels ``lod`` accepts before looking at the scan (level 12 is 2048 times coarser).
MAX_LEVELS = 12
#: Files each folder command writes: an existing folder holding only these is replaced.
LOD_FILES = ("manifest.json", "level_*.ply", "level_*.asrbf", "network.asrbf", "qem_*.ply")
COMPARE_FILES = ("compare.json", "report.md", "report.html", "img", "lod", "asrbf_bpa.ply",
                 "som_bpa.ply")
REPORT_FILES = ("summary.json", "summary.md", "summary.html")
_LEARNING_FIELDS = tuple(f.name for f in dataclasses.fields(FitConfig))


def _progress(value: Any) -> bool | None:
    return check_bool(value, "progress", allow_none=True)


# --------------------------------------------------------------------------- fit


def _fit_summary(net: Network) -> dict[str, Any]:
    info = net.info
    n = int(info["n_points"])
    counters = net.log_counters()
    return {
        "n_points": n,
        "n_neurons": net.n_neurons,
        "ebar": info["ebar"],
        "ebar_sequential": info["ebar_sequential"],
        "n_to_k": net.compression_ratio(n),
        "storage_ratio": net.storage_ratio(n),
        "error_mean": info["error_mean"],
        "error_std": info["error_std"],
        "steps": info["steps"],
        "fit_seconds": info["fit_seconds"],
        "learn_seconds": info["learn_seconds"],
        "polish_seconds": info["polish_seconds"],
        "us_per_step": info["us_per_step"],
        "compile_seconds": info.get("compile_seconds"),
        "d_min": info["d_min"],
        "seed": info["seed"],
        "polish": net.config.polish,
        "added": counters["added"] if counters else None,
        "pruned": counters["pruned"] if counters else None,
        "n_pieces": net.n_pieces,
        "pieces": _pieces_summary(net),
    }


def _pieces_summary(net: Network) -> list[dict[str, Any]] | str:
    """Each piece's points, neurons and E-bar; or why a streamed fit is one piece."""
    if net.info.get("streamed"):
        return ("one network: a streamed fit is not segmented (cutting a scan into pieces "
                "needs all of its points at once)")
    whole = net.info if net.n_pieces == 1 else {}  # a single network's figures are its own
    return [{"n_points": p.info.get("n_points", whole.get("n_points")),
             "n_neurons": p.n_neurons, "ebar": p.info.get("ebar", whole.get("ebar")),
             "constant": bool(p.info.get("constant", False))} for p in net.pieces]


def _check_fit(*, seed: int, view_axis: str, float32: bool, stream: bool, chunk: int | None,
               mix: int | None, progress: bool | None, pieces: Any,
               learning: dict[str, Any]) -> FitConfig:
    unknown = sorted(set(learning) - set(_LEARNING_FIELDS))
    if unknown:
        raise ConfigError(f"{unknown[0]} is not a learning option (one of "
                          f"{', '.join(_LEARNING_FIELDS)})")
    cfg = FitConfig().replace(**{k: v for k, v in learning.items() if v is not None})
    check_seed(seed)
    check_choice(view_axis, "view_axis", VIEW_AXES)
    check_bool(float32, "float32")
    check_bool(stream, "stream")
    check_choice(pieces, "pieces", PIECES)
    _progress(progress)
    for name, value in (("chunk", chunk), ("mix", mix)):
        if value is None:
            continue
        if not stream:
            raise ConfigError(f"{name} applies to a streamed fit only (--stream); without it "
                              "the scan is loaded whole")
        check_int(value, name, 1)
    return cfg


def fit(scan: str | os.PathLike, output: str | os.PathLike, *, seed: int = 0,
        view_axis: str = "z", float32: bool = False, stream: bool = False,
        chunk: int | None = None, mix: int | None = None, progress: bool | None = None,
        pieces: str = "auto", range_options: dict[str, Any] | None = None,
        **learning: Any) -> dict[str, Any]:
    """``asrbf fit``: fit a network to a scan file and save it (``.asrbf``).

    ``learning``: :class:`~asrbf_mesh.FitConfig` fields (``error_threshold``, ``d_min``,
    ``passes``, ``update`` ...); None keeps the default. ``chunk`` (65,536 points) and
    ``mix`` (16 blocks) apply with ``stream=True`` only. ``pieces``: ``"auto"`` (one
    network per smooth piece) or ``"1"`` (one network); a streamed fit is one network
    and says so in the summary's ``pieces``. ``range_options``: how to read range data
    (:class:`~asrbf_mesh._range_io.RangeOptions` fields).
    """
    cfg = _check_fit(seed=seed, view_axis=view_axis, float32=float32, stream=stream,
                     chunk=chunk, mix=mix, progress=progress, pieces=pieces,
                     learning=learning)
    out = Path(output)
    if out.suffix.lower() != ".asrbf":
        raise AsrbfError(f"{out}: a network file must end in .asrbf")
    if stream:
        from ._stream import DEFAULT_CHUNK, DEFAULT_MIX, fit_stream, open_points

        chunk = DEFAULT_CHUNK if chunk is None else chunk
        mix = DEFAULT_MIX if mix is None else mix
        open_points(scan, chunk, range_options)  # the input's errors first
    else:
        data = load_scan(scan, options=range_options)
    check_output_path(out, scan)  # before the fit, not after it
    if stream:
        net = fit_stream(scan, cfg, seed=seed, view_axis=view_axis, chunk=chunk, mix=mix,
                         progress=progress, options=range_options)
    else:
        from ._fit import fit as fit_scan

        net = fit_scan(data, cfg, seed=seed, view_axis=view_axis, pieces=pieces,
                       progress=progress)
    net.save(out, float32=float32, inputs=(scan,))
    return jsonable(_fit_summary(net) | {"output": str(out)})


# --------------------------------------------------------------------------- info


def info(network: str | os.PathLike) -> dict[str, Any]:
    """``asrbf info``: describe a network file."""
    net = Network.load(network)
    return jsonable({"n_neurons": net.n_neurons, "format_version": FORMAT_VERSION,
                     "n_pieces": net.n_pieces, "pieces": _pieces_summary(net),
                     "config": net.config.to_dict(), "frame": net.frame.to_dict(),
                     "stats": net.stats().to_dict(), "info": net.info,
                     "log": net.log_counters()})


# --------------------------------------------------------------------------- reconstruct


def _check_reconstruct(*, resolution: int | None, spacing: float | None, mode: str | None,
                       margin: float, footprint: Any) -> None:
    if resolution is not None and spacing is not None:
        raise ConfigError("give either resolution or spacing, not both")
    if resolution is not None:
        check_int(resolution, "resolution", 2)
    if spacing is not None:
        check_float(spacing, "spacing", low=0.0, low_open=True)
    if mode is not None:
        check_choice(mode, "mode", FOOTPRINT_MODES)
    check_float(margin, "margin", low=0.0, high=10.0, high_open=True)
    used = mode or ("full" if footprint is None else "surface")
    if margin != 0 and used != "full":
        why = "" if mode else " (a footprint meshes mode surface unless mode is given)"
        raise ConfigError(f"margin applies to mode full only: mode {used} follows the scan's "
                          f"border{why}")


def reconstruct(network: str | os.PathLike, output: str | os.PathLike, *,
                resolution: int | None = None, spacing: float | None = None,
                footprint: str | os.PathLike | None = None, mode: str | None = None,
                margin: float = 0.0, range_options: dict[str, Any] | None = None
                ) -> dict[str, Any]:
    """``asrbf reconstruct``: mesh a network's surface on a grid (``spacing`` in scan units)."""
    from ._surface import reconstruct as mesh_network

    _check_reconstruct(resolution=resolution, spacing=spacing, mode=mode, margin=margin,
                       footprint=footprint)
    net = Network.load(network)
    fp = load_scan(footprint, options=range_options) if footprint else None
    # the arguments were checked above under the command's names
    mesh = mesh_network(net, resolution=resolution, spacing_abs=spacing, footprint=fp,
                        mode=mode, margin_rel=margin)
    save_mesh(mesh, output, overwrite_inputs=(network, footprint))
    return jsonable({"output": str(output), "vertices": mesh.n_vertices,
                     "faces": mesh.n_faces})


# --------------------------------------------------------------------------- fill-holes


def _check_fill_holes(*, network: Any, max_hole_size: Any, blend: str, lowpass_rel: float,
                      seed: int, progress: bool | None, pieces: Any = "auto",
                      lattice: Any = True) -> None:
    check_choice(pieces, "pieces", PIECES)
    check_bool(lattice, "lattice")
    check_choice(blend, "blend", BLENDS)
    check_float(lowpass_rel, "lowpass_rel")
    check_seed(seed)
    _progress(progress)


def fill_holes(scan: str | os.PathLike, output: str | os.PathLike, *,
               network: str | os.PathLike | None = None, max_hole_size: str | float | None = None,
               blend: str = "thin-plate", lowpass_rel: float = 1.0, seed: int = 0,
               progress: bool | None = None, pieces: str = "auto",
               mask: str | os.PathLike | None = None, lattice: bool = True,
               range_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``asrbf fill-holes``: fill a scan's holes from its network (fitted if not given).

    ``lowpass_rel=0`` keeps every neuron over a hole; ``pieces`` as for :func:`fit` (the
    fit made here: a given network keeps its own pieces). A depth image or elevation
    grid is filled on its grid (:func:`~asrbf_mesh._grid_fill.fill_grid`) and written
    in kind when ``output`` has a grid suffix (``mask``: also an image of the filled
    cells); a LAS/LAZ cloud is written back as the input's points plus the fill's,
    flagged synthetic, when ``output`` is a LAS/LAZ file. A mesh made from one depth
    frame (its vertices on a pixel lattice, :func:`~asrbf_mesh._lattice.find_lattice`)
    is filled on that lattice as its depth image would be, unless ``lattice=False``,
    a network is given or ``blend`` / ``lowpass_rel`` are not their defaults (options
    of the mesh fill); another depth camera's mesh or point cloud in camera coordinates
    is filled in the camera's frame (``fill_holes(frame="auto")``), unless
    ``lattice=False``.
    """
    from ._range_io import RangeOptions, is_range_path, load_range

    _check_fill_holes(network=network, max_hole_size=max_hole_size, blend=blend,
                      lowpass_rel=lowpass_rel, seed=seed, progress=progress, pieces=pieces,
                      lattice=lattice)
    opts = RangeOptions.of(range_options)
    kind = is_range_path(scan, opts)
    if mask is not None and kind != "grid":
        raise ConfigError("mask: only a depth image or an elevation grid has a mask of "
                          "filled cells")
    data, source = (load_range(scan, opts, scan=kind != "grid") if kind
                    else (load_scan(scan), None))
    out = check_output_path(output, scan, network)
    if mask is not None:
        check_output_path(mask, scan, network, output)
    net = Network.load(network) if network else None
    if kind == "grid":
        return _fill_grid_task(source, net, out, mask, max_hole_size, seed, pieces, progress,
                               (scan, network))
    if not kind and lattice and net is None and blend == "thin-plate" and lowpass_rel == 1.0:
        from ._lattice import find_lattice

        lat = find_lattice(data)
        if lat is not None:
            return _fill_lattice_task(data, lat, out, max_hole_size, seed, pieces, progress,
                                      (scan,))
    from ._holes import fill_holes as fill  # (the mesh fill: a grid's needs none of it)

    res = fill(data, net, max_hole_size=max_hole_size, blend=blend,
               lowpass_rel=None if lowpass_rel <= 0 else lowpass_rel, seed=seed,
               progress=progress, pieces=pieces, frame="auto" if lattice else "view")
    if kind == "lidar" and out.suffix.lower() in (".las", ".laz"):
        from ._lidar import write_las_with_fill

        added = res.mesh.vertices[len(data.points):]
        write_las_with_fill(scan, source, added, out)
    else:
        save_mesh(res.mesh, out, overwrite_inputs=(scan, network))
    return jsonable(res.to_dict() | {"output": str(out)})


_GRID_OUTPUTS = (".png", ".tif", ".tiff", ".npy", ".npz")


def _fill_grid_task(grid: Any, net: Network | None, out: Path, mask: Any, max_hole_size: Any,
                    seed: int, pieces: str, progress: bool | None,
                    inputs: tuple) -> dict[str, Any]:
    """Fill a range grid on its grid; write it in kind (grid suffix) or as a mesh."""
    import dataclasses

    import numpy as np

    from ._grid_fill import fill_grid
    from ._range_write import write_like, write_mask

    res = fill_grid(grid, net, max_hole_size=max_hole_size, seed=seed, pieces=pieces,
                    progress=progress)
    if out.suffix.lower() in _GRID_OUTPUTS:
        write_like(grid, res.z_filled, out, mask=mask)
    else:
        filled = dataclasses.replace(grid, z=res.z_filled)
        scan = filled.to_scan()
        _, index = filled.points()
        quality = res.filled_mask.ravel()[index].astype(np.float64)
        from ._mesh import Mesh

        save_mesh(Mesh(scan.points, scan.faces if scan.faces is not None
                       else np.zeros((0, 3), np.int64), vertex_quality=quality), out,
                  overwrite_inputs=inputs)
        if mask is not None:
            write_mask(grid, res.z_filled, mask)
    return jsonable(res.to_dict() | {"output": str(out)}
                    | ({"mask": str(mask)} if mask is not None else {}))


def _fill_lattice_task(scan: Any, lat: Any, out: Path, max_hole_size: Any, seed: int,
                       pieces: str, progress: bool | None, inputs: tuple) -> dict[str, Any]:
    """Fill a depth frame's mesh on its pixel lattice; write the mesh with the fill."""
    from ._grid_fill import fill_grid
    from ._lattice import frame_faces, lattice_grid, merge_fill
    from ._mesh import Scan

    bare = scan.faces is None or len(scan.faces) == 0
    if bare:  # a frame's bare point cloud: meshed as its depth image first
        scan = Scan(scan.points, frame_faces(scan, lat), source=scan.source)
    res = fill_grid(lattice_grid(scan, lat), None, max_hole_size=max_hole_size, seed=seed,
                    pieces=pieces, progress=progress)
    mesh = merge_fill(scan, lat, res.z_filled, res.filled_mask)
    save_mesh(mesh, out, overwrite_inputs=inputs)
    fx, fy, cx, cy = lat.intrinsics
    return jsonable(res.to_dict() | {
        "output": str(out), "vertices_added": mesh.n_vertices - scan.n_points,
        "faces_added": mesh.n_faces - len(scan.faces),
        "lattice": {"rows": lat.shape[0], "cols": lat.shape[1], "fx": fx, "fy": fy,
                    "cx": cx, "cy": cy, "points_only": bare,
                    "scan_faces": len(scan.faces)}})


# --------------------------------------------------------------------------- lod


def _check_lod(*, levels: int, method: str, compare_qem: bool, metro: bool,
               seed: int, pieces: Any = "auto", fill_holes: bool = False) -> None:
    check_choice(pieces, "pieces", PIECES)
    check_bool(fill_holes, "fill_holes")
    check_int(levels, "levels", 1, MAX_LEVELS)
    check_choice(method, "method", LOD_METHODS)
    check_bool(compare_qem, "compare_qem")
    check_bool(metro, "metro")
    check_seed(seed)


def lod(scan: str | os.PathLike, output: str | os.PathLike, *, levels: int = 4,
        method: str = "resample", compare_qem: bool = False, metro: bool = True,
        seed: int = 0, pieces: str = "auto", fill_holes: bool = False,
        range_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``asrbf lod``: write a level-of-detail set and its manifest into the folder ``output``.

    Returns the manifest. ``metro=False`` skips the Metro error measures; ``fill_holes``
    meshes the holes the scan encloses too (every level).
    """
    from ._lod import lod_set
    from .evaluate import write_lod_set

    _check_lod(levels=levels, method=method, compare_qem=compare_qem, metro=metro, seed=seed,
               pieces=pieces, fill_holes=fill_holes)
    data = load_scan(scan, options=range_options)
    out = check_output_dir(output)
    with atomic_dir(out, LOD_FILES) as tmp:
        lods = lod_set(data, levels=levels, method=method, seed=seed, pieces=pieces,
                       fill_holes=fill_holes)
        manifest = write_lod_set(data, lods, tmp, compare_qem=compare_qem, metro=metro)
    return jsonable(manifest)


# --------------------------------------------------------------------------- metro


def metro(mesh: str | os.PathLike, reference: str | os.PathLike, *, samples: int | None = None,
          seed: int = 0, error_mesh: str | os.PathLike | None = None,
          samples_out: str | os.PathLike | None = None,
          range_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``asrbf metro``: Metro distances between a mesh and a reference scan.

    ``error_mesh``: also write the mesh with its per-vertex error as quality;
    ``samples_out``: every sample and its distance (``.npz``).
    """
    import numpy as np

    from .evaluate._metro import metro as measure

    check_seed(seed)
    # Metro fits nothing: any mesh with a face, any reference with a point
    a = load_scan(mesh, min_points=1, height_field=False, options=range_options)
    b = load_scan(reference, min_points=1, height_field=False, options=range_options)
    outs = [x for x in (error_mesh, samples_out) if x]
    for x in outs:
        check_output_path(x, mesh, reference)
    if samples_out and not str(samples_out).lower().endswith(".npz"):
        raise AsrbfError(f"{samples_out}: the samples file must end in .npz")
    if error_mesh and b.faces is None:
        raise AsrbfError(f"{reference}: a point cloud without faces; --error-mesh needs "
                         "a mesh reference (point distances measure the cloud's gaps)")
    res = measure(a, b if b.faces is not None else b.points, samples=samples, seed=seed,
                  per_sample=bool(outs))
    if error_mesh:
        save_mesh(res.error_mesh(), error_mesh, overwrite_inputs=(mesh, reference))
    if samples_out:
        arrays = {f"{name}_{k}": getattr(d, k) for name, d in
                  (("a_to_b", res.a_to_b), ("b_to_a", res.b_to_a)) if d is not None
                  for k in ("points", "distances")}
        with atomic_path(samples_out) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return jsonable(res.to_dict() | {"mesh": str(mesh), "reference": str(reference)})


# --------------------------------------------------------------------------- compare


def _check_compare(*, network: Any, holes: bool, lod: bool, meshes: bool,
                   som_iterations: int | None, seed: int, progress: bool | None,
                   pieces: Any = "auto") -> None:
    check_choice(pieces, "pieces", PIECES)
    for name, value in (("holes", holes), ("lod", lod), ("meshes", meshes)):
        check_bool(value, name)
    if som_iterations is not None:
        check_int(som_iterations, "som_iterations", 1)
    check_seed(seed)
    _progress(progress)


def compare(scan: str | os.PathLike, output: str | os.PathLike, *,
            network: str | os.PathLike | None = None, holes: bool = False, lod: bool = False,
            meshes: bool = True, som_iterations: int | None = None, seed: int = 0,
            progress: bool | None = None, pieces: str = "auto",
            range_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``asrbf compare``: our reconstruction vs the SOM baseline, report in folder ``output``."""
    from .evaluate._report import compare as run_compare
    from .evaluate._report import write_compare

    _check_compare(network=network, holes=holes, lod=lod, meshes=meshes,
                   som_iterations=som_iterations, seed=seed, progress=progress, pieces=pieces)
    data = load_scan(scan, options=range_options)
    out = check_output_dir(output)
    net = Network.load(network) if network else None
    with atomic_dir(out, COMPARE_FILES) as tmp:
        c = run_compare(data, net=net, seed=seed, holes=holes, lod=lod, lod_dir=tmp / "lod",
                        som_iterations=som_iterations, progress=progress, pieces=pieces)
        paths = write_compare(c, tmp, meshes=meshes)
    files = {k: str(out / Path(v).relative_to(tmp)) for k, v in paths.items()}
    return jsonable(c.to_dict() | {"files": files})


# --------------------------------------------------------------------------- report


def _unique_inputs(inputs: Sequence[str | os.PathLike]) -> list[str | os.PathLike]:
    """Return the inputs without those naming a compare.json given before (one warning)."""
    seen: dict[Path, str | os.PathLike] = {}
    dropped = []
    for p in inputs:
        path = Path(p)
        key = (path / "compare.json" if path.is_dir() else path).resolve()
        if key in seen:
            dropped.append(f"{p} (same as {seen[key]})")
        else:
            seen[key] = p
    if dropped:
        warnings.warn(f"report: counted once: {', '.join(dropped)}", stacklevel=3)
    return list(seen.values())


def report(inputs: Sequence[str | os.PathLike], output: str | os.PathLike) -> dict[str, Any]:
    """``asrbf report``: one page over several ``asrbf compare`` results, in folder ``output``.

    Inputs naming the same ``compare.json`` count once. Returns ``summary.json``.
    """
    import json

    from .evaluate._report import load_compare, write_summary

    if isinstance(inputs, (str, os.PathLike)):
        raise ConfigError("inputs must be a list of compare folders or compare.json files")
    inputs = _unique_inputs(inputs)
    results = [load_compare(p) for p in inputs]
    out = check_output_dir(output)
    links = []
    for p in inputs:
        page = (Path(p) if Path(p).is_dir() else Path(p).parent) / "report.html"
        links.append(os.path.relpath(page, out) if page.exists() else None)
    with atomic_dir(out, REPORT_FILES) as tmp:
        paths = write_summary(results, tmp, links)
        summary = json.loads(paths["json"].read_text(encoding="utf-8"))
    return jsonable(summary)


# --------------------------------------------------------------------------- filter-script


def filter_script(script: str | os.PathLike, input: str | os.PathLike,  # noqa: A002
                  output: str | os.PathLike) -> dict[str, Any]:
    """``asrbf filter-script``: run a JSON list of pymeshlab and asrbf filters on a mesh."""
    from meshlab_filter import run_script_file

    return jsonable(run_script_file(script, input, output))


# --------------------------------------------------------------------------- demo


def demo(output: str | os.PathLike = "asrbf-demo", *, seed: int = 0,
         progress: bool | None = None) -> dict[str, Any]:
    """``asrbf demo``: fit the face range map shipped with pymeshlab, mesh it two ways.

    Returns the fit summary and the written files with their sizes.
    """
    from ._fit import fit as fit_scan
    from ._io import face_map_path
    from ._surface import reconstruct as mesh_network

    check_seed(seed)
    _progress(progress)
    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    scan = load_scan(face_map_path())
    net = fit_scan(scan, seed=seed, progress=progress)
    net_path = net.save(out / "face.asrbf")
    fp = mesh_network(net, footprint=scan)
    full = mesh_network(net)
    p1 = save_mesh(fp, out / "face_footprint.ply")
    p2 = save_mesh(full, out / "face_full.ply")
    return jsonable(_fit_summary(net) | {
        "network": str(net_path), "network_bytes": net_path.stat().st_size,
        "footprint_mesh": str(p1), "footprint_vertices": fp.n_vertices,
        "full_mesh": str(p2), "full_vertices": full.n_vertices})


# --------------------------------------------------------------------------- registry

#: Command name -> task function.
COMMANDS: dict[str, Callable[..., dict[str, Any]]] = {
    "fit": fit, "info": info, "reconstruct": reconstruct, "fill-holes": fill_holes,
    "lod": lod, "metro": metro, "compare": compare, "report": report,
    "filter-script": filter_script, "demo": demo}

_CHECKS: dict[str, Callable[..., Any]] = {
    "fill-holes": _check_fill_holes, "lod": _check_lod, "compare": _check_compare}


def check_options(command: str, **options: Any) -> dict[str, Any]:
    """Validate the keyword options of ``command``'s task without running it.

    What needs no data is checked: names, types, ranges, combinations. Returns the
    options; raises :class:`ConfigError` naming the first bad one.
    """
    if command not in COMMANDS:
        raise ConfigError(f"command must be one of {', '.join(COMMANDS)}; got {command!r}")
    params = inspect.signature(COMMANDS[command]).parameters
    keywords = {k: p.default for k, p in params.items() if p.kind is p.KEYWORD_ONLY}
    takes_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
    for k in options:
        if k not in keywords and not takes_any:
            raise ConfigError(f"{k} is not an option of {command}")
    values = keywords | options
    if "range_options" in values:  # how range files are read: checked as a whole
        from ._range_io import RangeOptions

        RangeOptions.of(values.pop("range_options"))
    values.pop("mask", None)  # an output path, checked when it is written
    if command == "fit":
        learning = {k: v for k, v in values.items() if k not in keywords}
        _check_fit(**{k: values[k] for k in keywords if k in values}, learning=learning)
    elif command in _CHECKS:
        _CHECKS[command](**values)
    elif command == "reconstruct":
        _check_reconstruct(**values)
    elif "seed" in values:
        check_seed(values["seed"])
    return options


def error_line(exc: BaseException) -> str:
    """Return the one line ``asrbf`` prints for an error of a task."""
    text = str(exc)
    return text.splitlines()[0] if text else ""
