"""The parameter-spec table of the asrbf filters and everything generated from it.

:data:`FILTERS` is the one table: per filter its name, a summary, a description and its
parameters (name, type, default, description). Argument checking, the defaults, the
printed parameter lists, :func:`filter_parameter_values` and the docstrings of the bound
``MeshSet`` methods all come from it.

Types, as :func:`print_filter_parameter_list` prints them (pymeshlab's spelling):

- ``bool``, ``int``, ``float``;
- ``str`` with choices (an enum: the name, or its index as pymeshlab accepts);
- ``PercentageValue``: a length, ``pymeshlab.PercentageValue`` (% of the bounding-box
  diagonal of the filter's mesh) or ``pymeshlab.PureValue`` (mesh units);
- ``int`` for a mesh too (as pymeshlab prints its ``sampledmesh``): the id of a mesh of
  the MeshSet (``-1``: the current mesh, where allowed).
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymeshlab

from asrbf_mesh._validate import _is_int  # the integer rule of check_int
from asrbf_mesh.errors import AsrbfError

__all__ = [
    "FILTERS",
    "FilterSpec",
    "InvalidEnumError",
    "Length",
    "MeshlabFilterError",
    "Param",
]


class MeshlabFilterError(pymeshlab.PyMeshLabException, AsrbfError):
    """Raised by the asrbf filters: a ``pymeshlab.PyMeshLabException`` and an ``AsrbfError``.

    Catch it as either: pymeshlab code catching ``PyMeshLabException`` and asrbf code
    catching ``AsrbfError`` both see it. Messages are one line.
    """


class InvalidEnumError(MeshlabFilterError, pymeshlab.InvalidEnumException):
    """A choice outside a parameter's choices (also a ``pymeshlab.InvalidEnumException``)."""


@dataclass(frozen=True)
class Length:
    """A validated length parameter: a percentage of a diagonal, or an absolute length.

    Attributes
    ----------
    value : float
        Percent (``percent`` True) or mesh units.
    percent : bool
        Whether ``value`` is a percentage of the bounding-box diagonal.
    """

    value: float
    percent: bool

    def absolute(self, diagonal: float) -> float:
        """Return the length in mesh units, given the bounding-box diagonal."""
        return self.value * diagonal / 100.0 if self.percent else self.value

    def __str__(self) -> str:
        return f"{self.value:g}%" if self.percent else f"{self.value:g}"


@dataclass(frozen=True)
class Param:
    """One filter parameter.

    Attributes
    ----------
    name : str
        Lowercase, as pymeshlab spells its parameters.
    kind : {"bool", "int", "float", "enum", "length", "mesh"}
        How values are checked (see the module docstring).
    default : object
        Default value; for ``length`` a percentage of the diagonal.
    description : str
        One or two sentences for the printed list and the docstrings.
    choices : tuple of str
        The names of an ``enum``.
    minimum : float, optional
        Smallest accepted value (``int``, ``float``, ``length``), inclusive.
    positive : bool
        ``float`` / ``length``: must be > 0 (instead of >= ``minimum``).
    special : int, optional
        ``int`` / ``mesh``: one more accepted value below ``minimum`` (``0`` meaning
        "automatic", ``-1`` meaning "the current mesh").
    """

    name: str
    kind: str
    default: Any
    description: str
    choices: tuple[str, ...] = ()
    minimum: float | None = None
    positive: bool = False
    special: int | None = None

    @property
    def type_name(self) -> str:
        """Type as :func:`print_filter_parameter_list` shows it (pymeshlab's words)."""
        return {"bool": "bool", "int": "int", "float": "float", "enum": "str",
                "length": "PercentageValue", "mesh": "int"}[self.kind]

    @property
    def default_text(self) -> str:
        """The default as :func:`print_filter_parameter_list` shows it."""
        if self.kind == "length":
            return f"{self.default:g}%"
        if self.kind == "enum":
            return repr(self.default)
        return str(self.default)

    def default_value(self) -> Any:
        """Return the default as a filter takes it (a fresh PercentageValue for lengths)."""
        if self.kind == "length":
            return pymeshlab.PercentageValue(float(self.default))
        return self.default

    # ------------------------------------------------------------------ checking

    def _type_error(self, what: str) -> MeshlabFilterError:
        return MeshlabFilterError(f"Parameter {self.name}: must be {what}. Other type values "
                                  "are not accepted.")

    def _range_error(self, value: Any, bound: str) -> MeshlabFilterError:
        return MeshlabFilterError(f"Parameter {self.name}: must be {bound}, got {value!r}.")

    def check(self, value: Any) -> Any:
        """Return ``value`` checked and normalized (``Length`` for lengths, names for enums).

        Raises
        ------
        MeshlabFilterError
            A value of the wrong type or out of range (pymeshlab's wording for lengths).
        InvalidEnumError
            An enum value that is not one of the choices.
        """
        kind = self.kind
        if kind == "bool":
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            if _is_int(value) and value in (0, 1):  # pymeshlab accepts 0 and 1 too
                return bool(value)
            raise self._type_error("a bool")
        if kind in ("int", "mesh"):
            if not _is_int(value):
                raise self._type_error("an int")
            v = int(value)
            if self.minimum is not None and v < self.minimum and v != self.special:
                bound = f">= {self.minimum:g}"
                if self.special is not None:
                    bound += f" (or {self.special})"
                raise self._range_error(v, bound)
            return v
        if kind == "float":
            if not (_is_int(value) or isinstance(value, (float, np.floating))):
                raise self._type_error("a float")
            v = float(value)
            self._check_number(v, value)
            return v
        if kind == "enum":
            return self._check_enum(value)
        if kind == "length":
            if isinstance(value, pymeshlab.PercentageValue):
                out = Length(float(value.value()), True)
            elif isinstance(value, pymeshlab.PureValue):
                out = Length(float(value.value()), False)
            else:  # pymeshlab's message to the letter (its missing space included)
                raise MeshlabFilterError(
                    f"Parameter {self.name}: must be a pymeshlab.Percentage object or a"
                    "pymeshlab.AbsoluteValue object. Other type values are not accepted.")
            self._check_number(out.value, value)
            return out
        raise AssertionError(f"unknown parameter kind {kind!r}")  # pragma: no cover

    def _check_number(self, v: float, given: Any) -> None:
        shown = str(Length(v, True)) if isinstance(given, pymeshlab.PercentageValue) else v
        if not math.isfinite(v):
            raise self._range_error(shown, "finite")
        if self.positive and v <= 0:
            raise self._range_error(shown, "> 0")
        if self.minimum is not None and v < self.minimum:
            raise self._range_error(shown, f">= {self.minimum:g}")

    def _check_enum(self, value: Any) -> str:
        if _is_int(value) and 0 <= int(value) < len(self.choices):
            return self.choices[int(value)]
        if isinstance(value, str) and value in self.choices:
            return value
        if not (isinstance(value, str) or _is_int(value)):
            raise self._type_error("a str (one of " + ", ".join(map(repr, self.choices)) + ")")
        listed = "".join(f"'{c}'; " for c in self.choices)  # pymeshlab's wording
        raise InvalidEnumError(f"Enum {value!r} not found. Possible values are {listed}"
                               f"(parameter {self.name}).")


@dataclass(frozen=True)
class FilterSpec:
    """One filter: its name, what it does, and its parameters in order."""

    name: str
    summary: str
    description: str
    params: tuple[Param, ...]

    def param(self, name: str) -> Param:
        """Return the parameter ``name``.

        Raises
        ------
        MeshlabFilterError
            pymeshlab's message for an unknown parameter.
        """
        for p in self.params:
            if p.name == name:
                return p
        raise MeshlabFilterError(f"Parameter {name} not found for filter {self.name}. Please "
                                 "check the documentation.")

    def check(self, params: dict[str, Any]) -> dict[str, Any]:
        """Return every parameter's checked value, defaults filled in.

        Raises
        ------
        MeshlabFilterError
            An unknown parameter name (pymeshlab's wording) or a bad value.
        """
        for name in params:
            self.param(name)
        return {p.name: p.check(params[p.name] if p.name in params else p.default_value())
                for p in self.params}

    def parameter_text(self) -> str:
        """Return the printed parameter list (pymeshlab's layout, plus descriptions)."""
        lines = [f"{self.name} filter - list of parameter names:"]
        for p in self.params:
            lines.append(f"\t{p.name} : {p.type_name} = {p.default_text}")
            lines += textwrap.wrap(p.description, 76, initial_indent="\t\t",
                                   subsequent_indent="\t\t")
        return "\n".join(lines)

    def docstring(self) -> str:
        """Return a numpydoc docstring for the bound ``MeshSet`` method."""
        out = [self.summary, "", *textwrap.wrap(self.description, 80), "", "Parameters",
               "----------"]
        for p in self.params:
            out.append(f"{p.name} : {p.type_name}, default {p.default_text}")
            out += textwrap.wrap(p.description, 80, initial_indent="    ",
                                 subsequent_indent="    ")
        out += ["", "Returns", "-------", "dict or None",
                "    What the filter reports (None when it reports nothing)."]
        return "\n".join(out)


# --------------------------------------------------------------------------- the table

_VIEW_AXES = ("z", "x", "y", "pca")

_SEED = Param("seed", "int", 0, "Seed of the network fit (same seed, same network). The fit "
              "of a layer is cached: filters on one unchanged layer fit it once.", minimum=0)
_PIECES = Param("pieces", "enum", "auto", "'auto': cut the scan at occlusion cliffs and "
                "walls and fit one network per smooth piece; '1': the paper's single "
                "network over the whole scan.", choices=("auto", "1"))
_VIEWAXIS = Param("viewaxis", "enum", "z", "Depth axis of the range scan's height field: "
                  "'z', 'x', 'y', or 'pca' (the points' least-variance direction).",
                  choices=_VIEW_AXES)

FILTERS: dict[str, FilterSpec] = {spec.name: spec for spec in (
    FilterSpec(
        "generate_surface_reconstruction_asrbf",
        "Surface Reconstruction: ASRBF network.",
        "Fits an adaptive Gaussian RBF network to the current mesh or point set (a range "
        "scan, z = f(x, y) in its view frame) and adds the network's surface, meshed on a "
        "regular grid, as a new layer '<source> (asrbf surface)'.",
        (
            Param("mode", "enum", "surface", "Where to mesh: 'surface' (the scan's "
                  "triangles; its holes stay open), 'footprint' (the scan's triangles and "
                  "the holes they enclose, filled by the network), 'hull' (a concave hull "
                  "of the points) or 'full' (the whole bounding square of the points).",
                  choices=("surface", "footprint", "hull", "full")),
            Param("resolution", "int", 0, "Grid samples along the longer side of the "
                  "points' extent; 0: the scan's own sampling spacing.", minimum=2,
                  special=0),
            Param("margin", "float", 0.0, "Mode 'full' only: extend the square by this "
                  "fraction of its size on every side (the network's extrapolation).",
                  minimum=0.0),
            _SEED,
            _PIECES,
            _VIEWAXIS,
        ),
    ),
    FilterSpec(
        "meshing_close_holes_asrbf",
        "Close Holes: ASRBF network.",
        "Fills the holes of the current mesh (a range scan) from a fitted network and adds "
        "the result as a new layer '<source> (asrbf filled)': the mesh's vertices and faces "
        "first, unchanged, then the fill. Added vertices have vertex quality 1 (others 0), "
        "new faces face quality 1. The scan's outer border is never filled. A pymeshlab "
        "Mesh cannot be edited in place, hence the new layer.",
        (
            Param("maxholesize", "length", 100.0, "Largest hole to fill, measured as the "
                  "diagonal of its bounding box in the view plane; 100% fills every hole.",
                  positive=True),
            Param("selected", "bool", False, "Only fill the holes with at least one "
                  "selected face on their rim."),
            Param("newfaceselected", "bool", True, "Select the new faces in the new layer."),
            _SEED,
            _PIECES,
            _VIEWAXIS,
        ),
    ),
    FilterSpec(
        "generate_lod_set_asrbf",
        "Levels of Detail: ASRBF network.",
        "Builds levels of detail of the current mesh or point set from fitted networks and "
        "adds one new layer per level, '<source> (asrbf LOD i)', level 0 the finest; the "
        "coarsest level is the current mesh afterwards.",
        (
            Param("levels", "int", 4, "Number of levels.", minimum=1),
            Param("method", "enum", "resample", "'resample': one network sampled on grids "
                  "from the scan's own spacing (level 0) to coarser ones; 'refit': one "
                  "network per level, fitted with a separation level D_min twice as large "
                  "per level.",
                  choices=("resample", "refit")),
            Param("targetfacenum", "int", 0, "About this many faces at level 0 (coarser "
                  "levels scale with it); 0: level 0 at the scan's own sampling spacing.",
                  minimum=1, special=0),
            Param("footprint", "bool", True, "Mesh only the scan's footprint (its "
                  "triangles); False: the whole bounding square."),
            Param("fillholes", "bool", False, "With 'footprint': also mesh the holes the "
                  "scan's triangles enclose (the network's surface over them)."),
            _SEED,
            _PIECES,
            _VIEWAXIS,
        ),
    ),
    FilterSpec(
        "compute_scalar_by_asrbf_residual_per_vertex",
        "Per-Vertex Quality: ASRBF residual.",
        "Fits a network to the current mesh or point set and stores each vertex's residual "
        "|z - f(x, y)| (mesh units, depth along the view axis) as its vertex quality, in "
        "place, like MeshLab's other per-vertex quality filters. The signed residual z - f "
        "is also kept in the custom per-vertex attribute 'asrbf_residual'.",
        (
            Param("signed", "bool", False, "Store the signed residual z - f instead of its "
                  "absolute value."),
            _SEED,
            _PIECES,
            _VIEWAXIS,
        ),
    ),
    FilterSpec(
        "get_metro_distance",
        "Metro Distance: symmetric, seeded.",
        "Metro distances between two meshes, both ways (Cignoni et al. 1998): every vertex "
        "plus a seeded uniform area sampling of each mesh, measured against the other. "
        "Returns get_hausdorff_distance's keys: 'max' (Hausdorff), 'mean', 'RMS' (mesh "
        "units), 'min', 'n_samples', 'diag_mesh_0' / 'diag_mesh_1' (bounding-box diagonals "
        "of the sampled and the target mesh). A target without faces is a point set: then "
        "only target -> sampled is measured.",
        (
            Param("sampledmesh", "mesh", -1, "The mesh under test; -1: the current mesh.",
                  minimum=0, special=-1),
            Param("targetmesh", "mesh", 0, "The reference mesh (or point set).", minimum=0),
            Param("samplenum", "int", 0, "Area samples per direction; 0: max(4 max(V0, V1), "
                  "10000) (V: referenced vertices).", minimum=1, special=0),
            Param("seed", "int", 0, "Seed of the area sampling (same seed, same figures).",
                  minimum=0),
            Param("savequality", "bool", False, "Store each vertex's distance to the target "
                  "as the vertex quality of the sampled mesh (as MeshLab's Hausdorff "
                  "filter does; custom attribute 'asrbf_metro_distance' too)."),
        ),
    ),
)}
