"""The one solver core: a frictional contact problem in reaction form ``u = W r + q``.

Both public entries end here: :func:`nscd.solver.solve_local` passes FCLIB's ``W, q``;
:func:`nscd.solver.solve_velocity` condenses the velocity form to the Delassus
operator ``W = H M^-1 H^T`` and ``q = H v_free + offset`` (``M`` block diagonal, so
``M^-1`` and ``W`` stay sparse for large assemblies; ``W`` couples only contacts that
share a body). Why condense rather than solve Clarabel's QP in the velocities: the
Newton fast path and polish need ``W`` anyway; the conic problem then has ``m dim``
unknowns instead of ``n``; and FCLIB's reaction-form problems use the very same code.

The stages, each reported in the counters:

1. **Scaling.** Per contact ``c`` a factor ``d_c = 1 / sqrt(W_NN,c)`` (normal
   diagonal) and one global ``sigma = ||D q||_inf``: ``r = sigma D r'``,
   ``u = sigma D^-1 u'``. A per-contact scalar maps each Coulomb cone onto itself, so
   the scaled problem is of the same kind with unit normal diagonal and unit ``q``
   (FCLIB has ``|q| ~ 1e-15`` and ``W ~ 1e6``). The merit is always evaluated on the
   unscaled data.
2. **Fast path** (at most ``fast_path_unknowns`` unknowns: the engine's steps and the
   small FCLIB problems): semismooth Newton on the natural map from the warm start,
   compiled (:mod:`.small`, ``W`` formed dense); accepted only at merit <= ``tol``. A problem
   it does not accept goes through the proximal-point outer loop from the Newton's best
   iterate (:mod:`.proximal`: problems with ``W + alpha diag(W_NN)``, each solved warm by the
   same compiled Newton, whose fixed point solves the original problem; compiled too, in the
   same call as the Newton, :func:`newton_batch`), then, if that stalls, to the conic fixed
   point (4.) and the polish (:func:`solve_rejected`). :func:`solve_batch` runs the compiled
   kernels over many problems in one call.
3. **Large problems** (more than ``large_problem_unknowns`` unknowns):
   nonsmooth block Gauss–Seidel with exact local solves and Anderson acceleration
   (:mod:`.nsgs`), stopped by the same merit test every ``sweeps_per_check`` sweeps;
   a problem the sweeps leave above ``tol`` (``max_sweeps`` reached, or stalled) is
   polished by Newton from the best sweep when within ``polish_below``, then (at most
   ``proximal_unknowns`` unknowns) given the proximal-point iterations on ``W`` formed dense,
   and if those fail goes on to the conic fixed point from its own warm start (noted) — unless
   it has more than ``max_conic_unknowns`` unknowns: then the best iterate is returned,
   ``STALLED`` (a bounded cost per step for time stepping).
4. **Conic fixed point.** For a fixed De Saxcé shift ``s_c = mu_c ||u_T,c||`` the
   problem is a convex SOCP solved by Clarabel (:mod:`.conic`) on ``(W + W^T)/2``;
   the shift (plus the skew part of an unsymmetric ``W`` times ``r``) is iterated,
   Anderson-accelerated (depth 5; history dropped and the step under-relaxed by halves
   whenever the merit rises), and handed to the polish when it
   stalls, cycles or reaches ``polish_below``.
5. **Polish.** The interior point stops 1e-7..1e-5 short on degenerate contacts (``r``
   and ``u`` both near the cone tip, semidefinite ``W``); the regularised Newton,
   started from the best conic iterate, takes it to ``tol``: compiled (:mod:`.small`, the
   fast path's kernel) for a dense ``W`` of at most ``large_problem_unknowns`` unknowns,
   :mod:`.newton` with scipy's factorisations for the sparse ``W`` of large problems.
6. **Regimes** (2D, exact Coulomb, at most ``regime_contacts`` contacts): a
   small problem that every route above leaves above ``tol`` (a contact whose impulse is
   many orders below its neighbours', at the apex of its cone) is solved exactly by
   choosing each contact's regime (open, sticking, slipping either way) and solving the
   linear system of the choice, the choices tried in order of how far they are from the
   best iterate's (:mod:`.regimes`; :func:`solve_rejected`).

A solution is accepted when its FCLIB merit and its dual-cone violation are both
<= ``tol``; otherwise the status says what went wrong and the best iterate is returned.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from nscd.solver import cone, newton, nsgs, proximal, regimes, small
from nscd.solver.coarse import CoarseCorrection
from nscd.solver.delassus import Delassus
from nscd.solver.conic import ConicSubproblem
from nscd.solver.settings import SolverSettings, Status

# The fixed point hands over to the polish after _STALE consecutive conic solves that
# do not cut the merit to _PROGRESS times the previous one (linear convergence too slow,
# a plateau, or a cycle — "cycling" when the merit rose at least _STALE times).
_STALE = 4
_PROGRESS = 0.9
# Anderson acceleration depth of the fixed point (number of past iterates kept).
_ANDERSON_DEPTH = 5
# Smallest under-relaxation of the fixed point (halved each time the merit grows).
_MIN_RELAX = 1.0 / 16.0
# Relative skew part of W above which the conic subproblem uses (W + W^T)/2 and the
# fixed point carries the skew part (noted).
_ASYMMETRY = 1e-12
# Diagonal regularisation (scaled units, where diag W = 1) added to the conic
# subproblem only when Clarabel fails on the plain (semidefinite or slightly
# indefinite) W; the merit and the polish always use W as given.
_REGULARISATION = 1e-7
# A bounded large problem's polish (nothing dearer after it) stops after this many Newton
# iterations without halving the residual: on a wall breaking up a polish that has not
# converged in a few iterations creeps (1.7e-4 -> 1.1e-4 in 53 iterations, 0.27 s, on one
# of the 97-block wall's problems; docs/solver.md, fifth round).
_POLISH_STALL = 8


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
    sweeps: int = 0
    proximal_iterations: int = 0
    notes: list[str] = field(default_factory=list)
    message: str = ""

    @property
    def iterations(self) -> int:
        """Total iterations: fast-path Newton + Gauss–Seidel sweeps + conic solves + Newton
        iterations of the proximal-point inner solves + polish Newton."""
        return (self.fast_iterations + self.sweeps + self.fixed_point_iterations + self.proximal_iterations
                + self.polish_iterations)

    @property
    def accepted(self) -> bool:
        """The acceptance test passed (converged, directly or after the polish)."""
        return self.status in (Status.CONVERGED, Status.POLISHED)


def _better(best: CoreResult, other: CoreResult) -> CoreResult:
    """The better of two answers to one problem: an accepted one, else the lower merit (a tie keeps ``best``)."""
    if best.accepted != other.accepted:
        return best if best.accepted else other
    return other if other.merit < best.merit else best


#: A small problem that every route leaves above the tolerance gets the proximal point once more
#: from its best iterate, with inner problems solved by up to this many times ``max_fast`` Newton
#: iterations (:func:`solve_rejected`): on degenerate 3D problems of the LNEC trilith (8-22
#: contacts, redundant) the inner solves capped at 25 iterations left the outer loop stalled at
#: merit 1e-8..3e-6; with 100, 5 of 6 converged, and with 200 the 6 that 100 left at 5 Hz, and
#: from zero where it stalled from the best iterate (``docs/solver.md``, sixteenth round).
PATIENT_INNER = 8

#: The largest problem (unknowns) whose sparse or factored ``W`` the proximal point forms dense, to
#: run its compiled loop (:func:`.proximal.solve_dense`) instead of the sparse one, whose inner Newton
#: runs are Python around scipy: a 22-block wall's problems of 192 unknowns took a third of the time
#: (``docs/solver.md``, fifteenth round). The default ``proximal_unknowns``; beyond (a setting raised
#: to take a wall's problems of many hundreds of unknowns) the dense elimination's n^3 / 3 would
#: cost more than the sparse factorisations.
DENSE_PROXIMAL_UNKNOWNS = 240


class _Scaled:
    """The problem in scaled units (``r = sigma d r'``, ``u = sigma u' / d``) and its unscaled merit."""

    def __init__(self, W, q: np.ndarray, mu: np.ndarray, dim: int, settings: SolverSettings) -> None:
        # One factor per contact (so each cone maps onto itself), from the normal diagonal.
        diag = W.diagonal()[::dim]
        floor = max(diag.max(), 1.0) * 1e-14
        self.d = np.repeat(np.maximum(diag, floor) ** -0.5, dim)
        self.sigma = float(np.abs(self.d * q).max())
        self.mu, self.dim, self.m = np.ascontiguousarray(mu, dtype=float), dim, mu.size
        self.exact, self.tol, self.tol_relative = settings.exact, settings.tol, settings.tol_relative
        self.q_norm = float(np.sqrt(q @ q))
        # a dense W (given, or formed for a problem of at most DENSE_PROXIMAL_UNKNOWNS unknowns that
        # the sweeps and their polish leave above the tolerance): the proximal point compiled; of a
        # small problem (not for the sweeps) also the polish by the compiled kernel
        self._given = (W, q)
        self._original = (np.ascontiguousarray(W, dtype=float), np.ascontiguousarray(q, dtype=float)) \
            if isinstance(W, np.ndarray) else None
        self.dense = self._original if q.size <= settings.large_problem_unknowns else None
        if self.sigma == 0.0:
            return
        if isinstance(W, Delassus):
            self.W = W.scaled(self.d)
        elif sp.issparse(W):
            # D W D on the stored entries (one pass, no sparse products)
            W = sp.csr_matrix(W)
            rows = np.repeat(np.arange(W.shape[0]), np.diff(W.indptr))
            self.W = sp.csr_matrix((W.data * self.d[rows] * self.d[W.indices], W.indices, W.indptr), shape=W.shape)
        else:
            self.W = W * self.d[:, None] * self.d[None, :]
        self.q = q * self.d / self.sigma

    @property
    def original(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The unscaled ``(W, q)`` with ``W`` dense, for the compiled proximal point
        (:func:`.proximal.solve_dense`): a dense ``W`` as given, or a sparse or factored one of at
        most :data:`DENSE_PROXIMAL_UNKNOWNS` unknowns formed dense once, on first use (a problem that the
        sweeps and their polish left above the tolerance: the compiled loop on its dense ``W``
        costs a fraction of the sparse one's inner Newton runs in Python, ``docs/solver.md``,
        fifteenth round); None for a larger sparse one."""
        W, q = self._given
        if self._original is None and q.size <= DENSE_PROXIMAL_UNKNOWNS:
            if isinstance(W, Delassus):
                W = W.tocsr()
            self._original = (np.ascontiguousarray(W.toarray(), dtype=float), np.ascontiguousarray(q, dtype=float))
        return self._original

    @property
    def matrix(self):
        """The scaled ``W`` as a matrix (a factored :class:`~.delassus.Delassus` formed once, on first use)."""
        if isinstance(self.W, Delassus):
            self.W = self.W.tocsr()
        return self.W

    def _unscaled(self, r_s: np.ndarray, u_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        shape = (self.m, self.dim)
        return (self.sigma * self.d * r_s).reshape(shape), (self.sigma * u_s / self.d).reshape(shape)

    def stop(self, r_s: np.ndarray, u_s: np.ndarray) -> tuple[float, bool]:
        """Unscaled FCLIB merit of the scaled pair ``(r_s, u_s)`` and whether it is accepted.

        Accepted when the merit meets ``tol`` and so does the
        dual-cone violation (:func:`~nscd.solver.cone.merit_and_dual_violation`; the merit alone is blind when
        ``||r|| >> ||u||``).
        """
        r, u = self._unscaled(r_s, u_s)
        value, gap = cone.merit_and_dual_violation(r, u, self.mu, self.q_norm, self.exact)
        return value, value <= self.tol and gap <= self.tol

    def relative(self, r_s: np.ndarray, u_s: np.ndarray) -> float:
        """Merit of the scaled pair relative to the problem's own scale (dimensionless).

        ``max(||F'||, ||v'||) / max(||r'||, ||q'||)`` in the scaled units (``r' = r / (sigma d)``,
        ``u' = u d / sigma``, ``d_c = 1 / sqrt(W_NN,c)``: the energy norm of ``W``), with
        ``F'`` the De Saxcé natural map and ``v'`` the distance of ``u' + mu ||u'_T|| e_N``
        to the dual cone. The ratio does not depend on ``sigma``, on the units, nor on a
        uniform scaling of the masses; it bounds the residual per unit of the solution's
        (or, when the impulses vanish, the data's) size, as Siconos' error over ``||q||``.
        """
        shape = (self.m, self.dim)
        value, gap = cone.merit_and_dual_violation(r_s.reshape(shape), u_s.reshape(shape), self.mu, 0.0, self.exact)
        return max(value, gap) / max(float(np.linalg.norm(r_s)), float(np.linalg.norm(self.q)))

    def stop_relative(self, r_s: np.ndarray, u_s: np.ndarray) -> tuple[float, bool]:
        """:meth:`stop`, also accepting ``relative <= tol_relative`` when that is set (the stopping test
        of the polish after the sweeps and of the sparse proximal point, evaluated by the compiled
        :func:`nscd.solver.nsgs.merit_test`: a tenth of the numpy test's cost; the sweeps and the
        compiled proximal point evaluate the same test in their compiled loops,
        :func:`nscd.solver.proximal._measure`)."""
        value, gap = nsgs.merit_test(r_s, u_s, self.d, self.sigma, self.mu, self.dim, self.exact, self.q_norm)
        done = value <= self.tol and gap <= self.tol
        if not done and self.tol_relative is not None:
            # relative(), by the compiled test on the scaled pair (d = 1, sigma = 1, ||q|| = 0)
            value_s, gap_s = nsgs.merit_test(r_s, u_s, np.ones(r_s.size), 1.0, self.mu, self.dim, self.exact, 0.0)
            done = max(value_s, gap_s) <= self.tol_relative * max(float(np.linalg.norm(r_s)),
                                                                   float(np.linalg.norm(self.q)))
        return value, done

    def newton(self, r_s: np.ndarray, max_iter: int, relative: bool = False,
               stall: int | None = None) -> newton.NewtonResult:
        """Semismooth Newton on the scaled natural map (``rho = 1``), stopped on the unscaled merit
        (``relative``: or on ``tol_relative``, as the sweeps it polishes, :meth:`stop_relative`).

        The unscaled residual of contact c is ``sigma d_c (r'_c - P_K(r'_c - (u'_c + s'_c) / d_c^2))``
        (``r = sigma d r'``, ``u = sigma u' / d``, ``P_K(d x) = d P_K(x)``), and for natural
        maps ``||F_rho|| / ||F_1||`` lies between ``min(1, rho)`` and ``max(1, rho)`` (per
        contact; Tseng's lemma on projections). The scaled norm thus bounds the merit from
        below, and the merit is evaluated only once that bound is below ``tol``: one
        natural map per iteration instead of two. The scaled norm is the numerator of the relative
        merit itself (:meth:`relative`), tested likewise before the dual-cone part is evaluated.
        ``stall``: that of :func:`nscd.solver.newton.solve` (sparse ``W`` only).
        """
        if self.dense is not None:
            return self._compiled_newton(r_s, max_iter)
        dc = self.d[::self.dim]
        lower = self.sigma / (1.0 + np.sqrt(self.q_norm)) * float(np.min(dc * np.minimum(1.0, 1.0 / dc**2)))
        relative = relative and self.tol_relative is not None
        q_scale = float(np.linalg.norm(self.q))

        def stop(r_s: np.ndarray, u_s: np.ndarray, norm_f: float) -> tuple[float | None, bool]:
            if lower * norm_f <= self.tol:
                value, done = self.stop(r_s, u_s)
                if done or not relative:
                    return value, done
            if relative and norm_f <= self.tol_relative * max(float(np.linalg.norm(r_s)), q_scale):
                return self.stop_relative(r_s, u_s)
            return None, False

        return newton.solve(self.matrix, self.q, self.mu, self.dim, r_s, self.exact, max_iter, stop,
                            lambda r_s, u_s: self.stop(r_s, u_s)[0], stall)

    def _compiled_newton(self, r_s: np.ndarray, max_iter: int) -> newton.NewtonResult:
        """:meth:`newton` of a small dense problem by the compiled kernel of the fast path
        (:func:`nscd.solver.small.solve_dense`: the same method, scaling and acceptance test,
        from ``r_s`` and, if that fails, once more from zero; no stall test), the scaled iterate it keeps."""
        W, q = self.dense
        n = q.size
        r, u = np.empty((1, n)), np.empty((1, n))
        merit, info = np.empty(1), np.empty((1, 2), dtype=np.int64)
        small.solve_dense(W[None], q[None], np.ascontiguousarray(self.mu, dtype=float)[None], np.array([n]),
                          self.dim, (self.sigma * self.d * r_s)[None], self.tol, self.exact, max_iter, 0, 0.0, r, u,
                          merit, info)
        return newton.NewtonResult(r[0] / (self.sigma * self.d), float(merit[0]), bool(info[0, 0] == small.ACCEPTED),
                                   int(info[0, 1]))

    def result(self, r_s: np.ndarray, merit: float, status: Status, path: str, counters: dict) -> CoreResult:
        """Unscaled :class:`CoreResult` for the scaled impulses ``r_s`` (unscaled merit ``merit``)."""
        u = self.sigma * (self.W @ r_s + self.q) / self.d
        return CoreResult(self.sigma * self.d * r_s, u, merit, status, path, **counters)


@dataclass
class _FixedPoint:
    """Outcome of :func:`_fixed_point` (scaled impulses ``r`` is None if no conic solve succeeded)."""

    r: np.ndarray | None
    merit: float
    iterations: int
    interior_point_iterations: int
    cycling: bool
    failure: str
    accepted: bool = False


def _skew(Ws, notes: list[str]):
    """Skew part ``(Ws - Ws^T)/2`` (recorded in ``notes``), or None when ``Ws`` is symmetric to rounding."""
    K = (Ws - Ws.T) * 0.5
    gap, size = abs(K).max(), abs(Ws).max()
    if gap <= _ASYMMETRY * size:
        return None
    notes.append(f"unsymmetric W (relative skew part {gap / size:.1e}): conic subproblem on (W + W^T)/2, "
                 "skew part iterated in the fixed point")
    return K


def _correction(u: np.ndarray, r: np.ndarray, skew, mu: np.ndarray, dim: int, exact: bool) -> np.ndarray:
    """Linear-term correction ``mu ||u_T|| e_N + K r`` for the next conic solve."""
    c = skew @ r if skew is not None else np.zeros_like(u)
    if exact:
        c[::dim] += mu * np.linalg.norm(u.reshape(-1, dim)[:, 1:], axis=1)
    return c


def _conic(W, mu: np.ndarray, dim: int, settings: SolverSettings) -> ConicSubproblem:
    return ConicSubproblem(W, mu, dim, settings.tol_gap_abs, settings.tol_gap_rel, settings.tol_feas,
                           settings.max_interior_point)


def _fixed_point(P: _Scaled, settings: SolverSettings, start: np.ndarray | None, notes: list[str]) -> _FixedPoint:
    """Clarabel solves of the shifted convex problem, iterating the linear-term correction.

    The correction is the De Saxcé shift ``mu ||u_T||`` on normal rows plus, for an
    unsymmetric ``W``, its skew part times ``r`` (the conic solve sees ``(W + W^T)/2``).
    Anderson-accelerated (:func:`_anderson`); each time the merit rises the history is
    dropped and the plain step under-relaxed by halves. Ends at ``tol``, at
    ``polish_below`` (polish enabled), when the correction stops changing, after
    ``_STALE`` solves without ``_PROGRESS``, or after ``max_fixed_point`` solves.
    """
    skew = _skew(P.matrix, notes)
    sym = P.matrix if skew is None else P.matrix - skew
    conic = _conic(sym, P.mu, P.dim, settings)
    correction = np.zeros_like(P.q)
    if start is not None:
        correction = _correction(P.W @ start + P.q, start, skew, P.mu, P.dim, P.exact)
    out = _FixedPoint(None, np.inf, 0, 0, False, "")
    previous, stale, rises, regularised, relax = np.inf, 0, 0, False, 1.0
    history: list[tuple[np.ndarray, np.ndarray]] = []
    while out.iterations < settings.max_fixed_point:
        res = conic.solve(P.q + correction)
        out.iterations += 1
        out.interior_point_iterations += res.iterations
        if not res.ok:
            out.failure = f"Clarabel: {res.status}"
            if out.r is None and not regularised:
                # Semidefinite or slightly indefinite W: retry once with a tiny ridge.
                regularised = True
                notes.append(f"regularised W + {_REGULARISATION:g} I (scaled) for the conic subproblem")
                ridge = sp.identity(P.q.size) if sp.issparse(sym) else np.eye(P.q.size)
                conic = _conic(sym + _REGULARISATION * ridge, P.mu, P.dim, settings)
                continue
            notes.append(out.failure)
            if out.r is None and np.all(np.isfinite(res.r)):
                out.r, out.merit = res.r, P.stop(res.r, P.W @ res.r + P.q)[0]
            return out
        u = P.W @ res.r + P.q
        value, done = P.stop(res.r, u)
        if done or (value < out.merit and not out.accepted):
            out.r, out.merit, out.accepted = res.r, value, done
        stale = stale + 1 if value > _PROGRESS * previous else 0
        rises += value > previous
        if done or (settings.polish and value <= settings.polish_below):
            return out
        target = _correction(u, res.r, skew, P.mu, P.dim, P.exact)
        if np.max(np.abs(target - correction)) <= settings.fixed_point_tol * (1.0 + np.max(np.abs(correction))):
            return out
        if stale >= _STALE:
            out.cycling = rises >= _STALE
            notes.append(f"fixed point {'cycling' if out.cycling else 'stalled'} at merit {value:.1e} "
                         f"after {out.iterations} conic solves")
            return out
        if value > previous:
            relax = max(0.5 * relax, _MIN_RELAX)
            history.clear()
        previous = value
        history.append((correction, target))
        correction = _anderson(history) if len(history) > 1 else correction + relax * (target - correction)
    return out


def _anderson(history: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Anderson-accelerated next correction from the last (c_k, g(c_k)) pairs (type II).

    ``c_next = g_k - dG gamma`` with ``gamma`` minimising ``||f_k - dF gamma||``, ``f = g - c``
    (Walker & Ni 2011); the caller clears the history whenever the merit rises.
    """
    del history[:-_ANDERSON_DEPTH]
    c = np.array([h[0] for h in history])
    g = np.array([h[1] for h in history])
    f = g - c
    dF, dG = np.diff(f, axis=0), np.diff(g, axis=0)
    gamma = np.linalg.lstsq(dF.T, f[-1], rcond=None)[0]
    return g[-1] - gamma @ dG


def solve(W, q: np.ndarray, mu: np.ndarray, dim: int, settings: SolverSettings,
          r0: np.ndarray | None = None, coarse: tuple[CoarseCorrection, np.ndarray] | None = None) -> CoreResult:
    """Solve ``K_mu ∋ r ⊥ W r + q + mu ||u_T|| e_N ∈ K_mu*`` (validated input).

    Parameters
    ----------
    W : ndarray, scipy.sparse.csr_matrix or Delassus, shape (n, n)
        Delassus matrix, ``n = m * dim``; rows per contact ``[N, T1, (T2)]``. A
        factored :class:`~.delassus.Delassus` (large velocity-form problems) is swept in
        the body velocities and formed as a matrix only if a later stage needs it.
    q : ndarray, shape (n,)
        Free relative velocity.
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    settings : SolverSettings
    r0 : ndarray, shape (n,), optional
        Warm start for the impulses.
    coarse : (CoarseCorrection, ndarray), optional
        Body-space correction of the Gauss–Seidel sweeps and the mass (diagonal of ``M`` in 2D, ``M^-1`` in 3D)
        (:mod:`.coarse`; used with a factored ``W`` on the large-problem path).

    Returns
    -------
    CoreResult
    """
    if q.size <= settings.fast_path_unknowns:
        # Compiled fast path: the very kernel of solve_batch (B = 1), so a problem solved
        # alone and inside a batch gets bitwise the same impulses (a small sparse or
        # factored W is formed dense: at most fast_path_unknowns^2 entries).
        if isinstance(W, Delassus):
            W = W.tocsr()
        if sp.issparse(W):
            W = W.toarray()
        return _solve_compiled(np.ascontiguousarray(W)[None], np.ascontiguousarray(q)[None],
                               np.ascontiguousarray(mu)[None], np.array([q.size]), dim, settings,
                               None if r0 is None else np.ascontiguousarray(r0)[None])[0]
    P = _Scaled(W, q, mu, dim, settings)
    if P.sigma == 0.0:
        # q == 0: r = 0, u = 0 satisfies the complementarity exactly.
        return CoreResult(np.zeros_like(q), q.copy(), 0.0, Status.CONVERGED, "trivial (q = 0)")
    start = None if r0 is None else r0 / (P.sigma * P.d)
    counters: dict = {"notes": []}
    earlier = None  # (r, merit, path) of the best unaccepted large-problem stage
    if q.size > settings.large_problem_unknowns:
        # Large problems: nonsmooth Gauss-Seidel (linear cost per sweep), same acceptance test.
        large = nsgs.solve(P.W, P.q, P.mu, dim, start, settings.max_sweeps, settings.sweeps_per_check,
                           nsgs.StopTest(P.d, P.sigma, P.q_norm, P.exact, P.tol, P.tol_relative or 0.0), coarse,
                           settings.polish_below if settings.polish else 0.0)
        counters["sweeps"] = large.sweeps
        if large.accepted:
            if large.merit > settings.tol:
                counters["notes"].append(f"accepted at relative merit {large.relative:.1e} "
                                         f"<= tol_relative {settings.tol_relative:.1e} (FCLIB merit {large.merit:.1e})")
            return P.result(large.r, large.merit, Status.CONVERGED, "nsgs", counters)
        earlier = (large.r, large.merit, "nsgs")
        note = f"NSGS left merit {large.merit:.1e} > tol {settings.tol:.1e} after {large.sweeps} sweeps"
        if settings.polish and large.merit <= settings.polish_below:
            # Near a solution Gauss-Seidel can stall (redundant contacts: a slow drift along
            # the null space of W); Newton is global and takes it to tol from there.
            # bounded (no interior point after it): the polish stops once it creeps, _POLISH_STALL
            # iterations without halving the residual (each a sparse factorisation)
            bounded = settings.max_conic_unknowns is not None and q.size > settings.max_conic_unknowns
            polished = P.newton(large.r, settings.max_polish, relative=True, stall=_POLISH_STALL if bounded else None)
            counters["polish_iterations"] = polished.iterations
            if polished.converged:
                counters["notes"].append(note + ": polished")
                if polished.merit > settings.tol:
                    counters["notes"].append(
                        f"accepted at relative merit {P.relative(polished.r, P.W @ polished.r + P.q):.1e} "
                        f"<= tol_relative {settings.tol_relative:.1e} (FCLIB merit {polished.merit:.1e})")
                return P.result(polished.r, polished.merit, Status.POLISHED, "nsgs + polish", counters)
            note += f", polish left {polished.merit:.1e}"
            if polished.merit < large.merit:
                earlier = (polished.r, polished.merit, "nsgs + polish")
        if settings.max_proximal and q.size <= settings.proximal_unknowns:
            # the proximal point from the best sweep (a small wall whose contacts multiply as it
            # breaks up; larger problems when proximal_unknowns is raised: a sparse inner Newton)
            prox = _proximal(P, settings, earlier[0])
            prox.sweeps, prox.polish_iterations = large.sweeps, prox.polish_iterations + counters.get(
                "polish_iterations", 0)
            prox.notes.insert(0, note)
            if prox.accepted:
                prox.path = "nsgs + " + prox.path
                return prox
            note += f", proximal point left {prox.merit:.1e}"
            counters["proximal_iterations"] = prox.proximal_iterations
            if prox.merit < earlier[1]:
                earlier = (prox.r / (P.sigma * P.d), prox.merit, "nsgs + proximal point")
        if settings.max_conic_unknowns is not None and q.size > settings.max_conic_unknowns:
            # Bounded work: the interior point's cost grows much faster than the sweeps' (seconds
            # at thousands of unknowns) and on a wall breaking up it rarely ends below tol either.
            best_r, best_merit, path = earlier
            counters["notes"].append(note + f": no interior point ({q.size} unknowns > max_conic_unknowns "
                                            f"{settings.max_conic_unknowns})")
            result = P.result(best_r, best_merit, Status.STALLED, path, counters)
            result.message = (f"merit {best_merit:.3e} > tol {settings.tol:.1e} "
                              f"(relative merit {P.relative(best_r, P.W @ best_r + P.q):.1e}) after the sweeps; "
                              f"the interior point is skipped above max_conic_unknowns = {settings.max_conic_unknowns}")
            return result
        # Hand the problem over as it came (same warm start): from the best sweep the
        # interior point can do worse (FCLIB Capsules-i125-1213 then stalls at 1e-6).
        counters["notes"].append(note + ": handed to the interior point")

    fp = _fixed_point(P, settings, start, counters["notes"])
    counters.update(fixed_point_iterations=fp.iterations, interior_point_iterations=fp.interior_point_iterations)
    if fp.accepted:
        return P.result(fp.r, fp.merit, Status.CONVERGED, "interior point", counters)
    best_r, best_merit = fp.r, fp.merit
    if best_r is None:
        best_r = np.zeros_like(q) if start is None else start
        best_merit = P.stop(best_r, P.W @ best_r + P.q)[0]
    path = "interior point"
    if settings.polish:
        polished = P.newton(best_r, settings.max_polish)
        counters["polish_iterations"] = polished.iterations
        path = "interior point + polish"
        if polished.converged:
            return P.result(polished.r, polished.merit, Status.POLISHED, path, counters)
        if polished.merit < best_merit:
            best_r, best_merit = polished.r, polished.merit
    if earlier is not None and earlier[1] < best_merit:
        # the sweeps had come closer than the interior point: report their best
        best_r, best_merit, path = earlier
        counters["notes"].append(f"the interior point did worse; the result is the best of the {path} stage")
    if fp.r is None or fp.failure:
        status = Status.NUMERICAL_FAILURE
    elif fp.cycling:
        status = Status.CYCLING
    else:
        status = Status.STALLED
    result = P.result(best_r, best_merit, status, path, counters)
    result.message = f"merit {result.merit:.3e}"
    if result.merit <= settings.tol:
        gap = cone.merit_and_dual_violation(result.r.reshape(-1, dim), result.u.reshape(-1, dim), mu,
                                            P.q_norm, P.exact)[1]
        result.message += (f" but u + mu |u_T| e_N lies {gap:.3e} outside the dual cone "
                           "(impulses diverging: is the problem solvable?)")
    else:
        result.message += f" > tol {settings.tol:.1e}"
    if fp.failure:
        result.message += f" ({fp.failure})"
        if "Infeasible" in fp.failure:
            result.message += (": the contact problem may have no solution "
                               "(a mechanism that no admissible impulse stops)")
    return result


def _solve_compiled(W: np.ndarray, q: np.ndarray, mu: np.ndarray, sizes: np.ndarray, dim: int,
                    settings: SolverSettings, r0: np.ndarray | None) -> list[CoreResult]:
    """Compiled fast path over a padded batch (validated, C-contiguous float input); the rest to :func:`solve`.

    A problem the kernels do not accept (the Newton from the warm start and from ``r = 0``,
    the proximal point and its polish: :func:`newton_batch`) is solved again by
    :func:`solve_rejected` (the conic fixed point and the polish), from the same warm start
    as an uncompiled solve after a failed fast path.
    """
    r, u, merit, info = newton_batch(W, q, mu, sizes, dim, settings, np.zeros(q.shape) if r0 is None else r0)
    conic_settings = None
    results = []
    for b, n in enumerate(sizes.tolist()):
        res = compiled_result(r[b, :n], u[b, :n], float(merit[b]), info[b], settings)
        if info[b, 0] == small.NOT_ACCEPTED:
            if conic_settings is None:
                conic_settings = dataclasses.replace(settings, fast_path_unknowns=0)
            res = solve_rejected(W[b, :n, :n], q[b, :n], mu[b, :n // dim], dim, conic_settings,
                                 None if r0 is None else r0[b, :n], res)
        results.append(res)
    return results


def newton_batch(W: np.ndarray, q: np.ndarray, mu: np.ndarray, sizes: np.ndarray, dim: int,
                 settings: SolverSettings, r0: np.ndarray) -> tuple:
    """The compiled fast path over a padded batch (C-contiguous float ``W`` (B, n, n), ``q``,
    ``r0`` (B, n), ``mu`` (B, n // dim), int64 ``sizes`` (B,)), each problem with the settings'
    ``tol``, cone and iteration limits, in one compiled call (:func:`nscd.solver.proximal.fast_path`,
    which the compiled steps call too): the semismooth Newton (:func:`nscd.solver.small.solve_dense`),
    then, on the problems it does not accept (at most ``proximal_unknowns`` unknowns, unless
    ``max_proximal == 0``), the proximal-point iterations and their polish, from the Newton's
    best iterate (:func:`nscd.solver.proximal.solve_dense`).

    Returns the impulses ``r`` and relative velocities ``u`` (B, n), the merits (B,) and per
    problem (B, 5) the outcome code (:data:`nscd.solver.small.ACCEPTED`,
    :data:`~nscd.solver.small.PROXIMAL`, ...), the Newton iterations, the inner problems of
    the proximal point, their Newton iterations and the polish's; a problem not accepted
    (:data:`~nscd.solver.small.NOT_ACCEPTED`: ``r`` its best iterate) is left to the caller
    (:func:`solve_rejected`).
    """
    r, u = np.empty(q.shape), np.empty(q.shape)
    merit, info = np.empty(sizes.size), np.empty((sizes.size, 5), dtype=np.int64)
    if sizes.size:
        proximal.fast_path(W, q, mu, sizes, dim, r0, *fast_path_settings(settings), r, u, merit, info)
    return r, u, merit, info


def fast_path_settings(settings: SolverSettings) -> tuple[float, float, bool, int, int, int, int]:
    """The settings of :func:`nscd.solver.proximal.fast_path` as it takes them: ``tol``,
    ``tol_relative`` (0.0: none), the cone (``exact``), ``max_fast``, ``max_proximal``,
    ``max_polish`` (0: no polish) and ``proximal_unknowns``."""
    return (float(settings.tol), float(settings.tol_relative or 0.0), bool(settings.exact), int(settings.max_fast),
            int(settings.max_proximal), int(settings.max_polish) if settings.polish else 0,
            int(settings.proximal_unknowns))


def compiled_result(r: np.ndarray, u: np.ndarray, merit: float, info: np.ndarray,
                    settings: SolverSettings) -> CoreResult:
    """:class:`CoreResult` of one problem of :func:`newton_batch` (``info``: its row; ``r``,
    ``u`` its unpadded entries), as :func:`solve` reports it; a problem the batch did not
    accept gets the status ``STALLED`` and the message of its best iterate."""
    code, fast, outer, inner, polish = info.tolist()
    counters = {"fast_iterations": fast, "proximal_iterations": inner, "polish_iterations": polish,
                "notes": [f"{outer} proximal-point iterations"] if outer else []}
    if code == small.ACCEPTED:
        return CoreResult(r, u, merit, Status.CONVERGED, "newton (fast path)", **counters)
    if code == small.TRIVIAL:
        return CoreResult(r, u, 0.0, Status.CONVERGED, "trivial (q = 0)")
    if code == small.PROXIMAL:
        result = CoreResult(r, u, merit, Status.CONVERGED, "proximal point", **counters)
        if merit > settings.tol:
            result.notes.append(f"accepted at relative merit <= tol_relative {settings.tol_relative:.1e} "
                                f"(FCLIB merit {merit:.1e})")
        return result
    if code == small.PROXIMAL_POLISHED:
        return CoreResult(r, u, merit, Status.POLISHED, "proximal point + polish", **counters)
    result = CoreResult(r, u, merit, Status.STALLED, "proximal point" if outer else "newton (fast path)",
                        **counters)
    result.message = f"merit {merit:.3e} > tol {settings.tol:.1e}" + (
        f" after {outer} proximal iterations" if outer else "")
    return result


def solve_rejected(W: np.ndarray, q: np.ndarray, mu: np.ndarray, dim: int, conic_settings: SolverSettings,
                   r0: np.ndarray | None, earlier: CoreResult | None = None) -> CoreResult:
    """A dense problem the compiled fast path (:func:`newton_batch`: the Newton, the proximal
    point and its polish) did not accept: the conic fixed point and the polish (:func:`solve`
    with ``conic_settings``, whose fast path is off, so the Newton is not run again from the
    same start), from ``r0``, and once more from the cold start (``r0=None``: no De Saxcé shift,
    which a zero ``r0`` is not) if that does not converge. The best of them and ``earlier`` (the
    fast path's best iterate, :func:`compiled_result`) is kept; if it is not accepted, a 2D problem
    of at most ``regime_contacts`` contacts is solved by its contacts' regimes (:mod:`.regimes`),
    and what is still not accepted gets the proximal point once more with patient inner solves
    (:data:`PATIENT_INNER`), from that best iterate and then, if need be, from zero; the best is
    returned.
    """
    res = solve(W, q, mu, dim, conic_settings, r0)
    if earlier is not None:
        res.fast_iterations, res.proximal_iterations = earlier.fast_iterations, earlier.proximal_iterations
        res.polish_iterations += earlier.polish_iterations
        if earlier.notes:
            res.notes.insert(0, f"proximal point: {earlier.message}")
        earlier.notes.append("the conic fixed point did worse; the result is the fast path's best iterate")
        res = _better(res, earlier)
    if r0 is not None and not res.accepted:
        # The warm start seeds the fixed point's De Saxcé shift, and a poor one can make it
        # cycle or stall where the cold start (zero shift) converges. A zero warm start is
        # not the cold start: its shift is mu ||q_T||, from the free velocity's slip.
        cold = solve(W, q, mu, dim, conic_settings, None)
        cold.notes.insert(0, f"fixed point from the warm start: {res.status} ({res.message}); "
                             "solved again from the cold start (no shift)")
        res = _better(res, cold)
    if not res.accepted and dim == 2 and conic_settings.exact and mu.size <= conic_settings.regime_contacts:
        exact = regimes.solve(W, q, mu, res.r, conic_settings.tol)
        if exact is not None:
            r, u, merit, trials = exact
            res = dataclasses.replace(res, r=r, u=u, merit=merit, status=Status.CONVERGED, path="regimes",
                                      notes=[*res.notes, f"{res.path}: {res.message}; solved exactly by the "
                                             f"contacts' regimes ({trials} linear systems)"], message="")
    if not res.accepted and conic_settings.max_proximal:
        # The proximal point's inner problems, each solved by at most max_fast Newton iterations,
        # can stay unsolved on a degenerate problem (redundant contacts at the friction limit), and
        # the outer loop then stalls: once more with patient inner solves, from the best iterate,
        # then from zero (the outer loop's path, and so where it stalls, depends on its start).
        P = _Scaled(W, q, mu, dim, conic_settings)
        patient = dataclasses.replace(conic_settings, max_fast=PATIENT_INNER * conic_settings.max_fast)
        for start, which in ((res.r / (P.sigma * P.d), "its best iterate"), (None, "zero")):
            again = _proximal(P, patient, start)
            again.notes[:0] = [*res.notes, f"{res.path}: {res.status} ({res.message}); the proximal point "
                               f"again from {which}, inner solves of up to {patient.max_fast} Newton iterations"]
            res = _better(res, again)
            if res.accepted:
                break
    return res


def _proximal(P: _Scaled, settings: SolverSettings, start: np.ndarray | None) -> CoreResult:
    """The proximal-point iterations of :mod:`.proximal` on the scaled problem ``P`` from the
    scaled impulses ``start`` (or zero), accepted by the same test as every path (``tol``, or
    ``tol_relative`` when set), then the polish (Newton on the original problem) from their
    best iterate: compiled (:func:`.proximal.solve_dense`) for a dense ``W``, with
    :mod:`.newton`'s sparse factorisations (:func:`.proximal.solve`) for a sparse one.
    """
    if P.original is not None:
        W, q = P.original
        n = q.size
        r0 = np.zeros((1, n)) if start is None else (P.sigma * P.d * start)[None]
        r, u, merit, info = np.empty((1, n)), np.empty((1, n)), np.empty(1), np.empty((1, 4), dtype=np.int64)
        proximal.solve_dense(W[None], q[None], np.ascontiguousarray(P.mu, dtype=float)[None], np.array([n]), P.dim,
                             r0, settings.tol, settings.tol_relative or 0.0, P.exact, settings.max_proximal,
                             settings.max_fast, settings.max_polish if settings.polish else 0, r, u, merit, info)
        code, outer, inner, polish = info[0].tolist()
        return compiled_result(r[0], u[0], float(merit[0]), np.array([code, 0, outer, inner, polish]), settings)

    def measure(r_s: np.ndarray, u_s: np.ndarray) -> tuple[float, float, bool]:
        value, done = P.stop_relative(r_s, u_s)
        return value, P.relative(r_s, u_s), done

    out = proximal.solve(P.matrix, P.q, P.mu, P.dim, np.zeros_like(P.q) if start is None else start, P.exact,
                         settings.max_proximal, settings.max_fast, measure, settings.tol)
    counters: dict = {"notes": [f"{out.outer} proximal-point iterations"], "proximal_iterations": out.inner}
    r_s, merit = out.r, out.merit
    if out.converged:
        result = P.result(r_s, merit, Status.CONVERGED, "proximal point", counters)
        if merit > settings.tol:
            result.notes.append(f"accepted at relative merit {P.relative(r_s, P.W @ r_s + P.q):.1e} "
                                f"<= tol_relative {settings.tol_relative:.1e} (FCLIB merit {merit:.1e})")
        return result
    if settings.polish:
        polished = P.newton(r_s, settings.max_polish)
        counters["polish_iterations"] = polished.iterations
        if polished.converged:
            return P.result(polished.r, polished.merit, Status.POLISHED, "proximal point + polish", counters)
        if polished.merit < merit:
            r_s, merit = polished.r, polished.merit
    result = P.result(r_s, merit, Status.STALLED, "proximal point", counters)
    result.message = f"merit {merit:.3e} > tol {settings.tol:.1e} after {out.outer} proximal iterations"
    return result


def _check_batch(W, q, mu, dim, r0, sizes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None,
                                                    np.ndarray]:
    """Validate :func:`solve_batch` input; returns C-contiguous float arrays and int64 ``sizes``."""
    if isinstance(dim, bool) or dim not in (2, 3):
        raise ValueError(f"dim == {dim!r}, must be 2 or 3.")
    q = np.ascontiguousarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] == 0 or q.shape[1] % dim:
        raise ValueError(f"q has shape {q.shape}, must be (B, n_max) with n_max a positive multiple of dim == {dim}.")
    batch, n_max = q.shape
    W = np.ascontiguousarray(W, dtype=float)
    if W.shape != (batch, n_max, n_max):
        raise ValueError(f"W has shape {W.shape}, must be ({batch}, {n_max}, {n_max}).")
    mu = np.ascontiguousarray(mu, dtype=float)
    if mu.shape != (batch, n_max // dim):
        raise ValueError(f"mu has shape {mu.shape}, must be ({batch}, {n_max // dim}).")
    if r0 is not None:
        r0 = np.ascontiguousarray(r0, dtype=float)
        if r0.shape != (batch, n_max):
            raise ValueError(f"r0 has shape {r0.shape}, must be ({batch}, {n_max}).")
    if sizes is None:
        sizes = np.full(batch, n_max, dtype=np.int64)
    else:
        given = np.asarray(sizes)
        if given.shape != (batch,) or not np.issubdtype(given.dtype, np.integer):
            raise ValueError(f"sizes has shape {given.shape} and dtype {given.dtype}, must be ({batch},) integers.")
        bad = np.flatnonzero((given < dim) | (given > n_max) | (given % dim != 0))
        if bad.size:
            raise ValueError(f"sizes[{bad[0]}] == {int(given[bad[0]])}, must be a multiple of dim == {dim} "
                             f"in [{dim}, {n_max}].")
        sizes = given.astype(np.int64)
    # Only the real (unpadded) entries are checked: padding is never read.
    rows = np.arange(n_max)[None, :] < sizes[:, None]
    contacts = rows[:, ::dim]
    for name, values, used in (("W", W, rows[:, :, None] & rows[:, None, :]), ("q", q, rows),
                               ("mu", mu, contacts), ("r0", r0, rows)):
        bad = None if values is None else np.argwhere(used & ~np.isfinite(values))
        if bad is not None and bad.size:
            raise ValueError(f"{name}[{int(bad[0, 0])}] contains NaN or inf, must be finite.")
    negative = np.argwhere((mu < 0.0) & contacts)
    if negative.size:
        b, c = negative[0]
        raise ValueError(f"mu[{b}, {c}] == {float(mu[b, c])!r}, must be >= 0.")
    return W, q, mu, r0, sizes


def solve_batch(W: np.ndarray, q: np.ndarray, mu: np.ndarray, dim: int, settings: SolverSettings,
                r0: np.ndarray | None = None, sizes: np.ndarray | None = None) -> list[CoreResult]:
    """Solve ``B`` independent small dense problems ``u = W r + q``, compiled in one call.

    Each problem is solved exactly as :func:`solve` solves it alone (same scaling, fast
    path, acceptance test and fallback), and gives bitwise the same result: problems of at most ``settings.fast_path_unknowns`` unknowns go through
    one call of the compiled kernel (:func:`nscd.solver.small.solve_dense`), which
    :func:`solve` also uses for a single dense problem; those the kernel does not accept
    are handed one by one to :func:`solve_rejected` (the proximal point, then the conic
    fixed point and the polish), larger ones to :func:`solve`.

    Parameters
    ----------
    W : ndarray, shape (B, n_max, n_max)
        Delassus matrices (unit of ``u`` per unit of ``r``), rows and columns per contact
        ``[N, T1, (T2)]``; problem ``b`` uses ``W[b, :sizes[b], :sizes[b]]`` and the
        padding is never read.
    q : ndarray, shape (B, n_max)
        Free relative velocities; ``u = W r + q``, ``u_N > 0`` separating.
    mu : ndarray, shape (B, n_max // dim)
        Friction coefficient per contact, ``>= 0`` (0: frictionless).
    dim : int
        2 or 3 (rows per contact).
    settings : SolverSettings
    r0 : ndarray, shape (B, n_max), optional
        Warm-start impulses; None: cold start (as ``r0=None`` in :func:`solve`).
    sizes : ndarray of int, shape (B,), optional
        Real unknowns of each problem, a multiple of ``dim`` in ``[dim, n_max]``;
        None: every problem has ``n_max``.

    Returns
    -------
    list of CoreResult
        One per problem, in order; ``r`` and ``u`` have shape ``(sizes[b],)``. Statuses,
        paths and counters as :func:`solve` reports them.

    Raises
    ------
    ValueError
        On wrong shapes, ``dim``, ``sizes``, non-finite data in the real entries, or
        negative friction.
    """
    W, q, mu, r0, sizes = _check_batch(W, q, mu, dim, r0, sizes)
    small_problems = np.flatnonzero(sizes <= settings.fast_path_unknowns)
    results: list[CoreResult | None] = [None] * sizes.size
    if small_problems.size == sizes.size:
        results = _solve_compiled(W, q, mu, sizes, dim, settings, r0)
    elif small_problems.size:
        compiled = _solve_compiled(W[small_problems], q[small_problems], mu[small_problems], sizes[small_problems],
                                   dim, settings, None if r0 is None else r0[small_problems])
        for b, res in zip(small_problems.tolist(), compiled):
            results[b] = res
    for b, n in enumerate(sizes.tolist()):
        if results[b] is None:
            results[b] = solve(W[b, :n, :n], q[b, :n], mu[b, :n // dim], dim, settings,
                               None if r0 is None else r0[b, :n])
    return results
