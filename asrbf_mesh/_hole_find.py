"""Finding the holes of a triangulated scan, told from its outer border by the footprint.

The boundary edges of the scan's triangles are labelled by the uncovered region of the
view plane they face (:class:`~asrbf_mesh._footprint.Footprint`): the regions connected
to the far margin are the outside (the outer border, never filled), the others are holes.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from . import _holes_kernels as _hk
from ._footprint import Footprint, _label_bays

__all__ = ["Hole", "boundary_edges", "chains", "find_holes", "usable_faces", "usable_faces_warned"]


@dataclass
class Hole:
    """One hole: its footprint label, its rim edges (scan vertex pairs) and its size."""

    label: int
    edges: np.ndarray  # (E, 2) scan vertex indices, rim edges
    size: float


def usable_faces(faces: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Return a scan's faces as the fill can use them, and how many of each fix were made.

    Left out: faces that repeat a vertex (``[a, b, a]`` covers nothing, and its edges
    ``a-b`` and ``b-a`` make the edge beside a missing triangle look shared, so the hole
    there is never found) and copies of a face (the same three vertices, in any order:
    the first is kept; a copy gives each of its edges two more faces, so a hole's rim
    looks shared), and fins (a face on an edge of more than two faces whose two other
    edges have no other face: the last ones, while the edge has more than two).
    Turned (``[a, c, b]``; every other face as given): faces against
    their neighbours, where an edge shared by two faces runs the same way in both (a
    patch cannot then join the rim the scan's way); each connected patch is turned one
    way (libigl's BFS, :func:`~asrbf_mesh._igl.orient_faces`), then as most of its
    faces were. A crop of the face map with 5 holes punched: with 2 % of its faces
    copied, 2 and 0 of them filled (two spoilings); 2 % turned, 1 and 0; half turned, 0
    and 0; fins on 2 % of its edges, 0 and 1; with these fixes 5 of 5 each time
    (``scripts/bench_mesh_defects.py``). Keys ``"repeated"``, ``"copies"``,
    ``"fins"``, ``"turned"``; the faces come back as given when all are 0 (checked in linear
    time, :func:`~asrbf_mesh._holes_kernels.face_faults`: 0.02 s on the face map).
    """
    f = np.asarray(faces, dtype=np.int64)
    fixes = {"repeated": 0, "copies": 0, "fins": 0, "turned": 0}
    bad = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if bad.any():
        fixes["repeated"] = int(bad.sum())
        f = f[~bad]
    copy, turned, over = _hk.face_faults(f)
    if copy.any():
        fixes["copies"] = int(copy.sum())
        f = f[~copy]
        _, turned, over = _hk.face_faults(f)
    if over:
        fin = _fins(f)
        if fin.any():
            fixes["fins"] = int(fin.sum())
            f = f[~fin]
            turned = _hk.face_faults(f)[1]
    if turned == 0:
        return f, fixes
    from ._igl import orient_faces

    def kept(out: np.ndarray) -> np.ndarray:  # libigl may start a face at another corner
        return np.any([np.all(np.roll(out, k, axis=1) == f, axis=1) for k in range(3)], axis=0)

    out, comp = orient_faces(f, components=True)
    back = np.bincount(comp, weights=~kept(out)) > 0.5 * np.bincount(comp)
    out[back[comp]] = out[back[comp]][:, ::-1]  # each patch as most of its faces were
    flip = ~kept(out)
    out = f.copy()
    out[flip] = f[flip][:, [0, 2, 1]]  # the others exactly as given
    if _hk.face_faults(out)[1] < turned:
        fixes["turned"] = int(flip.sum())
        f = out
    return f, fixes


def usable_faces_warned(faces: np.ndarray | None, source: str | None) -> np.ndarray | None:
    """Return the faces the fill can use (:func:`usable_faces`), with a warning on fixes."""
    if faces is None or len(faces) == 0:
        return faces
    faces, fixes = usable_faces(faces)
    said = [f"{n:,} {what}" for what, n in (
        ("faces with a repeated vertex left out", fixes["repeated"]),
        ("copies of faces left out", fixes["copies"]),
        ("fins left out (faces on an edge of more than two)", fixes["fins"]),
        ("faces turned to agree with their neighbours", fixes["turned"])) if n]
    if said:
        warnings.warn(f"{source or 'scan'}: {', '.join(said)}", stacklevel=3)
    return faces


def _fins(f: np.ndarray) -> np.ndarray:
    """Whether each face is a fin: on an edge of more than two faces, its others free.

    A fin's two other edges have no other face; on each edge the last fins (in face
    order) go while it has more than two faces.
    """
    n = int(f.max()) + 1
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2), axis=2)
    key = e[..., 0] * n + e[..., 1]
    _, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    uses = count[inv.reshape(-1, 3)]
    free = (uses == 1).sum(axis=1) == 2
    full = uses.max(axis=1) > 2
    cand = np.flatnonzero(free & full)
    edge = inv.reshape(-1, 3)[cand, np.argmax(uses[cand], axis=1)]
    order = np.lexsort((-cand, edge))  # per edge, the last faces first
    edge, cand = edge[order], cand[order]
    first = np.r_[0, np.flatnonzero(np.diff(edge)) + 1]
    rank = np.arange(len(edge)) - np.repeat(first, np.diff(np.r_[first, len(edge)]))
    out = np.zeros(len(f), dtype=bool)
    out[cand[rank < count[edge] - 2]] = True
    return out


def used_once(edges: np.ndarray) -> np.ndarray:
    """Whether each of the (E, 2) vertex pairs ``edges`` occurs once, either way round.

    Compiled (:func:`asrbf_mesh._holes_kernels.once`): on a filled Kinect frame's 1.8
    million half-edges, ``np.unique`` over one int64 key per pair took 0.35 s, the kernel
    0.05 s (``np.unique(..., axis=0)`` on the pairs themselves, 1.5 s on 1.2 million).
    """
    return _hk.once(edges)


def boundary_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges used by exactly one face, and that face's third vertex."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    third = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    once = used_once(e)
    return e[once], third[once]


def find_holes(xy: np.ndarray, faces: np.ndarray, spacing: float, *,
               bay_mouth: float | None = None, max_size: float | None = None
               ) -> tuple[list[Hole], int, Footprint]:
    """Holes of a triangulated height field and the count of outer-border edges.

    Parameters
    ----------
    xy : (N, 2) array
        Vertex positions in the view plane (physical units).
    faces : (F, 3) int array
        The scan's triangles.
    spacing : float
        Sampling spacing (physical units).
    bay_mouth : float, optional
        Bays of the outside behind mouths narrower than this are holes too
        (:meth:`~asrbf_mesh._footprint.Footprint.of`).
    max_size : float, optional
        With ``bay_mouth``: a hole larger than this is split into its bays, the parts
        at least twice as wide as ``bay_mouth`` joined to the rest only through narrower
        channels, each a hole of its own (filled up to its mouth), the rest one hole of
        the whole's size (left open). A
        disk punched next to an occlusion gap joins the gap (the one behind a bunny's
        tail, seen from the side: 26-30 % of the diagonal with the disk) and would stay
        open under ``--max-hole-size 20%``; its bay is the disk.

    Returns
    -------
    holes : list of Hole
        Largest first.
    border_edges : int
    footprint : Footprint
    """
    fp = Footprint.of(xy, faces, spacing, bay_mouth=bay_mouth)
    cell = fp.cell
    edges, third = boundary_edges(faces)
    a, b, c = xy[edges[:, 0]], xy[edges[:, 1]], xy[third]
    mid = 0.5 * (a + b)
    d = b - a
    nrm = np.column_stack([d[:, 1], -d[:, 0]])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    flip = np.einsum("ij,ij->i", nrm, c - mid) > 0  # point away from the edge's face
    nrm[flip] *= -1
    probes = [mid + t * cell * nrm for t in (0.3, 0.7, 1.2, 2.0)]
    holes, border = _holes_on(fp, edges, probes, xy)
    big = frozenset(h.label for h in holes if max_size is not None and h.size > max_size)
    if big and bay_mouth is not None:
        labels = _label_bays(fp.labels, big, 0.5 * bay_mouth / cell)
        if labels is not fp.labels:
            size = {h.label: h.size for h in holes}
            fp = Footprint(fp.lo, fp.cell, labels, fp.outside)
            holes, border = _holes_on(fp, edges, probes, xy)
            # what is left of a large hole (its channels) keeps the hole's size: it stays
            # open, as the whole would have
            holes = [Hole(h.label, h.edges, size[h.label]) if h.label in big else h
                     for h in holes]
    return holes, border, fp


def _holes_on(fp: Footprint, edges: np.ndarray, probes: list[np.ndarray], xy: np.ndarray
              ) -> tuple[list[Hole], int]:
    """Return the holes of the footprint's labels (largest first) and the border's edges.

    Each boundary edge takes the label of the first uncovered cell along ``probes``
    (points stepping away from its face).
    """
    lab = np.zeros(len(edges), dtype=np.int64)
    for q in probes:
        lab = np.where(lab == 0, fp.label_at(q), lab)
    is_out = np.isin(lab, list(fp.outside))
    holes = []
    for k in np.unique(lab[(lab > 0) & ~is_out]):
        e = edges[lab == k]
        if len(e) < 3:
            continue
        v = xy[np.unique(e)]
        holes.append(Hole(int(k), e, float(np.linalg.norm(v.max(0) - v.min(0)))))
    holes.sort(key=lambda h: -h.size)
    return holes, int(is_out.sum())


def chains(edges: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Split edges into ordered vertex chains, each with whether it is a closed loop."""
    adj: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    used: set[tuple[int, int]] = set()
    out = []
    starts = [v for v, n in adj.items() if len(n) != 2] + list(adj)
    for s in starts:
        for nxt in adj[s]:
            if (min(s, nxt), max(s, nxt)) in used:
                continue
            chain, prev, cur = [s], s, nxt
            used.add((min(s, nxt), max(s, nxt)))
            while True:
                chain.append(cur)
                step = [w for w in adj[cur] if (min(cur, w), max(cur, w)) not in used]
                if len(adj[cur]) != 2 or not step:
                    break
                prev, cur = cur, step[0]
                used.add((min(prev, cur), max(prev, cur)))
            loop = chain[-1] == chain[0]
            if loop:
                chain.pop()
            out.append((np.array(chain, dtype=np.int64), loop))
    return out
