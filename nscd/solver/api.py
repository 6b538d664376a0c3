"""Public entries of the contact solver: reaction form (FCLIB) and velocity form (Moreau–Jean).

Both validate their input, reduce to ``u = W r + q`` and call the one core
(:func:`nscd.solver.core.solve`); see that module for the algorithm.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from nscd.solver import cone, core
from nscd.solver.coarse import CoarseCorrection
from nscd.solver.delassus import Delassus
from nscd.solver.settings import SolverSettings, Status

# Above this many unknowns a sparse W given by the caller stays sparse; below it the
# dense kernels are faster.
_DENSE_UNKNOWNS = 600
# Velocity form: up to this many velocity unknowns (and at most _DENSE_UNKNOWNS contact
# unknowns), H and M^-1 H^T are dense.
_DENSE_VELOCITIES = 300


@dataclass(frozen=True)
class _Report:
    """Fields common to both solution classes (documented there)."""

    merit: float
    status: Status
    converged: bool
    iterations: int
    path: str
    fast_iterations: int
    fixed_point_iterations: int
    interior_point_iterations: int
    polish_iterations: int
    sweeps: int
    proximal_iterations: int
    notes: tuple[str, ...]
    message: str


_REPORT_DOC = """
    merit : float
        FCLIB merit ``||r - P_K(r - (u + mu ||u_T|| e_N))|| / (1 + sqrt(||q||))``
        (dimensionless; with ``coulomb="relaxed"`` the merit of the relaxed problem).
    status : Status
        ``"converged"``, ``"converged after polish"``, ``"stalled"``, ``"cycling"`` or
        ``"numerical failure"``.
    converged : bool
        ``merit <= tol`` and ``u + mu ||u_T|| e_N`` within ``tol`` of the dual cone
        (guards the merit against ``||r|| >> ||u||``).
    iterations : int
        Total iterations: fast-path Newton + Gauss–Seidel sweeps + conic solves + Newton
        iterations of the proximal-point inner problems + polish Newton.
    path : str
        Which stage produced the answer: ``"newton (fast path)"``, ``"nsgs"`` (Gauss–Seidel
        sweeps of a large problem), ``"nsgs + polish"``, ``"proximal point"`` (the
        proximal-point iterations of a small problem the fast path did not accept),
        ``"proximal point + polish"``, ``"interior point"``, ``"interior point + polish"``,
        ``"regimes"`` (a small 2D problem those left above ``tol``, solved exactly by its
        contacts' regimes: :mod:`nscd.solver.regimes`) or ``"trivial (q = 0)"``.
    fast_iterations, fixed_point_iterations, interior_point_iterations, polish_iterations : int
        Newton iterations on the fast path; conic solves of the De Saxcé fixed point;
        Clarabel iterations summed over them; Newton iterations of the polish.
    sweeps : int
        Symmetric Gauss–Seidel sweeps of the large-problem path (0 if not taken).
    proximal_iterations : int
        Newton iterations of the proximal-point inner problems (0 if not taken).
    notes : tuple of str
        What was done to the data (symmetrised, regularised) or went wrong (Clarabel status).
    message : str
        Human-readable reason when not converged, else empty.
"""


@dataclass(frozen=True)
class LocalSolution(_Report):
    r: np.ndarray
    u: np.ndarray


LocalSolution.__doc__ = """Solution of the reaction form ``u = W r + q`` (:func:`solve_local`).

    Attributes
    ----------
    r : ndarray, shape (n,)
        Reactions (impulses), per contact ``[N, T1, (T2)]``, in the unit of ``q / W``.
    u : ndarray, shape (n,)
        Relative velocities ``W r + q``.""" + _REPORT_DOC


@dataclass(frozen=True)
class VelocitySolution(_Report):
    v: np.ndarray
    P: np.ndarray
    u: np.ndarray


VelocitySolution.__doc__ = """Solution of the velocity form (:func:`solve_velocity`).

    Attributes
    ----------
    v : ndarray, shape (n,)
        Velocities at the end of the step, ``v_free + M^-1 H^T P``.
    P : ndarray, shape (m, dim)
        Contact impulses in N s in the contact frames ``[N, T1, (T2)]``; ``P_N >= 0``
        pushes the bodies apart, ``||P_T|| <= mu P_N``.
    u : ndarray, shape (m, dim)
        ``u~ = H v + offset`` at the solution (m/s).""" + _REPORT_DOC


def _report(res: core.CoreResult) -> dict:
    return dict(
        merit=res.merit, status=res.status, converged=res.accepted,
        path=res.path,
        iterations=res.iterations,
        fast_iterations=res.fast_iterations, fixed_point_iterations=res.fixed_point_iterations,
        interior_point_iterations=res.interior_point_iterations, polish_iterations=res.polish_iterations,
        sweeps=res.sweeps, proximal_iterations=res.proximal_iterations,
        notes=tuple(res.notes), message=res.message,
    )


def _check_dim(dim) -> int:
    if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim not in (2, 3):
        raise ValueError(f"dim == {dim!r}, must be 2 or 3.")
    return int(dim)


def _finite(name: str, values: np.ndarray) -> None:
    if not np.isfinite(values).all():
        raise ValueError(f"{name} contains NaN or inf, must be finite.")


def _vector(name: str, x, size: int | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 1 or (size is not None and a.size != size):
        want = "a 1-D array" if size is None else f"shape ({size},)"
        raise ValueError(f"{name} has shape {a.shape}, must be {want}.")
    _finite(name, a)
    return a


def _matrix(name: str, A, shape: tuple[int | None, int | None]):
    """Dense float array or CSR matrix with the given shape (None: any), finite."""
    if sp.issparse(A):
        if A.format != "csr" or A.dtype != np.float64:
            A = sp.csr_matrix(A, dtype=float)
        data = A.data
    else:
        A = np.asarray(A, dtype=float)
        data = A
    if A.ndim != 2 or any(want is not None and got != want for got, want in zip(A.shape, shape)):
        want = "(" + ", ".join("any" if w is None else str(w) for w in shape) + ")"
        raise ValueError(f"{name} has shape {A.shape}, must be {want}.")
    _finite(name, data)
    return A


def _friction(mu, m: int) -> np.ndarray:
    mu = np.asarray(mu, dtype=float).reshape(-1) if np.ndim(mu) else np.full(1, float(mu))
    if mu.shape != (m,):
        raise ValueError(f"mu has shape {mu.shape}, must be ({m},) (one coefficient per contact).")
    _finite("mu", mu)
    if (mu < 0.0).any():
        bad = int(np.flatnonzero(mu < 0.0)[0])
        raise ValueError(f"mu[{bad}] == {float(mu[bad])!r}, must be >= 0.")
    return mu


def _settings(settings: SolverSettings | None) -> SolverSettings:
    if settings is None:
        return SolverSettings()
    if not isinstance(settings, SolverSettings):
        raise TypeError(f"settings is a {type(settings).__name__}, must be a SolverSettings.")
    return settings


def _check_local(W, q, mu, dim: int):
    """Validate the reaction form; returns (W, q, mu) as float arrays (W dense or CSR)."""
    q = _vector("q", q)
    n = q.size
    if n % dim:
        raise ValueError(f"q has {n} entries, must be a multiple of dim == {dim}.")
    W = _matrix("W", W, (n, n))
    mu = _friction(mu, n // dim)
    return W, q, mu


# Block sizes tried for a block-diagonal mass matrix (2D bodies: diagonal; 3D bodies: 6 x 6).
_BLOCK_SIZES = (1, 2, 3, 6)


def _mass_blocks(M) -> np.ndarray | None:
    """The diagonal blocks (n / k, k, k) of a block-diagonal ``M`` for the smallest k in
    ``_BLOCK_SIZES`` that fits its nonzeros, or None when no such k does."""
    n = M.shape[0]
    if sp.issparse(M):
        coo = M.tocoo()
        nonzero = coo.data != 0.0
        rows, cols, values = coo.row[nonzero], coo.col[nonzero], coo.data[nonzero]
    else:
        rows, cols = np.nonzero(M)
        values = M[rows, cols]
    for k in _BLOCK_SIZES:
        if n % k == 0 and np.array_equal(rows // k, cols // k):
            blocks = np.zeros((n // k, k, k))
            blocks[rows // k, rows % k, cols % k] = values
            return blocks
    return None


def _inverse_mass_times(M, B):
    """``M^-1 B`` for the mass matrix ``M`` (n, n) and ``B`` (n, k), dense or sparse like ``B``.

    A block-diagonal ``M`` (one block per body: diagonal in 2D, 6 x 6 in 3D; FCLIB's
    global problems) is inverted block by block, so the cost is linear in the bodies;
    any other symmetric positive definite ``M`` by a Cholesky (dense ``B``) or sparse LU
    solve. Raises ValueError when ``M`` is not symmetric positive definite.
    """
    n = M.shape[0]
    blocks = _mass_blocks(M)
    if blocks is not None and blocks.shape[1] == 1:
        diag = blocks[:, 0, 0]
        if not (diag > 0.0).all():
            bad = int(np.argmin(diag))
            raise ValueError(f"M[{bad}, {bad}] == {diag[bad]!r}, must be > 0 (M symmetric positive definite).")
        return sp.diags(1.0 / diag) @ B if sp.issparse(B) else B / diag[:, None]
    asymmetry = abs(M - M.T).max()
    if asymmetry > 1e-12 * abs(M).max():
        raise ValueError(f"M is not symmetric (max |M - M^T| == {float(asymmetry):.3g}), "
                         "must be symmetric positive definite.")
    if blocks is not None:
        try:
            np.linalg.cholesky(blocks)
        except np.linalg.LinAlgError:
            raise ValueError("M is not positive definite, must be symmetric positive definite.") from None
        inverse = np.linalg.inv(blocks)
        k = blocks.shape[1]
        if not sp.issparse(B):
            return (inverse @ B.reshape(n // k, k, -1)).reshape(B.shape)
        index = np.arange(n // k + 1)
        return (sp.bsr_array((inverse, index[:-1], index), shape=(n, n)).tocsr() @ B).tocsr()
    if not sp.issparse(B):
        # Cholesky solve straight from LAPACK (numpy.linalg adds ~15 us per call); it also
        # checks positive definiteness (of the lower triangle: M is assumed symmetric).
        _, X, info = lapack.dposv(M.toarray() if sp.issparse(M) else M, B, lower=True)
        if info != 0:
            raise ValueError("M is not positive definite, must be symmetric positive definite.")
        return X
    try:
        Minv = sp.csr_matrix(spla.spsolve(sp.csc_matrix(M), sp.identity(n, format="csc")))
    except RuntimeError:
        raise ValueError("M is singular, must be symmetric positive definite.") from None
    return (Minv @ B).tocsr()


def fclib_merit(W, q, mu, r, dim: int) -> float:
    """FCLIB's local merit ``||r - P_K(r - (u + mu ||u_T|| e_N))|| / (1 + sqrt(||q||))``.

    Parameters
    ----------
    W : ndarray or scipy.sparse matrix, shape (n, n)
        Delassus matrix, ``n = dim * contacts``.
    q : array_like, shape (n,)
        Free relative velocity; ``u = W r + q``.
    mu : array_like, shape (n // dim,)
        Friction coefficients, ``>= 0``.
    r : array_like, shape (n,)
        Reactions, per contact ``[N, T1, (T2)]``.
    dim : int
        2 or 3.

    Returns
    -------
    float
        The merit; solvers in the field call ``<= 1e-8`` solved.
    """
    dim = _check_dim(dim)
    W, q, mu = _check_local(W, q, mu, dim)
    r = _vector("r", r, q.size)
    u = W @ r + q
    return cone.merit(r.reshape(-1, dim), u.reshape(-1, dim), mu, float(np.linalg.norm(q)))


def solve_local(W, q, mu, dim: int = 3, tol: float | None = None, settings: SolverSettings | None = None,
                warm_start=None) -> LocalSolution:
    """Solve a frictional contact problem in reaction form (FCLIB's local problem).

    Find ``r, u = W r + q`` with, for every contact ``c``,
    ``K_mu ∋ r_c ⊥ u_c + mu_c ||u_T,c|| e_N ∈ K_mu*`` (De Saxcé), ``K_mu = {||r_T|| <= mu r_N}``.

    Parameters
    ----------
    W : ndarray or scipy.sparse matrix, shape (n, n)
        Delassus matrix, ``n = dim * contacts``, positive semidefinite; a slightly
        unsymmetric or indefinite ``W`` is symmetrised/regularised for the conic
        subproblem only (recorded in ``notes``).
    q : array_like, shape (n,)
        Free relative velocity.
    mu : array_like, shape (n // dim,)
        Friction coefficients, ``>= 0`` (0: frictionless).
    dim : int
        2 or 3.
    tol : float, optional
        Target merit; overrides ``settings.tol`` (default 1e-8).
    settings : SolverSettings, optional
    warm_start : array_like, shape (n,), optional
        Initial reactions.

    Returns
    -------
    LocalSolution
        Never silent: ``status``/``converged`` say whether ``merit <= tol``.
    """
    dim = _check_dim(dim)
    W, q, mu = _check_local(W, q, mu, dim)
    _check_delassus_diagonal(W, dim)
    settings = _settings(settings)
    if tol is not None:
        settings = dataclasses.replace(settings, tol=tol)
    r0 = None if warm_start is None else _vector("warm_start", np.ravel(warm_start), q.size)
    if sp.issparse(W) and q.size <= _DENSE_UNKNOWNS:
        W = W.toarray()
    res = core.solve(W, q, mu, dim, settings, r0)
    solution = LocalSolution(r=res.r, u=res.u, **_report(res))
    if not solution.converged:
        _check_semidefinite(W)
    return solution


#: Dense Delassus matrices up to this size are checked for negative eigenvalues when a solve fails.
_EIGEN_CHECK_UNKNOWNS = 2000


def _check_delassus_diagonal(W, dim: int) -> None:
    """ValueError when the diagonal of ``W`` rules out a Delassus matrix ``H M^-1 H^T``.

    Its diagonal entries are ``>= 0`` (positive semidefinite), and every normal one
    ``W_NN = n . M^-1 n > 0``: a contact that no impulse can move along its normal makes the
    problem meaningless (no impulse closes an approaching gap; the solver would run its
    impulses to ~1e21 where the merit rounds to zero).
    """
    diagonal = W.diagonal()
    negative = np.flatnonzero(diagonal < 0.0)
    if negative.size:
        i = int(negative[0])
        raise ValueError(f"W[{i}, {i}] == {float(diagonal[i])!r}: W is indefinite; a Delassus matrix is positive "
                         "semidefinite (its diagonal >= 0).")
    normal = diagonal[::dim]
    zero = np.flatnonzero(normal <= 0.0)
    if zero.size:
        i = int(zero[0]) * dim
        raise ValueError(f"W[{i}, {i}] == {float(diagonal[i])!r} (normal row of contact {zero[0]}), must be > 0: "
                         "a contact that no impulse moves along its normal.")


def _check_semidefinite(W) -> None:
    """ValueError naming the smallest eigenvalue when a dense ``W`` is clearly indefinite.

    Called after a failed solve only (an eigenvalue decomposition costs more than a solve);
    "clearly": below ``-1e-8`` times the largest eigenvalue magnitude, far beyond round-off of
    a ``W`` assembled as ``H M^-1 H^T``.
    """
    if sp.issparse(W) or W.shape[0] > _EIGEN_CHECK_UNKNOWNS:
        return
    eigenvalues = np.linalg.eigvalsh(0.5 * (W + W.T))
    if eigenvalues[0] < -1e-8 * np.max(np.abs(eigenvalues)):
        raise ValueError(f"W is indefinite (smallest eigenvalue of its symmetric part {eigenvalues[0]:.3g}, "
                         f"largest {eigenvalues[-1]:.3g}): a Delassus matrix is positive semidefinite.")


def solve_velocity(M, v_free, H, offset, mu, dim: int, settings: SolverSettings | None = None,
                   warm_start=None) -> VelocitySolution:
    """Solve one Moreau–Jean contact step in velocity form.

    Find ``v = v_free + M^-1 H^T P`` and impulses ``P`` with, per contact ``c``,
    ``K_mu ∋ P_c ⊥ u~_c + mu_c ||u~_T,c|| e_N ∈ K_mu*``, ``u~ = H v + offset``
    (``mu_c == 0``: ``P_N >= 0 ⊥ u~_N >= 0``, ``P_T = 0``). Condensed to
    ``W = H M^-1 H^T``, ``q = H v_free + offset`` and solved by the same core as
    :func:`solve_local`; ``merit`` is the FCLIB merit of that condensed problem.

    Parameters
    ----------
    M : scipy.sparse matrix or ndarray, shape (n, n)
        Mass matrix (kg, kg m^2), symmetric positive definite, block diagonal.
    v_free : array_like, shape (n,)
        Free velocity at the end of the step (m/s, rad/s).
    H : scipy.sparse matrix or ndarray, shape (m * dim, n)
        Contact Jacobian; rows per contact ``[N, T1, (T2)]``, normal pointing so that
        ``u~_N > 0`` separates.
    offset : array_like, shape (m * dim,)
        ``u~ = H v + offset``: driven-body velocities and the Newton term ``e u_N^k``
        on normal rows (m/s).
    mu : array_like, shape (m,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    settings : SolverSettings, optional
    warm_start : array_like, shape (m, dim), optional
        Impulses of the previous step (N s), e.g. matched by contact feature ids.

    Returns
    -------
    VelocitySolution
    """
    dim = _check_dim(dim)
    settings = _settings(settings)
    v_free = _vector("v_free", v_free)
    n = v_free.size
    offset = _vector("offset", offset)
    if offset.size % dim:
        raise ValueError(f"offset has {offset.size} entries, must be a multiple of dim == {dim}.")
    m = offset.size // dim
    M = _matrix("M", M, (n, n))
    H = _matrix("H", H, (m * dim, n))
    mu = _friction(mu, m)
    r0 = None
    if warm_start is not None:
        ws = np.asarray(warm_start, dtype=float)
        if ws.shape != (m, dim):
            raise ValueError(f"warm_start has shape {ws.shape}, must be ({m}, {dim}).")
        _finite("warm_start", ws)
        r0 = ws.ravel()
    if n <= _DENSE_VELOCITIES and m * dim <= _DENSE_UNKNOWNS:
        H = H.toarray() if sp.issparse(H) else H
        MinvHT = _inverse_mass_times(M, H.T)
    else:
        H = sp.csr_matrix(H)
        MinvHT = _inverse_mass_times(M, H.T.tocsr())
    return _solve_condensed(MinvHT, H, v_free, offset, mu, dim, settings, r0)


def _solve_condensed(MinvHT, H, v_free: np.ndarray, offset: np.ndarray, mu: np.ndarray, dim: int,
                     settings: SolverSettings, r0: np.ndarray | None,
                     coarse: tuple[CoarseCorrection, np.ndarray] | None = None) -> VelocitySolution:
    """The velocity form from ``M^-1 H^T`` on: condense to ``W, q``, solve, recover ``v`` and ``u``."""
    m = offset.size // dim
    if offset.size > max(settings.large_problem_unknowns, settings.fast_path_unknowns):
        # the Gauss-Seidel path: W kept factored, the sweeps run in the body velocities
        W = Delassus(sp.csr_matrix(H), MinvHT if sp.issparse(MinvHT) else sp.csr_matrix(MinvHT), dim)
    elif isinstance(MinvHT, np.ndarray):
        W = H @ MinvHT
    elif offset.size <= _DENSE_UNKNOWNS:
        W = (H @ MinvHT).toarray()
    else:
        W = H @ MinvHT
    q = H @ v_free + offset
    if m == 0:
        res = core.CoreResult(np.zeros(0), q.copy(), 0.0, Status.CONVERGED, "trivial (no contact)")
    else:
        res = core.solve(W, q, mu, dim, settings, r0, coarse if isinstance(W, Delassus) else None)
    v = v_free + MinvHT @ res.r
    u = H @ v + offset
    return VelocitySolution(v=v, P=res.r.reshape(m, dim), u=u.reshape(m, dim), **_report(res))


def solve_velocity_unchecked(mass, v_free: np.ndarray, H, offset: np.ndarray, mu: np.ndarray, dim: int,
                             settings: SolverSettings, warm_start: np.ndarray | None = None,
                             coarse: CoarseCorrection | None = None) -> VelocitySolution:
    """:func:`solve_velocity` without input checks, from ``M`` diagonal or ``M^-1``: the lean entry of the stepper.

    For callers that built the data themselves and know it valid (the stepper's own
    mass matrix, Jacobian and friction): no shape, finiteness, symmetry or positivity
    check, no conversion, no inversion of ``M``. The rest (condensation, core solve,
    recovery of ``v`` and ``u``) is the code :func:`solve_velocity` runs after its
    checks, so both give the same solution for the same data: bit for bit with a diagonal
    ``M`` (``H^T`` divided by it, as :func:`solve_velocity` does), to the rounding of
    ``M^-1`` formed by the caller otherwise. Bad data here gives wrong answers or numpy
    errors, not the ``ValueError`` of :func:`solve_velocity`.

    Parameters
    ----------
    mass : ndarray, shape (n,), or ndarray / scipy.sparse matrix, shape (n, n)
        A 1-D array is the diagonal of a diagonal ``M`` itself (kg, kg m^2; 2D bodies);
        a matrix is ``M^-1`` (1/kg, 1/(kg m^2); block diagonal, symmetric positive
        definite: 3D bodies, inverted by the caller).
    v_free : ndarray, shape (n,), float
        Free velocity at the end of the step (m/s, rad/s).
    H : ndarray or scipy.sparse.csr_matrix, shape (m * dim, n)
        Contact Jacobian, rows per contact ``[N, T1, (T2)]`` (dense below ~300 velocities).
    offset : ndarray, shape (m * dim,), float
        ``u~ = H v + offset`` (m/s).
    mu : ndarray, shape (m,), float
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    settings : SolverSettings
    warm_start : ndarray, shape (m, dim), float, optional
        Impulses of the previous step (N s).
    coarse : CoarseCorrection, optional
        Kept by the caller from step to step: the body-space correction of the
        Gauss–Seidel sweeps of large problems (:mod:`.coarse`), 2D and 3D.

    Returns
    -------
    VelocitySolution
        As :func:`solve_velocity`.
    """
    if isinstance(H, np.ndarray):
        MinvHT = H.T / mass[:, None] if mass.ndim == 1 else mass @ H.T
    elif mass.ndim == 1:
        # diag(1 / mass) H^T, the entries of H scaled in place of a sparse product: CSC (the transpose
        # of a CSR matrix), which the Delassus operator and the products below take as it is
        H = sp.csr_matrix(H)
        scaled = H.data * (1.0 / mass)[H.indices]
        MinvHT = sp.csr_matrix((scaled, H.indices.copy(), H.indptr.copy()), shape=H.shape).T
    else:
        MinvHT = (mass @ H.T).tocsr()
    r0 = None if warm_start is None else warm_start.reshape(-1)
    return _solve_condensed(MinvHT, H, v_free, offset, mu, dim, settings, r0,
                            None if coarse is None else (coarse, mass))
