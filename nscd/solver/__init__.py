"""Frictional contact solver: exact Coulomb friction (De Saxcé) by a conic fixed point.

One implementation, two entries:

- :func:`solve_velocity` — the velocity form of a Moreau–Jean step
  (``u~ = H v + offset``, ``v = v_free + M^-1 H^T P``), called by the stepper;
- :func:`solve_local` — the reaction form ``u = W r + q`` of FCLIB test problems.

Both reduce to ``u = W r + q`` and run :func:`nscd.solver.core.solve`: scaling, a
semismooth Newton fast path for small problems (compiled, :mod:`nscd.solver.small`),
a nonsmooth Gauss–Seidel for large ones (:mod:`nscd.solver.nsgs`, compiled), the Clarabel fixed point on the De Saxcé shift, and a Newton polish (see
:mod:`nscd.solver.core`). :func:`solve_batch` solves many independent small problems
in one compiled call. FCLIB problems
load with :func:`load_fclib` (= :func:`nscd.fclib.load`).
"""
from nscd.fclib import load as load_fclib
from nscd.solver.api import LocalSolution, VelocitySolution, fclib_merit, solve_local, solve_velocity
from nscd.solver.core import CoreResult, solve_batch
from nscd.solver.settings import SolverSettings, Status

__all__ = [
    "CoreResult", "LocalSolution", "SolverSettings", "Status", "VelocitySolution",
    "fclib_merit", "load_fclib", "solve_batch", "solve_local", "solve_velocity",
]
