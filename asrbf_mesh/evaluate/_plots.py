"""Pictures of meshes for reports: shaded renders from above and error heat maps.

Everything draws on a matplotlib ``Axes`` (the Agg backend is enough); the view is
along -z of the world frame, i.e. from the scanner for a range scan.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._mesh import Mesh

__all__ = ["figure", "render_error", "render_shaded", "save_figure"]

_LIGHT = np.array([-0.4, 0.5, 0.77]) / np.linalg.norm([-0.4, 0.5, 0.77])


def figure(ncols: int, *, width: float = 5.0, height: float = 5.0) -> tuple[Any, Any]:
    """Make a figure with ``ncols`` axes side by side (non-interactive backend)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(width * ncols, height), squeeze=False)
    return fig, axes[0]


def save_figure(fig: Any, path: Any, *, dpi: int = 80) -> None:
    """Save a figure atomically and close it."""
    import matplotlib.pyplot as plt

    from .._atomic import atomic_path

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)


def _shade(mesh: Mesh) -> np.ndarray:
    v, f = mesh.vertices, mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return np.clip(np.abs(n @ _LIGHT), 0.05, 1.0)


def _frame(ax: Any, title: str) -> None:
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.axis("off")


def render_shaded(ax: Any, mesh: Mesh, title: str = "",
                  highlight: np.ndarray | None = None) -> None:
    """Lambert-shaded render of ``mesh`` seen from above (+z), grey.

    ``highlight`` (a vertex mask) paints the triangles touching those vertices orange,
    e.g. the fill of a repaired scan.
    """
    v, f = mesh.vertices, mesh.faces
    shade = _shade(mesh)
    ax.tripcolor(v[:, 0], v[:, 1], f, facecolors=shade, cmap="gray", vmin=0, vmax=1,
                 edgecolors="none")
    if highlight is not None and highlight.any():
        sel = highlight[f].any(axis=1)
        ax.tripcolor(v[:, 0], v[:, 1], f[sel], facecolors=shade[sel], cmap="Oranges_r",
                     vmin=-0.5, vmax=1.2, edgecolors="none")
    _frame(ax, title)


def render_error(ax: Any, mesh: Mesh, error: np.ndarray, title: str = "", *,
                 vmax: float | None = None, unit: str = "% of diagonal") -> Any:
    """Heat map of a per-vertex ``error`` over ``mesh`` seen from above, with a colour bar.

    ``vmax`` fixes the top of the colour scale (to compare two maps); default: the
    99th percentile of ``error``. Returns the colour mapping.
    """
    v, f = mesh.vertices, mesh.faces
    e = np.asarray(error, dtype=np.float64)
    top = float(vmax if vmax is not None else np.percentile(e, 99)) or 1.0
    im = ax.tripcolor(v[:, 0], v[:, 1], f, e, shading="gouraud", cmap="inferno", vmin=0.0,
                      vmax=top)
    ax.figure.colorbar(im, ax=ax, shrink=0.8, label=unit)
    _frame(ax, title)
    return im
