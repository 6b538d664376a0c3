"""The convex conic subproblem for a fixed De Saxcé shift, solved by Clarabel.

For a fixed shift ``s`` (``s_c = mu_c ||u_T,c||`` from the previous iterate) the
problem ``K_mu ∋ r ⊥ W r + q + s e_N ∈ K_mu*`` is the optimality system of the
convex second-order-cone QP

    min_r  1/2 r^T W r + (q + s e_N)^T r    subject to  r_c ∈ K_mu,c,

written for Clarabel as ``A r + z = 0``, ``z ∈ cone`` with, per contact,
``z = (mu r_N, r_T) ∈ SOC(dim)`` (so ``A = -diag(mu, 1, 1)``) when ``mu > 0``, and
``r_N >= 0`` (nonnegative cone), ``r_T = 0`` (zero cone) when ``mu == 0``. The KKT
conditions give ``W r + q + s e_N = -A^T y = (mu y_N, y_T)`` with the conic dual
``y ∈ SOC``, i.e. ``u + s e_N ∈ K_mu*`` and ``y^T z = 0`` is ``r ⊥ u + s e_N``: the
primal ``r`` is the impulse, the dual is the shifted velocity up to the 1/mu scaling.

Only ``q`` changes between fixed-point iterations; the Clarabel solver object is
built once and updated in place (``DefaultSolver.update(q=...)``).
"""
from __future__ import annotations

from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.sparse as sp

_OK = (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved)


@dataclass
class ConicResult:
    """One Clarabel solve: impulses ``r``, conic duals ``y`` (rows in cone order), success, IPM iterations, status."""

    r: np.ndarray
    y: np.ndarray
    ok: bool
    iterations: int
    status: str


class ConicSubproblem:
    """Clarabel model of the shifted problem, built once per contact problem.

    Parameters
    ----------
    W : ndarray or scipy.sparse matrix, shape (n, n)
        Symmetric positive semidefinite Delassus matrix (scaled units), ``n = m * dim``.
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    tol_gap_abs, tol_gap_rel, tol_feas : float
        Clarabel tolerances.
    max_iter : int
        Clarabel iteration limit.
    """

    def __init__(self, W, mu: np.ndarray, dim: int, tol_gap_abs: float, tol_gap_rel: float,
                 tol_feas: float, max_iter: int) -> None:
        m = mu.size
        n = m * dim
        self._P = sp.triu(sp.csc_matrix(W)).tocsc()
        rows, cols, vals, cones = [], [], [], []
        row = 0
        friction = np.flatnonzero(mu > 0.0)
        frictionless = np.flatnonzero(mu <= 0.0)
        for c in friction:
            rows.extend(range(row, row + dim))
            cols.extend(range(c * dim, (c + 1) * dim))
            vals.extend([-mu[c]] + [-1.0] * (dim - 1))
            row += dim
        if friction.size:
            cones.extend([clarabel.SecondOrderConeT(dim)] * friction.size)
        if frictionless.size:
            rows.extend(range(row, row + frictionless.size))
            cols.extend(frictionless * dim)
            vals.extend([-1.0] * frictionless.size)
            row += frictionless.size
            cones.append(clarabel.NonnegativeConeT(int(frictionless.size)))
            tangent = (frictionless[:, None] * dim + np.arange(1, dim)).ravel()
            rows.extend(range(row, row + tangent.size))
            cols.extend(tangent)
            vals.extend([1.0] * tangent.size)
            row += tangent.size
            cones.append(clarabel.ZeroConeT(int(tangent.size)))
        self._A = sp.csc_matrix((vals, (rows, cols)), shape=(row, n))
        self._b = np.zeros(row)
        self._cones = cones
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.tol_gap_abs = tol_gap_abs
        settings.tol_gap_rel = tol_gap_rel
        settings.tol_feas = tol_feas
        settings.max_iter = max_iter
        settings.presolve_enable = False
        self._settings = settings
        self._solver = None

    def solve(self, q: np.ndarray) -> ConicResult:
        """Solve ``min 1/2 r^T W r + q^T r`` over the cones (``q`` already shifted).

        Parameters
        ----------
        q : ndarray, shape (n,)
            Linear term ``q + s e_N`` (scaled units).

        Returns
        -------
        ConicResult
        """
        # In-place data updates (clarabel >= 0.10) keep the symbolic factorisation; they
        # need presolve off (set above) and no dropped structural zeros (the default).
        if self._solver is None or not getattr(self._solver, "is_data_update_allowed", lambda: False)():
            self._solver = clarabel.DefaultSolver(self._P, q, self._A, self._b, self._cones, self._settings)
        else:
            self._solver.update(q=q)
        sol = self._solver.solve()
        r = np.asarray(sol.x, dtype=float)
        ok = sol.status in _OK and bool(np.all(np.isfinite(r)))
        return ConicResult(r, np.asarray(sol.z, dtype=float), ok, int(sol.iterations), str(sol.status))
