"""A depth camera's mesh filled in the camera's projective frame, not in the view plane.

A depth frame meshed in metric camera coordinates is a perspective view: seen along the
camera axis from infinitely far (the view plane of :func:`~asrbf_mesh._holes.fill_holes`)
its walls seen at an angle fold over, and the shadow behind every near object is a gap
of the footprint under it, whose fill would cross the scan. Along the camera's own rays
it is a height field again. A mesh whose vertices lie on the frame's pixel lattice is
filled on that lattice as its depth image (:mod:`~asrbf_mesh._lattice`, in
``asrbf fill-holes``); this module takes the others (a frame's mesh decimated, rounded to
millimetres, merged from a cropped frame) and bare point clouds off the lattice
(voxel-downsampled, rounded): :func:`camera_frame` tells a perspective scan from a camera
at the origin, looking along z, by its triangles (it overlaps itself in the view plane,
not along the rays; a cloud is meshed in the image first, :func:`image_faces`), and
:func:`fill_in_camera` fills it in
the coordinates ``(c x / d, c y' / d, c^2 / d)`` (``d = |z|`` the depth, ``y'`` the image's
up, ``c`` the scan's median depth): image coordinates scaled to metres at the median
depth and inverse depth, in which a plane stays a plane and the scan is locally metric
near that depth, so hole sizes, spacings and the fill's rules keep their meaning there.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ._mesh import Mesh, Scan

__all__ = ["Camera", "camera_frame", "fill_in_camera", "image_faces"]

#: A mesh is filled in its camera's frame when at least this share of its vertices lies
#: under another of its triangles in the view plane (the mesh overlaps itself there: a
#: wall seen at an angle turned over, the far surface beside a near object's edge under
#: it; the TUM frames meshed in metric coordinates 7.7-20 %; of 60 random frames
#: (``tests/test_hole_camera.py``) 50 at 0.5-28 %, the other 10 at 0.03 % or 0; the
#: synthetic views, model views and the face map 0; the Stanford scans 0.1-1.5 %, but
#: their depths cross zero) ...
COVERED_MIN = 0.002
#: ... and at most this share of that along the rays (every camera frame above: 0; the
#: synthetic views in front of the origin: 11-30 %, far more than in their view plane).
COVERED_RATIO = 0.2
#: ... and every ray is within this tangent of the camera axis (a field of view of 127
#: degrees): a scan far off the axis is no camera's.
MAX_TAN = 2.0
#: A bare point cloud (a frame's points off its pixel lattice: voxel-downsampled,
#: rounded, cropped) is meshed in the image (:func:`image_faces`): Delaunay triangles
#: whose edges are at most this many times the local spacing (the mean distance to a
#: point's :data:`CLOUD_NEIGHBOURS` nearest in the image, the larger of its two ends) ...
CLOUD_LONGEST = 2.5
CLOUD_NEIGHBOURS = 6
#: The covered shares are measured on at most this many of the scan's vertices (a
#: seeded sample): on a TUM frame's mesh (204,859 vertices, 397,101 triangles) both
#: shares took 1.4 s of `fill-holes` measured on every vertex; the thresholds above lie
#: far from every share measured (0.2 % against 0.03 % or 0.5 % and more), where a
#: sample of 50,000 has a standard error of 0.02 % (at the threshold) or less.
COVER_SAMPLE = 50_000
#: The fill's new vertices are held within these factors of the scan's nearest and
#: farthest inverse depths (a guard: no vertex at infinity or behind the camera).
_W_RANGE = (0.5, 2.0)


@dataclass(frozen=True)
class Camera:
    """The projective frame of a camera at the origin looking along ``sign`` x z.

    ``sign`` -1 for OpenGL camera coordinates (looking along -z, +y up), +1 for OpenCV's
    (along +z, +y down); ``c`` the scan's median depth (the frame's scale);
    ``covered_view``, ``covered_rays``: the share of the scan's vertices under another of
    its triangles in the view plane and along the rays; ``faces``: a bare point cloud's
    triangles, made in the image (:func:`image_faces`; None for a mesh).
    """

    sign: float
    c: float
    covered_view: float
    covered_rays: float
    faces: np.ndarray | None = dataclasses.field(default=None, repr=False, compare=False)

    def to_frame(self, p: np.ndarray) -> np.ndarray:
        """World points to ``(c x / d, c y' / d, c^2 / d)`` (y' = -sign y: the image's up)."""
        d = self.sign * p[:, 2]
        return np.column_stack([self.c * p[:, 0] / d, -self.sign * self.c * p[:, 1] / d,
                                self.c * self.c / d])

    def from_frame(self, q: np.ndarray) -> np.ndarray:
        """Map frame points back to world points (the inverse of :meth:`to_frame`)."""
        d = self.c * self.c / q[:, 2]
        return np.column_stack([q[:, 0] * d / self.c, -self.sign * q[:, 1] * d / self.c,
                                self.sign * d])


def _covered(xy: np.ndarray, faces: np.ndarray) -> float:
    """Share of the points ``xy`` strictly inside one of the 12 triangles nearest them.

    Measured on :data:`COVER_SAMPLE` of the points at most (seeded: the same share each
    time).
    """
    from scipy.spatial import cKDTree

    from . import _holes_kernels as _hk

    at = xy
    if len(xy) > COVER_SAMPLE:
        at = xy[np.random.default_rng(0).choice(len(xy), COVER_SAMPLE, replace=False)]
    _, cand = cKDTree(xy[faces].mean(axis=1)).query(at, k=min(12, len(faces)), workers=-1)
    return float(_hk.inside_any(at, xy, faces, cand).mean())


def _looking(p: np.ndarray) -> tuple[float, np.ndarray] | None:
    """``(sign, depths)`` if ``p`` lies in front of a camera at the origin on its z axis.

    Every depth ``sign z`` above zero, every ray within :data:`MAX_TAN` of the axis.
    """
    z = p[:, 2]
    sign = 1.0 if np.median(z) > 0 else -1.0
    d = sign * z
    if not np.all(d > 0):
        return None
    with np.errstate(all="ignore"):
        tan = np.abs(p[:, :2] / d[:, None])
    if not (np.all(np.isfinite(tan)) and tan.max() <= MAX_TAN):
        return None
    return sign, d


def image_faces(p: np.ndarray, cam: Camera) -> np.ndarray:
    """Triangulate a camera's bare point cloud ``p`` in its image, depth jumps cut.

    Delaunay in the image; a triangle is dropped when an edge is longer than
    :data:`CLOUD_LONGEST` local spacings, or steeper than a range grid's jump rule
    (:data:`~asrbf_mesh._range.DEFAULT_JUMP` times its lateral footprint at its depth),
    as a depth image is meshed.
    """
    from scipy.spatial import cKDTree

    from ._range import DEFAULT_JUMP
    from ._triangle import delaunay

    q = cam.to_frame(p)[:, :2]
    tris = delaunay(q)
    if len(tris) == 0:
        return tris
    d = cam.sign * p[:, 2]
    k = min(CLOUD_NEIGHBOURS, len(p) - 1)
    dist, _ = cKDTree(q).query(q, k=k + 1)
    spacing = dist[:, 1:].mean(axis=1)
    keep = np.ones(len(tris), dtype=bool)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        a, b = tris[:, i], tris[:, j]
        edge = np.hypot(q[a, 0] - q[b, 0], q[a, 1] - q[b, 1])
        keep &= edge <= CLOUD_LONGEST * np.maximum(spacing[a], spacing[b])
        keep &= np.abs(d[a] - d[b]) <= DEFAULT_JUMP * edge / cam.c * (d[a] + d[b]) / 2
    return tris[keep]


def camera_frame(scan: Scan) -> Camera | None:
    """Return the camera frame of a perspective scan from a camera at the origin, or None.

    A scan whose depths ``|z|`` are all of one sign and above zero, whose rays are all
    within :data:`MAX_TAN` of the z axis, and which overlaps itself in the view plane
    (:data:`COVERED_MIN` of its vertices or more under another of its triangles) much
    more than along the rays (:data:`COVERED_RATIO` of that at most). A bare point cloud
    is meshed in the image first (:func:`image_faces`; then nothing overlaps along the
    rays): a camera's turns over in the view plane (a TUM frame voxel-downsampled to
    1 cm: 18 %), a height field's seen from a point in front of it does not (the
    synthetic and model views 0.6, 1 and 3 extents in front of the origin: 0.05 % at
    most).
    """
    faces, p = scan.faces, scan.points
    cloud = faces is None or len(faces) == 0
    if len(p) < 3 or (not cloud and len(faces) < 2):
        return None
    looking = _looking(p)
    if looking is None:
        return None
    sign, d = looking
    cam = Camera(sign, float(np.median(d)), 0.0, 0.0)
    with np.errstate(all="ignore"):
        q = cam.to_frame(p)
    if not np.all(np.isfinite(q)):
        return None  # (a depth so near zero that its inverse overflows)
    if cloud:
        faces = image_faces(p, cam)
        if len(faces) < 2:
            return None
    view = _covered(p[:, :2], faces)
    if view < COVERED_MIN:
        return None
    if cloud:
        return dataclasses.replace(cam, covered_view=view, faces=faces)
    rays = _covered(q[:, :2], faces)
    if rays > COVERED_RATIO * view:
        return None
    return dataclasses.replace(cam, covered_view=view, covered_rays=rays)


def fill_in_camera(fill, scan: Scan, cam: Camera, limit: float | None, diag: float,
                   t0: float, **kw):
    """Fill ``scan`` in ``cam``'s frame with ``fill`` (:func:`~asrbf_mesh._holes.fill_holes`).

    The scan's vertices come back as they were; the fill's through the inverse map
    (their inverse depths held within :data:`_W_RANGE` of the scan's). Hole sizes are
    measured in the frame (the image, scaled to the median depth), ``limit`` (scan
    units) with them; their % is of the scan's own diagonal, their centres in world
    coordinates. The network returned is the frame's; ``seconds`` counts from ``t0``
    (:func:`time.perf_counter`, the caller's start).
    """
    q = cam.to_frame(scan.points)
    faces = scan.faces if cam.faces is None else cam.faces
    res = fill(Scan(q, faces, source=scan.source), None, max_hole_size=limit,
               frame="view", **kw)
    n = len(scan.points)
    added = res.mesh.vertices[n:].copy()
    w = q[:, 2]
    added[:, 2] = np.clip(added[:, 2], _W_RANGE[0] * w.min(), _W_RANGE[1] * w.max())
    vertices = np.vstack([scan.points, cam.from_frame(added)])
    holes = tuple(dataclasses.replace(
        h, size_pct=100.0 * h.size_abs / diag,
        centre=tuple(float(v) for v in cam.from_frame(np.array([h.centre]))[0]))
        for h in res.holes)
    mesh = Mesh(vertices, res.mesh.faces, vertex_quality=res.mesh.vertex_quality)
    return dataclasses.replace(res, mesh=mesh, holes=holes, frame="camera",
                               seconds=time.perf_counter() - t0)
