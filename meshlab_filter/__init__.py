"""MeshLab-style asrbf filters on ``pymeshlab.MeshSet``: fit, fill holes, LOD, residual, Metro.

The filters follow pymeshlab's conventions: names with its verb prefixes, keyword
arguments only, lowercase parameter names as pymeshlab spells them, lengths as
``pymeshlab.PercentageValue`` (% of the bounding-box diagonal) or ``pymeshlab.PureValue``,
and ``pymeshlab.PyMeshLabException`` (with pymeshlab's wording) for unknown or mistyped
parameters. ``generate_*`` and ``meshing_*`` filters add new layers (a mesh in a MeshSet
cannot be edited in place); ``compute_*`` writes vertex quality of the current mesh in
place; ``get_*`` returns a dict.

======================================================  ===================================
``generate_surface_reconstruction_asrbf``               the network surface, a new layer
``meshing_close_holes_asrbf``                           holes filled, a new layer
``generate_lod_set_asrbf``                              one new layer per level of detail
``compute_scalar_by_asrbf_residual_per_vertex``         ``|z - f|`` as vertex quality
``get_metro_distance``                                  symmetric Metro distances (a dict)
======================================================  ===================================

Filters on one unchanged layer share one fit: the networks are cached per MeshSet, layer
id and vertex content (:data:`cache`, a few entries).

Examples
--------
>>> import pymeshlab, asrbf_mesh, meshlab_filter as mf             # doctest: +SKIP
>>> ms = pymeshlab.MeshSet()                                       # doctest: +SKIP
>>> ms.load_new_mesh(str(asrbf_mesh.face_map_path()))              # doctest: +SKIP
>>> mf.register()            # bind the filters as MeshSet methods  # doctest: +SKIP
>>> ms.meshing_close_holes_asrbf(maxholesize=pymeshlab.PercentageValue(5))  # doctest: +SKIP
>>> mf.apply_filter(ms, "get_metro_distance", targetmesh=0)        # doctest: +SKIP
"""

from __future__ import annotations

from ._filters import (
    apply_filter,
    cache,
    filter_list,
    filter_parameter_values,
    print_filter_list,
    print_filter_parameter_list,
    register,
    unregister,
)
from ._params import FILTERS, InvalidEnumError, MeshlabFilterError
from .script import ScriptError, check_script, load_script, run_script, run_script_file

__all__ = [
    "FILTERS",
    "InvalidEnumError",
    "MeshlabFilterError",
    "ScriptError",
    "apply_filter",
    "cache",
    "check_script",
    "filter_list",
    "filter_parameter_values",
    "load_script",
    "print_filter_list",
    "print_filter_parameter_list",
    "register",
    "run_script",
    "run_script_file",
    "unregister",
]
