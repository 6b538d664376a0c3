"""The one solver core: a frictional contact problem in reaction form ``u = W r + q``.

Both public entries end here: :func:`nscd.solver.solve_local` passes FCLIB's ``W, q``;
:func:`nscd.solver.solve_velocity` condenses the velocity form to the Delassus
operator ``W = H M^-1 H^T`` (kept sparse for large assemblies) and ``q = H v_free +
offset``. The stages, each reported in the counters:

1. **Scaling.** Per contact ``c`` a factor ``d_c = 1 / sqrt(max diag W_cc)`` and one
   global ``sigma = ||D q||_inf``: ``r = sigma D r'``, ``u = sigma D^-1 u'``. A
   per-contact scalar maps each Coulomb cone onto itself, so the scaled problem is
   of the same kind with unit diagonal and unit ``q`` (FCLIB has ``|q| ~ 1e-15`` and
   ``W ~ 1e6``). The merit is always evaluated on the unscaled data.
2. **Fast path** (at most ``fast_path_unknowns`` unknowns, the engine's case):
   semismooth Newton on the natural map from the warm start (:mod:`.newton`).
3. **Conic fixed point.** For a fixed De Saxcé shift ``s_c = mu_c ||u_T,c||`` the
   problem is a convex SOCP solved by Clarabel (:mod:`.conic`, on the symmetrised
   ``W``); ``s`` is iterated, under-relaxed by 1/2 whenever the merit fails to
   improve, and declared cycling after ``_STALE`` iterations without improvement.
4. **Polish.** The interior point stops ~1e-6 short on degenerate contacts (``r``
   and ``u`` both near the cone tip); Newton from its best iterate finishes the job.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from nscd.solver import cone, newton
from nscd.solver.conic import ConicSubproblem
from nscd.solver.settings import SolverSettings, Status

# Fixed-point iterations without a better merit before the shift is declared cycling.
_STALE = 4
# Relative asymmetry of W above which the conic subproblem uses (W + W^T)/2 (noted).
_ASYMMETRY = 1e-12
# Diagonal regularisation (scaled units, where diag W = 1) added to the conic
# subproblem only when Clarabel fails on the plain (semidefinite or slightly
# indefinite) W; the merit and the polish always use W as given.
_REGULARISATION = 1e-7


@dataclass
class CoreResult:
    """Unscaled outcome of :func:`solve` (see the public solution classes for meanings)."""

    r: np.ndarray
    u: np.ndarray
    merit: float
    status: Status
    path: str
    fast_iterations: int = 0
    fixed_point_iterations: int = 0
    interior_point_iterations: int = 0
    polish_iterations: int = 0
    notes: list[str] = field(default_factory=list)
    message: str = ""


def _scale(W, q: np.ndarray, dim: int):
    """Per-contact Jacobi factors ``d`` (shape (n,)) and the global factor ``sigma``."""
    diag = np.asarray(W.diagonal(), dtype=float).reshape(-1, dim).max(axis=1)
    floor = max(float(diag.max()), 1.0) * 1e-14 if diag.size else 1.0
    d = np.repeat(1.0 / np.sqrt(np.maximum(diag, floor)), dim)
    sigma = float(np.max(np.abs(d * q))) if q.size else 0.0
    return d, sigma


def _symmetrised(Ws, notes: list[str]):
    """``(Ws + Ws^T)/2`` when ``Ws`` is measurably unsymmetric (recorded in ``notes``)."""
    if sp.issparse(Ws):
        gap = abs(Ws - Ws.T).max()
        size = abs(Ws).max()
    else:
        gap = np.max(np.abs(Ws - Ws.T))
        size = np.max(np.abs(Ws))
    if gap > _ASYMMETRY * size:
        notes.append(f"symmetrised W for the conic subproblem (relative asymmetry {gap / size:.1e})")
        return (Ws + Ws.T) * 0.5
    return Ws


def solve(W, q: np.ndarray, mu: np.ndarray, dim: int, settings: SolverSettings,
          r0: np.ndarray | None = None) -> CoreResult:
    """Solve ``K_mu ∋ r ⊥ W r + q + mu ||u_T|| e_N ∈ K_mu*`` (validated input).

    Parameters
    ----------
    W : ndarray or scipy.sparse.csr_matrix, shape (n, n)
        Delassus matrix, ``n = m * dim``; rows per contact ``[N, T1, (T2)]``.
    q : ndarray, shape (n,)
        Free relative velocity.
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    settings : SolverSettings
    r0 : ndarray, shape (n,), optional
        Warm start for the impulses.

    Returns
    -------
    CoreResult
    """
    m = mu.size
    exact = settings.exact
    q_norm = float(np.linalg.norm(q))
    d, sigma = _scale(W, q, dim)
    if sigma == 0.0:
        # q == 0: r = 0, u = 0 satisfies the complementarity exactly.
        return CoreResult(np.zeros_like(q), q.copy(), 0.0, Status.CONVERGED, "trivial (q = 0)")
    if sp.issparse(W):
        Dm = sp.diags(d)
        Ws = (Dm @ W @ Dm).tocsr()
    else:
        Ws = W * d[:, None] * d[None, :]
    qs = q * d / sigma

    def stop(r_s: np.ndarray, u_s: np.ndarray) -> tuple[float, bool]:
        value = cone.merit((sigma * d * r_s).reshape(m, dim), (sigma * u_s / d).reshape(m, dim),
                           mu, q_norm, exact)
        return value, value <= settings.tol

    def finish(r_s: np.ndarray, status: Status, path: str, **counters) -> CoreResult:
        r = sigma * d * r_s
        u = sigma * (Ws @ r_s + qs) / d
        value = cone.merit(r.reshape(m, dim), u.reshape(m, dim), mu, q_norm, exact)
        return CoreResult(r, u, value, status, path, **counters)

    start = np.zeros_like(q) if r0 is None else r0 / (sigma * d)
    counters: dict = {"notes": []}
    if q.size <= settings.fast_path_unknowns:
        fast = newton.solve(Ws, qs, mu, dim, start, exact, settings.max_fast, stop)
        counters["fast_iterations"] = fast.iterations
        if fast.converged:
            return finish(fast.r, Status.CONVERGED, "newton (fast path)", **counters)

    conic = ConicSubproblem(_symmetrised(Ws, counters["notes"]), mu, dim, settings.tol_gap_abs,
                            settings.tol_gap_rel, settings.tol_feas, settings.max_interior_point)
    shift = np.zeros(m)
    if exact and r0 is not None:
        us = (Ws @ start + qs).reshape(m, dim)
        shift = mu * np.linalg.norm(us[:, 1:], axis=1)
    best_r, best_merit = None, np.inf
    stale, cycling, regularised, failure = 0, False, False, ""
    fp_iters = ip_iters = 0
    while fp_iters < settings.max_fixed_point:
        q_shift = qs.copy()
        q_shift[::dim] += shift
        res = conic.solve(q_shift)
        fp_iters += 1
        ip_iters += res.iterations
        if not res.ok:
            failure = f"Clarabel: {res.status}"
            if best_r is None and not regularised:
                # Semidefinite or slightly indefinite W: retry once with a tiny ridge.
                regularised = True
                counters["notes"].append(f"regularised W + {_REGULARISATION:g} I (scaled) for the conic subproblem")
                Wreg = _symmetrised(Ws, []) + _REGULARISATION * (sp.identity(q.size) if sp.issparse(Ws) else np.eye(q.size))
                conic = ConicSubproblem(Wreg, mu, dim, settings.tol_gap_abs, settings.tol_gap_rel,
                                        settings.tol_feas, settings.max_interior_point)
                continue
            counters["notes"].append(failure)
            if best_r is None and np.all(np.isfinite(res.r)):
                best_r, best_merit = res.r, stop(res.r, Ws @ res.r + qs)[0]
            break
        us = Ws @ res.r + qs
        value, done = stop(res.r, us)
        if value < best_merit:
            best_r, best_merit, stale = res.r, value, 0
        else:
            stale += 1
        if done or not exact or (settings.polish and value <= settings.polish_below):
            break
        new_shift = mu * np.linalg.norm(us.reshape(m, dim)[:, 1:], axis=1)
        change = np.max(np.abs(new_shift - shift))
        if change <= settings.fixed_point_tol * (1.0 + np.max(np.abs(shift))):
            break
        if stale >= _STALE:
            cycling = True
            counters["notes"].append(f"De Saxcé shift cycling after {fp_iters} conic solves")
            break
        shift = new_shift if stale == 0 else 0.5 * (shift + new_shift)
    counters.update(fixed_point_iterations=fp_iters, interior_point_iterations=ip_iters)
    if best_merit <= settings.tol:
        return finish(best_r, Status.CONVERGED, "interior point", **counters)

    origin = best_r if best_r is not None else start
    path = "interior point"
    if settings.polish:
        polished = newton.solve(Ws, qs, mu, dim, origin, exact, settings.max_polish, stop)
        counters["polish_iterations"] = polished.iterations
        path = "interior point + polish"
        if polished.converged:
            return finish(polished.r, Status.POLISHED, path, **counters)
        if polished.merit < best_merit:
            origin, best_merit = polished.r, polished.merit
    if best_r is None:
        status = Status.NUMERICAL_FAILURE
    elif cycling:
        status = Status.CYCLING
    else:
        status = Status.STALLED
    result = finish(origin, status, path, **counters)
    result.message = f"merit {result.merit:.3e} > tol {settings.tol:.1e}" + (f" ({failure})" if failure else "")
    return result
