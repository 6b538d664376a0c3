"""nscd: non-smooth contact dynamics for rigid-block assemblies on a shaking base.

A Moreau-Jean time-stepping engine for rigid convex polygons (2D) and polyhedra (3D)
with exact Coulomb friction solved as second-order-cone programs (Clarabel), plus the
one-degree-of-freedom Housner rocking model and the analyses built on both.

Submodules are imported lazily, so ``import nscd`` is cheap and optional extras
(matplotlib, dask) are only needed by the parts that use them.
"""
from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_SUBMODULES = {
    "motion", "shapes", "shapes3d", "scene", "state", "contact", "solver", "stepper",
    "result", "rocking", "analysis", "sweep", "rigs", "io", "plot", "cli", "synthetic",
    "intensity", "lnec", "fclib", "model", "rotation", "builders", "batch", "stacked", "choose", "limit",
    "convergence", "events",
}

# public name -> submodule that defines it
_EXPORTS = {
    "Polygon": "shapes", "box": "shapes", "polygon": "shapes", "regular_polygon": "shapes",
    "Polyhedron": "shapes3d", "polyhedron": "shapes3d",
    "Scene": "scene", "Body": "scene",
    "State": "state",
    "Settings": "stepper", "Simulator": "stepper", "simulate": "stepper", "step": "stepper",
    "BatchSimulator": "batch", "simulate_batch": "batch",
    "Result": "result", "load": "result", "SolverSettings": "solver",
    "choose_model": "choose", "ModelChoice": "choose", "StackedBlocks": "stacked",
    "HousnerBlock": "rocking", "ElasticBrittle": "rocking", "ElastoPlastic": "rocking",
    "box3": "shapes3d", "chamfered_box": "shapes3d", "to_paraview": "io",
    "DoublePulseRig": "rigs", "DoublePulse": "rigs", "Table": "sweep",
    "stack": "builders", "wall": "builders", "arch": "builders", "drum": "builders",
    "column": "builders", "colonnade": "builders", "tilted_block": "builders",
    "Motion": "motion", "HalfSine": "motion", "OneSine": "motion", "OneCosine": "motion", "TypeCn": "motion",
    "Harmonic": "motion", "HanningSine": "motion", "Sweep": "motion", "Prescribed": "motion",
    "Record": "motion", "Scaled": "motion", "elcentro": "motion",
    "response_spectrum": "synthetic", "ec8_spectrum": "synthetic",
    "spectrum_compatible_records": "synthetic", "intensity_measures": "intensity",
}

__all__ = sorted(_SUBMODULES | set(_EXPORTS))


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"nscd.{name}")
    if name in _EXPORTS:
        module = importlib.import_module(f"nscd.{_EXPORTS[name]}")
        return getattr(module, name)
    raise AttributeError(f"module 'nscd' has no attribute {name!r}")
