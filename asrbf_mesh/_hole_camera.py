"""A depth camera's mesh filled in the camera's projective frame, not in the view plane.

A depth frame meshed in metric camera coordinates is a perspective view: seen along the
camera axis from infinitely far (the view plane of :func:`~asrbf_mesh._holes.fill_holes`)
its walls seen at an angle fold over, and the shadow behind every near object is a gap
of the footprint under it, whose fill would cross the scan. Along the camera's own rays
it is a height field again. A mesh whose vertices lie on the frame's pixel lattice is
filled on that lattice as its depth image (:mod:`~asrbf_mesh._lattice`, in
``asrbf fill-holes``); this module takes the others (a frame's mesh decimated, rounded to
millimetres, merged from a cropped frame): :func:`camera_frame` tells a perspective
mesh from a camera at the origin, looking along z, by its triangles (it overlaps itself in
the view plane, not along the rays), and :func:`fill_in_camera` fills it in
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

__all__ = ["Camera", "camera_frame", "fill_in_camera"]

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
#: The fill's new vertices are held within these factors of the scan's nearest and
#: farthest inverse depths (a guard: no vertex at infinity or behind the camera).
_W_RANGE = (0.5, 2.0)


@dataclass(frozen=True)
class Camera:
    """The projective frame of a camera at the origin looking along ``sign`` x z.

    ``sign`` -1 for OpenGL camera coordinates (looking along -z, +y up), +1 for OpenCV's
    (along +z, +y down); ``c`` the scan's median depth (the frame's scale);
    ``covered_view``, ``covered_rays``: the share of the scan's vertices under another of
    its triangles in the view plane and along the rays.
    """

    sign: float
    c: float
    covered_view: float
    covered_rays: float

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
    """Share of the points ``xy`` strictly inside one of the 12 triangles nearest them."""
    from scipy.spatial import cKDTree

    from . import _holes_kernels as _hk

    _, cand = cKDTree(xy[faces].mean(axis=1)).query(xy, k=min(12, len(faces)))
    return float(_hk.inside_any(xy, xy, faces, cand).mean())


def camera_frame(scan: Scan) -> Camera | None:
    """Return the camera frame of a perspective mesh from a camera at the origin, or None.

    A triangulated scan whose depths ``|z|`` are all of one sign and above zero, whose
    rays are all within :data:`MAX_TAN` of the z axis, and which overlaps itself in the
    view plane (:data:`COVERED_MIN` of its vertices or more under another of its
    triangles) much more than along the rays (:data:`COVERED_RATIO` of that at most). A
    bare point cloud has no triangles to tell by: None.
    """
    faces, p = scan.faces, scan.points
    if faces is None or len(faces) < 2 or len(p) < 3:
        return None
    z = p[:, 2]
    sign = 1.0 if np.median(z) > 0 else -1.0
    d = sign * z
    if not np.all(d > 0):
        return None
    with np.errstate(all="ignore"):
        tan = np.abs(p[:, :2] / d[:, None])
    if not (np.all(np.isfinite(tan)) and tan.max() <= MAX_TAN):
        return None
    view = _covered(p[:, :2], faces)
    if view < COVERED_MIN:
        return None
    cam = Camera(sign, float(np.median(d)), view, 0.0)
    q = cam.to_frame(p)
    if not np.all(np.isfinite(q)):
        return None
    rays = _covered(q[:, :2], faces)
    if rays > COVERED_RATIO * view:
        return None
    return dataclasses.replace(cam, covered_rays=rays)


def fill_in_camera(fill, scan: Scan, cam: Camera, limit: float | None, diag: float,
                   **kw):
    """Fill ``scan`` in ``cam``'s frame with ``fill`` (:func:`~asrbf_mesh._holes.fill_holes`).

    The scan's vertices come back as they were; the fill's through the inverse map
    (their inverse depths held within :data:`_W_RANGE` of the scan's). Hole sizes are
    measured in the frame (the image, scaled to the median depth), ``limit`` (scan
    units) with them; their % is of the scan's own diagonal, their centres in world
    coordinates. The network returned is the frame's.
    """
    t0 = time.perf_counter()
    q = cam.to_frame(scan.points)
    res = fill(Scan(q, scan.faces, source=scan.source), None, max_hole_size=limit,
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
                               seconds=res.seconds + time.perf_counter() - t0)
