"""A first run compiles two things at once: the learning kernel here, the others beside it.

numba compiles a kernel the first time it is called and caches the machine code; a fresh
install therefore spends its first fit compiling, most of it (about 8 s on the benchmark
machine) on the learning kernel. Compilation holds a process-wide lock, so threads cannot
share the work, but processes can: while a command that learns compiles the learning
kernel, :func:`alongside` runs a helper process (``python -m asrbf_mesh._warm``) that
compiles the other kernels the command needs and writes them to numba's cache, where the
command finds them. The helper starts with what a fit needs right after learning (the
weight polish, the tail refinement, evaluation, reconstruction), because a command compiles
the frame's measures and the cut into pieces itself before it learns; it ends with those
(for ``asrbf demo``, which compiles the learning kernel before anything else). Nothing
starts when the learning kernel is cached already, and the helper never outlives the
command.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from collections.abc import Iterator

__all__ = ["alongside", "compile_after_learning"]

#: Commands that learn a network (and so may compile the learning kernel first).
LEARNING_COMMANDS = frozenset({"demo", "fit", "fill-holes", "lod", "compare"})


def _learning_kernel_cached() -> bool:
    """Whether numba's cache holds an index for the learning kernel (a cold install: no)."""
    try:
        from . import _learn_kernels

        return os.path.exists(_learn_kernels.run_steps._cache._cache_file._index_path)
    except Exception:  # noqa: BLE001 - numba internals moved: behave as if cached
        return True


@contextlib.contextmanager
def alongside(command: str | None) -> Iterator[None]:
    """Run the body with a compiling helper process beside it, on a cold cache only."""
    proc = None
    if command in LEARNING_COMMANDS and not os.environ.get("ASRBF_NO_WARM") \
            and not _learning_kernel_cached():
        try:
            proc = subprocess.Popen([sys.executable, "-m", "asrbf_mesh._warm"],
                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL)
        except OSError:
            proc = None  # no helper: the command compiles everything itself, as before
    if proc is not None and command == "demo":
        # the learning kernel now, while the helper compiles the rest: the demo's input is
        # known to be good (another command checks its input first, and a bad one gets
        # its error at once, not after compiling)
        from ._config import FitConfig
        from ._learn import _warm_up

        _warm_up(FitConfig(), 0.01)
    try:
        yield
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()  # numba writes cache files atomically: a kill leaves none half-done
            proc.wait()


def compile_after_learning() -> None:
    """Call every kernel a learning command needs after the learning loop, on tiny data.

    The calls go through the same functions as a real fit (the arrays have the same
    types), so the cache entries written here are the ones the command looks up.
    """
    import warnings

    import numpy as np

    from ._config import FitConfig
    from ._frame import to_height_field
    from ._mesh import Mesh
    from ._network import Network
    from ._pieces import refine_tails
    from ._polish import polish_weights
    from ._segment import segment
    from ._surface import grid_faces, reconstruct

    warnings.simplefilter("ignore")
    rng = np.random.default_rng(0)
    x, y = (a.ravel().astype(np.float64) for a in np.meshgrid(np.arange(40), np.arange(40)))
    faces = grid_faces(40, 40)
    pts = np.c_[x, y, 4.0 * np.sin(0.1 * x) * np.cos(0.07 * y)]
    hf = to_height_field(pts)  # (its measures: compiled here if the command has not yet)
    cfg = FitConfig()
    centers = rng.random((30, 2))
    widths = np.full(30, 0.2)
    weights = rng.normal(0.0, 0.05, 30)
    # first what a fit needs right after learning (the command compiles the frame's
    # measures, the cut into pieces and the learning kernel itself meanwhile): the
    # polish, then the tails (data slopes, spread, appended columns, solve and drop)
    pr = polish_weights(hf.xy, hf.z, 0.0, centers, widths, weights, cfg.support,
                        cfg.polish_ridge)
    refine_tails(hf, cfg.replace(error_threshold=0.001), pr.a0, pr.centers, pr.widths,
                 pr.weights, 0.05, pr)
    net = Network(pr.a0, pr.centers, pr.widths, pr.weights, hf.frame, cfg)
    net.evaluate(rng.random((10_000, 2)), unit=True)  # the threaded kernel
    net.evaluate(rng.random((100, 2)), unit=True)  # the one-thread path
    net.gradient(rng.random((100, 2)), unit=True)
    reconstruct(net, footprint=Mesh(pts, faces))
    # last what the command compiles before learning anyway (for the demo, which learns
    # first): the cut into pieces, of a ramp winding once around a point (a cliff along
    # one ray: jump pairs, then the geodesic split) with one point in no triangle (its
    # nearest anchor)
    ramp = 10.0 * (np.arctan2(y - 20.3, x - 19.7) % (2 * np.pi)) / (2 * np.pi)
    segment(Mesh(np.r_[np.c_[x, y, ramp], [[20.5, 20.5, 0.0]]], faces))


if __name__ == "__main__":  # pragma: no cover - the helper process
    compile_after_learning()
