"""Nonsmooth block Gauss–Seidel (NSGS) on the reaction form ``u = W r + q``, for large problems.

The method of Moreau and Jean that LMGC90 and Siconos use for large assemblies: sweep
the contacts in turn; for contact ``c`` freeze the impulses of all the others, so that
its velocity is ``u_c = W_cc r_c + b_c`` with ``b_c = q_c + sum_{j != c} W_cj r_j``,
and solve that ``dim x dim`` De Saxcé problem exactly,

    K_mu ∋ r_c ⊥ u_c + mu_c ||u_T,c|| e_N ∈ K_mu*.

A sweep costs one pass over the nonzeros of ``W`` (block-sparse rows), so the cost per
sweep is linear in the number of contacts; the number of sweeps depends on the
conditioning (it grows with the height of a wall) and on the warm start (the previous
step's impulses, extrapolated by the stepper).

The local problem has four regimes, tried in this order (``W_cc = [[a, c^T], [d, B]]``
in the rows ``[N, T...]``, ``b = (b_N, b_T)``):

- **separation** ``b_N >= 0``: ``r_c = 0`` (then ``u_c = b`` has ``u_N >= 0``);
- **frictionless** ``mu == 0``: ``r_N = -b_N / a``, ``r_T = 0``;
- **stick** ``r = -W_cc^-1 b`` if it lies in ``K_mu``;
- **slide**: ``u_N = 0``, ``||r_T|| = mu r_N`` and ``u_T = -kappa r_T`` with
  ``kappa >= 0`` (friction opposes sliding). Eliminating ``r_N = -(b_N + c.r_T) / a``
  gives ``(S + kappa I) r_T = g`` with the Schur complement ``S = B - d c^T / a`` and
  ``g = d b_N / a - b_T``. In 2D ``r_T = -s mu r_N`` for the sliding sign ``s = +-1``
  (closed form). In 3D the scalar ``kappa`` solves
  ``phi(kappa) = ||r_T(kappa)|| - mu r_N(kappa) = 0``: ``phi(0) > 0`` whenever stick was
  rejected and ``phi -> mu b_N / a < 0`` as ``kappa -> inf``, so a root is bracketed; it is
  found to round-off by Newton's method on ``rho = mu r_N / ||r_T|| - 1`` (the same root,
  nearly linear in ``kappa``), kept inside the bracket — the local solve is exact, not a few
  projected iterations.

Given ``W`` factored (:class:`~.delassus.Delassus`, the velocity form of large
assemblies) the sweeps run in the body velocities instead, and with a
:class:`~.coarse.CoarseCorrection` every sweep starts from an iterate corrected in the
body space, which removes the assembly-wide error that single-contact updates only let
diffuse: 6–16 sweeps per step on a 44-course wall on a shaking base instead of 30–100
(two-level Gauss–Seidel; if the corrected sweeps stop making progress, the plain ones
finish).

On a factored ``W``, once the plain sweeps have taken over (below), every merit check that
does not accept the iterate is followed by *focused passes*: symmetric passes over the contacts that carry almost all of the residual
and the contacts that share a body with them — in 3D, the contacts of the same joints (an
adaptive, residual-driven Gauss–Seidel).
Where a wall breaks up the residual sits on a few joints, which full sweeps settle only as
fast as the rest of the wall lets them; the focused passes settle them locally, at a
fraction of a sweep's cost each. A solution is a fixed point of the passes as of the
sweeps, so they cannot move the answer, only reach it sooner.

The sweeps are accelerated by Anderson mixing (see :func:`solve`). The kernels are
compiled with numba (:mod:`nscd._jit`), and so is the loop around them (the merit checks,
the mixing, the focused passes: :func:`_iterate`), which returns to Python only for the coarse
level. The stopping test is the caller's (:class:`StopTest`: the FCLIB merit of
:mod:`nscd.solver.core`, or its relative merit), evaluated every few sweeps.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from nscd._jit import njit
from nscd.solver import proximal, small
from nscd.solver.coarse import CoarseCorrection
from nscd.solver.delassus import Delassus, _body_velocities, _contact_velocities

# The 3D sliding root: at most _ROOT_ITERATIONS Newton steps (each a bisection of the bracket or a
# fourfold growth of its high end at worst: 200 reach round-off from any start), stopped once
# rho = mu r_N / ||r_T|| - 1 or the relative step is below _ROOT_TOLERANCE (four units of
# round-off: rho is a ratio of O(1) terms). rho is close to linear in kappa (for an isotropic
# Schur complement ||r_T|| ~ 1 / (s + kappa)), so Newton takes 3-4 steps from kappa = 0 where
# the Illinois method on ||r_T|| - mu r_N took ~10 from a bracket grown to hold the root.
_ROOT_ITERATIONS = 200
_ROOT_TOLERANCE = 4.0 * float(np.finfo(float).eps)
# Anderson acceleration of the sweeps: depth (past iterates kept), and the growth of the
# sweep residual over its smallest value that drops the history.
_DEPTH = 5
_GROWTH = 10.0
# Stagnation: stop when _STALL_CHECKS merit evaluations in a row have not brought the best
# merit below _STALL_PROGRESS times what it was before them. Redundant contacts whose
# velocity targets disagree by ~tol (gap terms of a hyperstatic wall) leave a residual that
# only a slow drift along the null space of W removes: Gauss-Seidel stalls there.
_STALL_CHECKS = 20
_STALL_PROGRESS = 0.5
# The coarse-corrected sweeps converge in a few checks or not at all: after this many
# checks without halving the merit they hand over to the plain sweeps.
_COARSE_STALL_CHECKS = 3
# The corrected sweeps are dropped at once when an iterate's merit exceeds the first plain
# sweep's by this factor: the correction assumes the loaded contacts stick, and where most
# slide or open (a wall breaking up) it throws the iterate off by far more than this factor
# (docs/solver.md, "What was measured").
_COARSE_SPOIL = 10.0
# After the correction spoiled the iterate of its first check, the next _COARSE_REST solves with
# the same correction go without it (it is tried again after them): on a wall breaking up it
# spoils the first corrected sweep of almost every solve, and preparing it (a banded factorization
# when the active rows change), applying it and checking the spoiled iterate cost ~7 % of a step.
# One that helped first and spoiled later does not rest: on the 990-block wall riding its base
# (theta scheme) the two levels pull apart after a few corrected sweeps in every other solve (the
# redundant contacts' data disagree by ~tol), and resting it there cost the next ten solves
# 100-300 one-level sweeps each where the corrected ones take 15-60 (docs/solver.md, seventh round).
_COARSE_REST = 10
# The merit is checked every this many sweeps at most while the correction is on.
_COARSE_CHECK_EVERY = 2
# Plain sweeps (after the mixing stalled) progress slowly but steadily where many contacts
# sit at the friction limit (a wall breaking up: the merit halves only every few hundred
# sweeps, docs/solver.md): they stop after this many evaluations without halving it, so a
# halving that needs that many sweeps still counts as progress. On the 990-block wall breaking
# up, the last halving (relative merit 2e-4 -> 1e-4) took up to 600 sweeps with the focused
# passes: with 60 checks (300 sweeps) 6 of 40 captured problems stalled there, with 120 two
# (docs/solver.md, eighth round); the cap max_sweeps still bounds a solve.
_PLAIN_STALL_CHECKS = 120
# Focused passes (factored W, plain sweeps only): after each merit check that does not accept the iterate,
# _FOCUS_PASSES symmetric passes over the contacts that carry _FOCUS_SHARE of the squared
# residual and every contact that shares a body with them. On a wall breaking up the residual
# sits on a few joints (half of it on 3-4 of ~300 contacts, docs/solver.md, fifth round) that
# full sweeps settle only as fast as the rest of the wall lets them; on 169 problems of the
# 97-block wall's break-up, 30 passes over 99 % took the unaccepted ones from 18 to 2 at the same
# CPU (10 passes, or 90 %: more left unaccepted; 60 or 100 passes: as few, dearer). Not during
# Anderson's mixing: the passes change the map it extrapolates (a random problem it solves alone
# then needs the polish), and on the wall the mixing phase gains nothing from them.
# In 3D the neighbours are the contacts of the same joints instead (between the same two bodies:
# a face's four corner points): a 3D block touches ~24 contact points, and on the 97-block wall
# 0.2 m deep the contacts sharing a body with the hot ones were 89 % of all, so the 30 passes cost
# 27 sweeps after every 5 (62 % of the solver's CPU through the break-up); over the joints, as few
# steps unconverged at less CPU (docs/solver.md, "3D, sixth round").
# The passes go over the contacts that carry 90 % of the residual, not 99 %: on the 990-block wall
# breaking up, 99 % with their neighbours is about half the wall (a pass then costs half a sweep), 90 %
# a third; with the plain sweeps' stall window long enough for the last halving, 2 of 40 captured
# problems were left above the tolerance instead of 6, at 14 % less CPU (docs/solver.md, eighth round).
# In 3D the joints of 99 % were 55 % of the contacts through the 97-block wall's rocking, those of 90 %
# 27 %: on 38 captured problems 10 % less CPU, as many accepted (docs/solver.md, "3D, eighth round").
_FOCUS_PASSES = 30
_FOCUS_SHARE = 0.90
# Relative ridge of Anderson's least-squares normal equations (and its floor, for an all-zero history).
_RIDGE = 1e-12
_TINY = float(np.finfo(float).tiny)


@njit
def _local_2d(a: float, c: float, d: float, e: float, bn: float, bt: float, mu: float) -> tuple:
    """Exact 2D local De Saxcé solve for ``u = [[a, c], [d, e]] r + (bn, bt)``; returns ``(r_N, r_T)``."""
    if bn >= 0.0:
        return 0.0, 0.0
    if mu == 0.0:
        return -bn / a, 0.0
    det = a * e - c * d
    best_n, best_t, best_violation = 0.0, 0.0, np.inf
    if det > 0.0:
        rn = (c * bt - e * bn) / det
        rt = (d * bn - a * bt) / det
        violation = max(abs(rt) - mu * rn, -rn, 0.0)
        if violation == 0.0:
            return rn, rt
        best_n, best_t, best_violation = rn, rt, violation
    for s in (1.0, -1.0):
        # sliding with sign s: r_T = -s mu r_N, u_N = 0, s u_T >= 0
        den = a - s * mu * c
        if den <= 0.0:
            continue
        rn = -bn / den
        ut = (d - s * mu * e) * rn + bt
        violation = max(-s * ut, 0.0)
        if violation == 0.0:
            return rn, -s * mu * rn
        if violation < best_violation:
            best_n, best_t, best_violation = rn, -s * mu * rn, violation
    # Round-off at a regime boundary (e.g. stick with |r_T| = mu r_N): the closest
    # candidate; the caller's global merit judges the result.
    return best_n, best_t


@njit
def _slide_tangent(s00: float, s01: float, s10: float, s11: float, g0: float, g1: float,
                   kappa: float) -> tuple:
    """``(S + kappa I)^-1 g`` for a 2 x 2 ``S`` (0, 0 when singular)."""
    m00, m11 = s00 + kappa, s11 + kappa
    det = m00 * m11 - s01 * s10
    if det == 0.0:
        return 0.0, 0.0
    return (m11 * g0 - s01 * g1) / det, (m00 * g1 - s10 * g0) / det


@njit
def _local_3d(w: np.ndarray, b: np.ndarray, mu: float, out: np.ndarray) -> None:
    """Exact 3D local De Saxcé solve for ``u = w r + b`` (``w`` 3 x 3); writes ``r`` into ``out``."""
    _local_3d_reduced(_reduce_3d(w), b, mu, out, 0.0)


# Slots of a 3D diagonal block reduced for its local solves (_reduce_3d): 1 / a, c / a, d / a, the Schur
# complement S (row by row), det S and 1 / det S; then, in the sweeps' rows (_reduced_blocks), the contact's
# last sliding kappa (0: none yet), where its next slide's root is sought first.
_REDUCED_3D = 11
_LAST_KAPPA = _REDUCED_3D


@njit
def _reduce_3d(w: np.ndarray) -> tuple:
    """What the local solves of ``w = [[a, c^T], [d, B]]`` (3 x 3) reuse: ``(1 / a, c_0 / a, c_1 / a,
    d_0 / a, d_1 / a, S_00, S_01, S_10, S_11, det S, 1 / det S)`` with the Schur complement
    ``S = B - d c^T / a`` (``1 / det S`` = 0 where ``det S <= 0``)."""
    a = w[0, 0]
    s00 = w[1, 1] - w[1, 0] * w[0, 1] / a
    s01 = w[1, 2] - w[1, 0] * w[0, 2] / a
    s10 = w[2, 1] - w[2, 0] * w[0, 1] / a
    s11 = w[2, 2] - w[2, 0] * w[0, 2] / a
    det = s00 * s11 - s01 * s10
    return (1.0 / a, w[0, 1] / a, w[0, 2] / a, w[1, 0] / a, w[2, 0] / a, s00, s01, s10, s11, det,
            1.0 / det if det > 0.0 else 0.0)


@njit
def _reduced_blocks(blocks: np.ndarray) -> np.ndarray:
    """:func:`_reduce_3d` of every diagonal block (m, 3, 3) with ``a > 0``, (m, ``_REDUCED_3D + 1``) with the
    slot ``_LAST_KAPPA`` at 0; zeros elsewhere (contacts the sweeps skip)."""
    reduced = np.zeros((blocks.shape[0], _REDUCED_3D + 1))
    for c in range(blocks.shape[0]):
        if blocks[c, 0, 0] > 0.0:
            values = _reduce_3d(blocks[c])
            for i in range(_REDUCED_3D):
                reduced[c, i] = values[i]
    return reduced


@njit
def _local_3d_reduced(k, b: np.ndarray, mu: float, out: np.ndarray, start: float) -> float:
    """:func:`_local_3d` from the reduced block ``k`` (:func:`_reduce_3d`, a tuple or a row of
    :func:`_reduced_blocks`): :func:`_local_3d_solve` of its numbers, ``r`` written into ``out``; returns
    the slide's ``kappa`` (0 for the other regimes)."""
    out[0], out[1], out[2], kappa = _local_3d_solve(k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7], k[8], k[9],
                                                    k[10], b[0], b[1], b[2], mu, start)
    return kappa


@njit
def _local_3d_solve(inv_a: float, c0: float, c1: float, d0: float, d1: float, s00: float, s01: float, s10: float,
                    s11: float, det_s: float, inv_det_s: float, bn: float, bt0: float, bt1: float, mu: float,
                    start: float) -> tuple:
    """The exact 3D local De Saxcé solve of ``u = w r + b`` from the numbers of its reduced block
    (:func:`_reduce_3d`: ``inv_a`` ... ``inv_det_s``) and ``b = (bn, bt0, bt1)``: no division on the way to a
    stick, one per Newton step of a slide. A slide's root is sought from ``kappa = start`` when that is
    inside its bracket (a contact's last sliding ``kappa``: from sweep to sweep it moves little), else from
    the bracket's low end. Returns ``(r_N, r_T0, r_T1, kappa)``, ``kappa`` the slide's (0 for the other
    regimes). Numbers in and out, no array: the sweeps call it once per contact, and a compiled callee
    given arrays takes and drops a reference to each at every call (``docs/solver.md``, fourteenth
    round)."""
    if bn >= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if mu == 0.0:
        return -bn * inv_a, 0.0, 0.0, 0.0
    # right-hand side g = d b_N / a - b_T of (S + kappa I) r_T = g
    g0 = d0 * bn - bt0
    g1 = d1 * bn - bt1
    bn_a = bn * inv_a
    # stick: kappa = 0
    t0 = (s11 * g0 - s01 * g1) * inv_det_s
    t1 = (s00 * g1 - s10 * g0) * inv_det_s
    rn = -(bn_a + c0 * t0 + c1 * t1)
    # phi(0) = |t| - mu r_N > 0 (outside the cone), compared in squares (no root taken)
    outside = not (rn >= 0.0 and t0 * t0 + t1 * t1 <= (mu * rn) * (mu * rn))
    if not outside and det_s > 0.0:
        return rn, t0, t1, 0.0
    # slide: the root of rho(kappa) = mu r_N(kappa) / ||t(kappa)|| - 1, by Newton's method kept inside the
    # bracket [low, high] that each evaluation narrows (bisection, or growth while no high end is known)
    low = 0.0
    if not outside:  # singular Schur complement at kappa = 0: start just above it
        low = 1e-14 * (abs(s00) + abs(s11) + 1.0)
    high = np.inf
    scale = abs(s00) + abs(s01) + abs(s10) + abs(s11) + 1e-300
    kappa = start if start > low else low
    for _ in range(_ROOT_ITERATIONS):
        m00, m11 = s00 + kappa, s11 + kappa
        det = m00 * m11 - s01 * s10
        if det == 0.0:  # S + kappa I singular (S not positive definite): move on in the bracket
            kappa = 0.5 * (low + high) if high < np.inf else max(4.0 * kappa, scale)
            continue
        inverse = 1.0 / det
        t0 = (m11 * g0 - s01 * g1) * inverse
        t1 = (m00 * g1 - s10 * g0) * inverse
        norm_t = np.sqrt(t0 * t0 + t1 * t1)
        if norm_t == 0.0:
            # g = 0 (a singular S: the stick test could not take it) or t below the smallest
            # number: r_T = 0 and u_N = 0 solve the contact (u_T = -g = 0)
            return -bn_a, 0.0, 0.0, kappa
        rn = -(bn_a + c0 * t0 + c1 * t1)
        rho = mu * rn / norm_t - 1.0
        if not abs(rho) > _ROOT_TOLERANCE:  # at the root to round-off
            break
        if rho < 0.0:
            low = kappa
        else:
            high = kappa
        # d t / d kappa = -(S + kappa I)^-1 t
        dt0 = (s01 * t1 - m11 * t0) * inverse
        dt1 = (s10 * t0 - m00 * t1) * inverse
        slope = mu * (-(c0 * dt0 + c1 * dt1) * norm_t - rn * (t0 * dt0 + t1 * dt1) / norm_t) / (norm_t * norm_t)
        step = kappa - rho / slope if slope != 0.0 else np.nan  # compiled code raises on / 0
        if not low < step < high:
            step = 0.5 * (low + high) if high < np.inf else max(4.0 * kappa, scale)
        if abs(step - kappa) <= _ROOT_TOLERANCE * kappa:
            kappa = step
            break
        kappa = step
    t0, t1 = _slide_tangent(s00, s01, s10, s11, g0, g1, kappa)
    norm_t = np.sqrt(t0 * t0 + t1 * t1)
    return norm_t / mu, t0, t1, kappa  # on the cone surface (r_N = -(b_N + c.t) / a at the root)


@njit
def _diagonal_blocks(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> np.ndarray:
    """The diagonal blocks ``W_cc`` (m, dim, dim) of a block-sparse (BSR) matrix; zero where absent."""
    m, dim = indptr.size - 1, data.shape[1]
    blocks = np.zeros((m, dim, dim))
    for c in range(m):
        for k in range(indptr[c], indptr[c + 1]):
            if indices[k] == c:
                blocks[c] += data[k]
    return blocks


@njit
def _symmetric_sweep(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, blocks: np.ndarray,
                     q: np.ndarray, mu: np.ndarray, r: np.ndarray) -> None:
    """One symmetric Gauss–Seidel sweep (contacts forward, then backward) on ``r`` (m, dim), in place.

    ``indptr, indices, data`` are ``W`` in block-sparse row form (dim x dim blocks).
    """
    m, dim = blocks.shape[0], blocks.shape[1]
    b = np.empty(dim)
    local = np.empty(dim)
    for k in range(2 * m):
        c = k if k < m else 2 * m - 1 - k
        w = blocks[c]
        if w[0, 0] <= 0.0:
            continue  # a contact that no impulse can move: leave it
        for i in range(dim):
            acc = q[c, i]
            for j in range(dim):
                acc -= w[i, j] * r[c, j]
            b[i] = acc
        if dim == 2:  # unrolled: the hot loop of the 2D walls
            b0, b1 = b[0], b[1]
            for e in range(indptr[c], indptr[c + 1]):
                col = indices[e]
                x0, x1 = r[col, 0], r[col, 1]
                b0 += data[e, 0, 0] * x0 + data[e, 0, 1] * x1
                b1 += data[e, 1, 0] * x0 + data[e, 1, 1] * x1
            b[0], b[1] = b0, b1
        else:
            for e in range(indptr[c], indptr[c + 1]):
                col = indices[e]
                for i in range(dim):
                    acc = 0.0
                    for j in range(dim):
                        acc += data[e, i, j] * r[col, j]
                    b[i] += acc
        if dim == 2:
            local[0], local[1] = _local_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], b[0], b[1], mu[c])
        else:
            _local_3d(w, b, mu[c], local)
        for i in range(dim):
            r[c, i] = local[i]


@njit
def _symmetric_sweep_body(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray,
                          g_ind: np.ndarray, g_dat: np.ndarray, blocks: np.ndarray, bodies: np.ndarray,
                          h_rows: np.ndarray, g_rows: np.ndarray, reduced: np.ndarray, q: np.ndarray, mu: np.ndarray,
                          r: np.ndarray, y: np.ndarray) -> None:
    """:func:`_symmetric_sweep` on a factored ``W = H G^T`` (:class:`~.delassus.Delassus`), in place.

    ``y = G^T r`` (the bodies' impulse velocities ``M^-1 H^T r``) must hold on entry and
    is kept up to date: contact ``c`` reads ``u_c = H_c y + q_c`` and, after its local
    solve, adds ``G_c^T dr_c`` to ``y``. The arrays up to ``reduced`` are :func:`sweep_arrays`:
    ``h_*``/``g_*`` the CSR rows of ``H`` and ``G`` (2D), ``bodies, h_rows, g_rows`` the same rows
    laid out contact by contact and ``reduced`` the diagonal blocks reduced for the local solves (3D).
    """
    _sweep_contacts(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced, q, mu, r,
                    y, np.arange(blocks.shape[0]), 1)


@njit
def _sweep_contacts(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray,
                    g_ind: np.ndarray, g_dat: np.ndarray, blocks: np.ndarray, bodies: np.ndarray,
                    h_rows: np.ndarray, g_rows: np.ndarray, reduced: np.ndarray, q: np.ndarray, mu: np.ndarray,
                    r: np.ndarray, y: np.ndarray, order: np.ndarray, passes: int) -> None:
    """``passes`` symmetric passes (forward, then backward) of :func:`_symmetric_sweep_body` over the
    contacts ``order`` only, in place (``y = G^T r`` kept up to date)."""
    if blocks.shape[1] == 2:
        _sweep_contacts_2d(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, q, mu, r, y, order, passes)
    else:
        _sweep_contacts_3d(bodies, h_rows, g_rows, blocks, reduced, q, mu, r, y, order, passes)


@njit
def _sweep_contacts_3d(bodies: np.ndarray, h_rows: np.ndarray, g_rows: np.ndarray, blocks: np.ndarray,
                       reduced: np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray, y: np.ndarray,
                       order: np.ndarray, passes: int) -> None:
    """:func:`_sweep_contacts` for ``dim == 3``, on the rows laid out contact by contact
    (:meth:`~.delassus.Delassus.contact_rows`): the twelve body velocities of a contact gathered once
    for its three rows, no column index read per entry. The sums run in the order of the CSR rows
    (the bodies ascending, an absent entry adding an exact zero), so the iterates are those of the
    rows of ``H`` and ``G`` swept entry by entry. A contact without impulse whose normal velocity does not
    approach (``u_N >= 0``: it stays open, ``r = 0``) is left after its normal row, its tangential rows and
    its writes skipped: a third of the contacts of the 97-block wall 0.2 m deep through its rocking, the
    sweep ~10 % cheaper, the iterates the same. ``reduced``: the diagonal blocks reduced for the local
    solves (:func:`_reduced_blocks`)."""
    m = order.size
    velocity = np.zeros(12)
    for _ in range(passes):
        for k in range(2 * m):
            c = order[k] if k < m else order[2 * m - 1 - k]
            if blocks[c, 0, 0] <= 0.0:
                continue  # a contact that no impulse can move: leave it
            first, second = bodies[c, 0], bodies[c, 1]
            for j in range(6):
                velocity[j] = y[first + j] if first >= 0 else 0.0
                velocity[6 + j] = y[second + j] if second >= 0 else 0.0
            r0, r1, r2 = r[c, 0], r[c, 1], r[c, 2]
            acc0 = q[c, 0]
            for j in range(12):
                acc0 += h_rows[c, 0, j] * velocity[j]
            if acc0 >= 0.0 and r0 == 0.0 and r1 == 0.0 and r2 == 0.0:
                continue  # unloaded and opening: its local solve keeps r = 0 (b_N = u_N >= 0), y unchanged
            # the tangential rows' sums side by side: two independent chains of additions
            acc1, acc2 = q[c, 1], q[c, 2]
            for j in range(12):
                v = velocity[j]
                acc1 += h_rows[c, 1, j] * v
                acc2 += h_rows[c, 2, j] * v
            b0 = acc0 - blocks[c, 0, 0] * r0 - blocks[c, 0, 1] * r1 - blocks[c, 0, 2] * r2
            b1 = acc1 - blocks[c, 1, 0] * r0 - blocks[c, 1, 1] * r1 - blocks[c, 1, 2] * r2
            b2 = acc2 - blocks[c, 2, 0] * r0 - blocks[c, 2, 1] * r1 - blocks[c, 2, 2] * r2
            n0, n1, n2, kappa = _local_3d_solve(
                reduced[c, 0], reduced[c, 1], reduced[c, 2], reduced[c, 3], reduced[c, 4], reduced[c, 5],
                reduced[c, 6], reduced[c, 7], reduced[c, 8], reduced[c, 9], reduced[c, 10], b0, b1, b2, mu[c],
                reduced[c, _LAST_KAPPA])
            if kappa > 0.0:
                reduced[c, _LAST_KAPPA] = kappa
            change0, change1, change2 = n0 - r0, n1 - r1, n2 - r2
            for side in range(2):
                start = bodies[c, side]
                if start < 0:
                    continue
                for j in range(6):
                    value = y[start + j]
                    value += g_rows[c, 0, 6 * side + j] * change0
                    value += g_rows[c, 1, 6 * side + j] * change1
                    value += g_rows[c, 2, 6 * side + j] * change2
                    y[start + j] = value
            r[c, 0], r[c, 1], r[c, 2] = n0, n1, n2


@njit
def _sweep_contacts_2d(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray,
                       g_ind: np.ndarray, g_dat: np.ndarray, blocks: np.ndarray, q: np.ndarray, mu: np.ndarray,
                       r: np.ndarray, y: np.ndarray, order: np.ndarray, passes: int) -> None:
    """:func:`_sweep_contacts` for ``dim == 2``, in scalars (the hot loop of the 2D walls)."""
    m = order.size
    for _ in range(passes):
        for k in range(2 * m):
            c = order[k] if k < m else order[2 * m - 1 - k]
            a = blocks[c, 0, 0]
            if a <= 0.0:
                continue
            w01, w10, w11 = blocks[c, 0, 1], blocks[c, 1, 0], blocks[c, 1, 1]
            r0, r1 = r[c, 0], r[c, 1]
            b0 = q[c, 0] - a * r0 - w01 * r1
            b1 = q[c, 1] - w10 * r0 - w11 * r1
            row = 2 * c
            for e in range(h_ptr[row], h_ptr[row + 1]):
                b0 += h_dat[e] * y[h_ind[e]]
            for e in range(h_ptr[row + 1], h_ptr[row + 2]):
                b1 += h_dat[e] * y[h_ind[e]]
            n0, n1 = _local_2d(a, w01, w10, w11, b0, b1, mu[c])
            change0, change1 = n0 - r0, n1 - r1
            if change0 != 0.0:
                for e in range(g_ptr[row], g_ptr[row + 1]):
                    y[g_ind[e]] += g_dat[e] * change0
            if change1 != 0.0:
                for e in range(g_ptr[row + 1], g_ptr[row + 2]):
                    y[g_ind[e]] += g_dat[e] * change1
            r[c, 0], r[c, 1] = n0, n1


@dataclass
class NSGSResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    r : ndarray, shape (n,)
        Impulses of the last merit evaluation (the output of a plain sweep, so every
        ``r_c`` lies in its cone), or the best one when not accepted.
    merit : float
        The FCLIB merit of ``r`` (:class:`StopTest`).
    relative : float
        Its merit relative to the problem's own scale (:meth:`nscd.solver.core._Scaled.relative`).
    accepted : bool
        The caller's :class:`StopTest` accepted ``r``.
    sweeps : int
        Symmetric sweeps taken (each is one forward and one backward pass); when not
        accepted, also the reason: ``max_sweeps``, or fewer when the merit stagnated.
    restarts : int
        Times the Anderson history was dropped because the sweep residual grew.
    """

    r: np.ndarray
    merit: float
    relative: float
    accepted: bool
    sweeps: int
    restarts: int


@dataclass(frozen=True)
class StopTest:
    """The sweeps' acceptance test, evaluated inside the compiled iterations (:func:`nscd.solver.proximal._measure`,
    the test of :meth:`nscd.solver.core._Scaled.stop_relative`) on the scaled pair ``(r', u')``.

    Attributes
    ----------
    d : ndarray, shape (n,)
        Per-row scale ``r = sigma d r'``, ``u = sigma u' / d`` (``d_c = 1 / sqrt(W_NN,c)``).
    sigma : float
        Global scale.
    q_norm : float
        ``||q||_2`` of the unscaled problem (FCLIB's merit divides by ``1 + sqrt(q_norm)``).
    exact : bool
        Exact Coulomb (the De Saxcé shift in the merit).
    tol : float
        Accepted at FCLIB merit and dual-cone violation ``<= tol``.
    tol_relative : float
        Or at relative merit ``<= tol_relative`` (``<= 0``: the absolute test alone).
    """

    d: np.ndarray
    sigma: float
    q_norm: float
    exact: bool
    tol: float
    tol_relative: float


def solve(W, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray | None, max_sweeps: int,
          check_every: int, test: StopTest, coarse: tuple[CoarseCorrection, np.ndarray] | None = None,
          plain_above: float = np.inf) -> NSGSResult:
    """NSGS with Anderson acceleration on ``u = W r + q``, stopped by the caller's merit.

    One iteration is a symmetric sweep ``g = G(x)`` (contacts forward, then backward:
    a symmetric Gauss–Seidel, the better preconditioner); the next iterate is Anderson's
    type-II mix ``x_next = g - (dX + dF) gamma`` of the last ``_DEPTH`` iterates,
    ``gamma`` minimising ``||f - dF gamma||`` for the sweep residuals ``f = g - x``
    (Walker & Ni 2011). Why: on a 19-course wall plain Gauss–Seidel contracts by
    ~0.998 per sweep (2000 sweeps to merit 1e-8 from the previous step's impulses),
    the accelerated sweeps take ~60 (~200 on a 44-course wall). When ``||f||`` grows past ``_GROWTH`` times its
    smallest value (a change of contact regime breaks the near-linear model), the history
    is dropped and the mixing restarts from the last plain sweep. When the merit stagnates
    (``_STALL_CHECKS``) above ``plain_above``, the mixing and the coarse level are dropped
    and plain sweeps go on from the best iterate (on a wall at the friction limit they still
    progress where the mixing stalls: ``docs/solver.md``). The sweeps end when the merit is
    accepted, after ``max_sweeps``, when the mixing stagnates at or below ``plain_above``,
    or when the plain sweeps stagnate too.

    The iterations, the merit checks, the mixing and the focused passes run in one compiled
    call (:func:`_iterate`); it returns to Python only for the coarse level (its factor and
    each correction are scipy's), while that is on.

    Parameters
    ----------
    W : scipy.sparse matrix or Delassus, shape (n, n)
        Delassus matrix, ``n = m * dim``, rows per contact ``[N, T1, (T2)]``; its
        diagonal blocks must be positive definite (rigid bodies: they are). Given as a
        :class:`~.delassus.Delassus` (factored), the sweeps run in the body velocities.
    q : ndarray, shape (n,)
        Free relative velocity.
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    r0 : ndarray, shape (n,), optional
        Warm start (previous step's impulses); zeros if None.
    max_sweeps : int
        Cap on the symmetric sweeps.
    check_every : int
        Evaluate the merit every this many sweeps (and at the cap).
    test : StopTest
        The acceptance test (FCLIB merit of the unscaled pair, or the relative merit).
    coarse : (CoarseCorrection, ndarray), optional
        With a factored ``W``: the body-space correction (:mod:`.coarse`) and the mass
        (diagonal of ``M`` in 2D, ``M^-1`` in 3D); from the second sweep on each sweep starts from the corrected iterate
        (the Anderson map is then sweep-after-correction), and the merit is checked every
        other sweep at most. A correction that spoils an iterate is dropped, and if it did so at
        its first check the next ``_COARSE_REST`` solves go without it (``CoarseCorrection.resting``).
    plain_above : float
        When the mixing stagnates with the best merit above this, plain sweeps go on from
        the best iterate; at or below it the sweeps end there (the caller polishes by
        Newton, which converges quadratically from close by). 0: always go on; inf (the
        default): never, the mixing alone.

    Returns
    -------
    NSGSResult
    """
    m = mu.size
    q_blocks = np.ascontiguousarray(q, dtype=np.float64).reshape(m, dim)
    mu = np.ascontiguousarray(mu, dtype=np.float64)
    x = np.zeros(q.size) if r0 is None else np.array(r0, dtype=np.float64)
    factored = isinstance(W, Delassus)
    if factored:
        data = sweep_arrays(W)
        velocities = W.H.shape[1]
    else:  # one compiled signature (int64, float64), the blocks' entries flat
        B = sp.bsr_matrix(W, blocksize=(dim, dim))
        B.sort_indices()
        indptr, indices = B.indptr.astype(np.int64), B.indices.astype(np.int64)
        entries = np.ascontiguousarray(B.data, dtype=np.float64)
        none = np.zeros(0, dtype=np.int64)
        data = (indptr, indices, entries.reshape(-1), none, none, np.zeros(0),
                _diagonal_blocks(indptr, indices, entries), *_NO_CONTACT_ROWS)
        velocities = 0
    state = np.zeros(_STATE_SLOTS, dtype=np.int64)
    state[_CHECK_EVERY] = check_every
    reals = np.full(_REAL_SLOTS, np.inf)
    x_in, g, best_r = np.empty_like(x), np.empty_like(x), x.copy()
    work = (np.empty((_DEPTH, x.size)), np.empty((_DEPTH, x.size)), np.empty_like(x), np.empty_like(x),
            np.empty_like(x), np.empty(max_sweeps + 1), np.empty(x.size), np.empty(velocities),
            np.empty((_DEPTH, _DEPTH)))
    with_coarse = coarse is not None and factored and coarse[0].resting == 0
    if coarse is not None and coarse[0].resting:
        coarse[0].resting -= 1
    d = np.ascontiguousarray(test.d, dtype=np.float64)
    corrected = 0  # corrected sweeps of this solve
    while True:
        outcome = _iterate(data, factored, dim, q_blocks, mu, d, float(test.sigma), float(test.q_norm),
                           bool(test.exact), float(test.tol), float(test.tol_relative), max_sweeps, check_every,
                           float(plain_above), with_coarse, state, reals, x, x_in, g, best_r, *work)
        if outcome == _DONE:
            if state[_SPOILED] and corrected <= _COARSE_CHECK_EVERY:  # spoiled at its first check
                coarse[0].resting = _COARSE_REST
            return NSGSResult(best_r, float(reals[_BEST_MERIT]), float(reals[_BEST_RELATIVE]), bool(state[_ACCEPTED]),
                              int(state[_BEST_SWEEPS]), int(state[_RESTARTS]))
        if outcome == _PREPARE:
            state[_COARSE] = coarse[0].prepare(W, coarse[1], mu, g)
        else:
            x_in[:] = coarse[0].correct(W, q, x)
            corrected += 1


# The contact-by-contact rows of a 2D or unfactored W (its sweeps read the CSR rows): empty.
_NO_CONTACT_ROWS = (np.zeros((0, 2), dtype=np.int64), np.zeros((0, 3, 12)), np.zeros((0, 3, 12)),
                    np.zeros((0, _REDUCED_3D + 1)))


def sweep_arrays(W: Delassus) -> tuple:
    """What the body-velocity sweeps read of a factored ``W``: :meth:`~.delassus.Delassus.sweep_data`
    (CSR rows of ``H`` and ``G``, diagonal blocks), then in 3D the rows laid out contact by contact
    (:meth:`~.delassus.Delassus.contact_rows`) and the diagonal blocks reduced for the local solves
    (:func:`_reduced_blocks`; empty in 2D)."""
    if W.dim != 3:
        return W.sweep_data() + _NO_CONTACT_ROWS
    data = W.sweep_data()
    return data + W.contact_rows() + (_reduced_blocks(data[6]),)


@njit
def _body_sweeps(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray, g_ind: np.ndarray,
                 g_dat: np.ndarray, blocks: np.ndarray, bodies: np.ndarray, h_rows: np.ndarray, g_rows: np.ndarray,
                 reduced: np.ndarray, q: np.ndarray, mu: np.ndarray, x: np.ndarray, g: np.ndarray, y: np.ndarray,
                 count: int) -> None:
    """``g`` = ``count`` symmetric sweeps (:func:`_symmetric_sweep_body`) from ``x``; ``y = G^T g`` on exit."""
    for row in range(x.size):
        g[row] = x[row]
    _body_velocities(g_ptr, g_ind, g_dat, x, y)
    _sweep_contacts(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced, q, mu,
                    g.reshape(q.shape), y, np.arange(q.shape[0]), count)


@njit
def merit_test(r_s: np.ndarray, u_s: np.ndarray, d: np.ndarray, sigma: float, mu: np.ndarray, dim: int,
               exact: bool, q_norm: float) -> tuple:
    """The unscaled FCLIB merit and dual-cone violation of the scaled pair, from Python
    (:meth:`nscd.solver.core._Scaled.stop_relative`): :func:`nscd.solver.small._unscaled_test`, a
    compiled helper without an entry from Python, which called from Python would run as plain Python."""
    return small._unscaled_test(r_s, u_s, d, sigma, mu, dim, exact, q_norm, np.empty(small.TEST_VECTORS * r_s.size))


@njit
def _contact_residuals(r: np.ndarray, u: np.ndarray, mu: np.ndarray, dim: int, out: np.ndarray) -> None:
    """``out[c] = |F_c|^2``, De Saxce's natural map of contact ``c`` (exact Coulomb), ``u = W r + q``."""
    f = np.empty(r.size)
    small._natural_map(r, u, mu, dim, True, np.empty(r.size), f)
    for c in range(out.size):
        acc = 0.0
        for i in range(dim):
            acc += f[c * dim + i] * f[c * dim + i]
        out[c] = acc


@njit
def _gram_row(dF: np.ndarray, row: int, used: int, gram: np.ndarray) -> None:
    """Row and column ``row`` of the Gram matrix ``dF dF^T`` of the first ``used`` rows of the history, after
    row ``row`` of ``dF`` changed (the others' entries stay valid): ``used`` sums in one pass over ``dF[row]``,
    each in the order of the entries."""
    n = dF.shape[1]
    sums = np.zeros(_DEPTH)
    for t in range(n):
        value = dF[row, t]
        for j in range(used):
            sums[j] += value * dF[j, t]
    for j in range(used):
        gram[row, j] = sums[j]
        gram[j, row] = sums[j]


@njit
def _anderson_mix(dX: np.ndarray, dF: np.ndarray, used: int, gram: np.ndarray, g: np.ndarray, f: np.ndarray,
                  out: np.ndarray) -> None:
    """Anderson's type-II mix ``out = g - gamma (dX + dF)`` over the first ``used`` rows of the histories.

    ``gamma`` solves the small normal equations ``(dF dF^T + ridge) gamma = dF f``
    (ridge ``_RIDGE trace``, against near-collinear rows) by Gaussian elimination with
    partial pivoting (:func:`nscd.solver.small._lu_solve`); the order of the rows does not
    matter. ``gram`` holds ``dF dF^T`` (kept up to date by :func:`_gram_row` as rows are
    pushed: one row of sums per sweep instead of the whole matrix). Where the elimination fails
    (a zero pivot, a non-finite gamma) ``out = g``, the plain step.
    """
    n = g.size
    normal = np.empty((used, used))
    rhs = np.zeros(used)  # dF f: the rows' sums side by side, each in the order of the entries
    for t in range(n):
        value = f[t]
        for i in range(used):
            rhs[i] += dF[i, t] * value
    trace = 0.0
    for i in range(used):
        for j in range(used):
            normal[i, j] = gram[i, j]
        trace += gram[i, i]
    for i in range(used):
        normal[i, i] += _RIDGE * trace + _TINY
    gamma = np.empty(used)
    if not small._lu_solve(normal, rhs, gamma):
        for t in range(n):
            out[t] = g[t]
        return
    for t in range(n):
        out[t] = g[t]
    for i in range(used):  # row by row: independent updates, which the compiler vectorises (same sums)
        for t in range(n):
            out[t] -= gamma[i] * (dX[i, t] + dF[i, t])




# What _iterate returns: the sweeps are over (the best iterate in best_r), or Python must prepare
# the coarse level from the first sweep (state[_COARSE] = whether it is on), or correct x into x_in.
_DONE, _PREPARE, _CORRECT = 0, 1, 2
# Where _iterate resumes (state[_STAGE]): before a sweep (x the iterate), at the sweep (x_in its
# start), after the first sweep with the coarse level prepared.
_NEXT, _SWEEP, _PREPARED = 0, 1, 2
# Slots of the integer state of _iterate: sweeps taken, Anderson pushes, restarts, plain phase (0/1),
# coarse level on (0/1), sweeps per check, checks recorded, a previous iterate in the history
# (0/1), sweeps of the best iterate, best accepted (0/1), stage, the coarse level dropped for
# spoiling an iterate (0/1).
(_SWEEPS, _PUSHES, _RESTARTS, _PLAIN, _COARSE, _CHECK_EVERY, _CHECKS, _PREVIOUS, _BEST_SWEEPS, _ACCEPTED,
 _STAGE, _SPOILED) = range(12)
_STATE_SLOTS = 12
# Slots of the real state: best merit and its relative merit, smallest sweep residual, merit of the
# first (plain) sweep.
_BEST_MERIT, _BEST_RELATIVE, _BEST_NORM, _FIRST_MERIT = range(4)
_REAL_SLOTS = 4


@njit
def _iterate(data: tuple, factored: bool, dim: int, q_blocks: np.ndarray, mu: np.ndarray, d: np.ndarray,
             sigma: float, q_norm: float, exact: bool, tol: float, tol_relative: float, max_sweeps: int,
             plain_check_every: int, plain_above: float, with_coarse: bool, state: np.ndarray, reals: np.ndarray,
             x: np.ndarray, x_in: np.ndarray, g: np.ndarray, best_r: np.ndarray, dX: np.ndarray, dF: np.ndarray,
             previous_x: np.ndarray, previous_f: np.ndarray, f: np.ndarray, checks: np.ndarray, u: np.ndarray,
             y: np.ndarray, gram: np.ndarray) -> int:
    """The iterations of :func:`solve` (see there) from the state ``state``, ``reals`` and the iterate ``x``,
    until they end (:data:`_DONE`: the best iterate in ``best_r``) or need the coarse level
    (:data:`_PREPARE`: prepare it from ``g``; :data:`_CORRECT`: write the corrected ``x`` into ``x_in``);
    then call again with the same arguments. ``data``: :meth:`~.delassus.Delassus.sweep_data` when
    ``factored``, else the BSR arrays of ``W`` (entries flat), three empty arrays and its diagonal blocks.
    ``y`` holds the bodies' impulse velocities of ``g`` (factored ``W``); the other arrays are work space.
    (A factored ``W``'s ``data`` is :func:`sweep_arrays`; a BSR ``W``'s ends with the four empty ones of 2D.)"""
    h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced = data
    m = q_blocks.shape[0]
    q = q_blocks.reshape(m * dim)
    n = x.size
    measure_work = np.empty(proximal.MEASURE_VECTORS * n)  # the merit checks' work
    while True:
        if state[_STAGE] == _NEXT:
            if state[_SWEEPS] >= max_sweeps:
                state[_BEST_SWEEPS] = max_sweeps
                return _DONE
            state[_STAGE] = _SWEEP
            if state[_COARSE]:
                return _CORRECT
            for i in range(n):
                x_in[i] = x[i]
        prepared = False
        if state[_STAGE] == _SWEEP:
            k, every = state[_SWEEPS], state[_CHECK_EVERY]
            count = min(every - k % every, max_sweeps - k) if state[_PLAIN] else 1
            state[_SWEEPS] = k + count
            state[_STAGE] = _NEXT
            if factored:
                _body_sweeps(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced,
                             q_blocks, mu, x_in, g, y, count)
            else:
                for i in range(n):
                    g[i] = x_in[i]
                entries = h_dat.reshape((h_ind.size, dim, dim))
                for _ in range(count):
                    _symmetric_sweep(h_ptr, h_ind, entries, blocks, q_blocks, mu, g.reshape((m, dim)))
            if state[_SWEEPS] == 1 and max_sweeps > 1 and with_coarse:
                state[_STAGE] = _PREPARED
                return _PREPARE
        else:  # _PREPARED: the caller has said whether the coarse level is on
            state[_STAGE] = _NEXT
            prepared = state[_COARSE] == 1
        k = state[_SWEEPS]
        if prepared:
            _velocity(factored, h_ptr, h_ind, h_dat, y, q, g, dim, u)
            value, relative, accepted = proximal._measure(g, u, q, d, sigma, mu, dim, exact, q_norm, tol,
                                                          tol_relative, measure_work)
            reals[_FIRST_MERIT] = value
            _keep_best(g, value, relative, accepted, k, best_r, state, reals)
            if accepted:
                return _DONE
            state[_CHECK_EVERY] = min(state[_CHECK_EVERY], _COARSE_CHECK_EVERY)
            for i in range(n):  # the Anderson history starts with the corrected map
                x[i] = g[i]
            continue
        plain = state[_PLAIN] == 1
        if k % state[_CHECK_EVERY] == 0 or k == max_sweeps:
            _velocity(factored, h_ptr, h_ind, h_dat, y, q, g, dim, u)
            value, relative, accepted = proximal._measure(g, u, q, d, sigma, mu, dim, exact, q_norm, tol,
                                                          tol_relative, measure_work)
            if accepted or value < reals[_BEST_MERIT]:
                _keep_best(g, value, relative, accepted, k, best_r, state, reals)
            if accepted:
                return _DONE
            c = state[_CHECKS]
            checks[c] = reals[_BEST_MERIT]
            c += 1
            state[_CHECKS] = c
            # The correction targets u = 0 on every loaded row; where the data of redundant
            # contacts disagree (gap terms of a hyperstatic wall, ~tol), or where contacts slide
            # and open, that target is out of reach and the two levels pull apart: one level on.
            spoiled = state[_COARSE] == 1 and value > _COARSE_SPOIL * reals[_FIRST_MERIT]
            if spoiled:
                state[_SPOILED] = 1
            coarse_off = spoiled or (state[_COARSE] == 1 and c > _COARSE_STALL_CHECKS
                                     and checks[c - 1] > _STALL_PROGRESS * checks[c - 1 - _COARSE_STALL_CHECKS])
            window = _PLAIN_STALL_CHECKS if plain else _STALL_CHECKS
            stalled = not coarse_off and c > window and checks[c - 1] > _STALL_PROGRESS * checks[c - 1 - window]
            if stalled and (plain or reals[_BEST_MERIT] <= plain_above):
                # plain sweeps stagnated too, or the mixing stalled close enough to a solution
                # for the caller's Newton polish (quadratic there; plain sweeps are not)
                state[_BEST_SWEEPS] = k
                return _DONE
            if coarse_off or stalled:
                # Anderson's mixing stalled: where many contacts sit at the friction limit (a
                # wall shaken above mu g) the plain symmetric sweeps still make slow, steady
                # progress that the mixing loses: finish with them.
                if stalled:
                    state[_PLAIN] = 1
                state[_COARSE] = 0
                state[_CHECK_EVERY] = plain_check_every
                state[_PREVIOUS] = 0
                state[_CHECKS] = 0
                state[_PUSHES] = 0
                for i in range(n):
                    x[i] = best_r[i]
                continue
            if plain and _FOCUS_PASSES and factored and k < max_sweeps:
                _focus(data, q_blocks, mu, g, u, y, dim)
        if plain:
            for i in range(n):
                x[i] = g[i]
            continue
        norm2 = 0.0
        for i in range(n):
            f[i] = g[i] - x[i]
            norm2 += f[i] * f[i]
        norm_f = np.sqrt(norm2)
        if norm_f > _GROWTH * reals[_BEST_NORM]:
            state[_RESTARTS] += 1
            state[_PUSHES] = 0
            state[_PREVIOUS] = 0
            for i in range(n):
                x[i] = g[i]
            continue
        reals[_BEST_NORM] = min(reals[_BEST_NORM], norm_f)
        if state[_PREVIOUS]:
            row = state[_PUSHES] % _DEPTH
            for i in range(n):
                dX[row, i] = x[i] - previous_x[i]
                dF[row, i] = f[i] - previous_f[i]
            state[_PUSHES] += 1
            _gram_row(dF, row, min(state[_PUSHES], _DEPTH), gram)
        for i in range(n):
            previous_x[i] = x[i]
            previous_f[i] = f[i]
        state[_PREVIOUS] = 1
        if state[_PUSHES]:
            _anderson_mix(dX, dF, min(state[_PUSHES], _DEPTH), gram, g, f, x)
        else:
            for i in range(n):
                x[i] = g[i]


@njit
def _keep_best(g: np.ndarray, value: float, relative: float, accepted: bool, k: int, best_r: np.ndarray,
               state: np.ndarray, reals: np.ndarray) -> None:
    """Record ``g`` (merit ``value``, relative merit ``relative``, after ``k`` sweeps) as the best iterate of
    :func:`_iterate`."""
    for i in range(g.size):
        best_r[i] = g[i]
    reals[_BEST_MERIT] = value
    reals[_BEST_RELATIVE] = relative
    state[_ACCEPTED] = 1 if accepted else 0
    state[_BEST_SWEEPS] = k


@njit
def _velocity(factored: bool, ptr: np.ndarray, ind: np.ndarray, dat: np.ndarray, y: np.ndarray, q: np.ndarray,
              g: np.ndarray, dim: int, u: np.ndarray) -> None:
    """``u = W g + q``: from the bodies' impulse velocities ``y`` of ``g`` (factored ``W``: ``ptr, ind, dat``
    the CSR rows of ``H``), or by the BSR rows of ``W`` (entries flat, ``dim x dim`` blocks)."""
    if factored:
        _contact_velocities(ptr, ind, dat, y, q, u)
        return
    size = dim * dim
    for c in range(ptr.size - 1):
        for i in range(dim):
            acc = q[c * dim + i]
            for e in range(ptr[c], ptr[c + 1]):
                col = ind[e]
                for j in range(dim):
                    acc += dat[e * size + i * dim + j] * g[col * dim + j]
            u[c * dim + i] = acc


@njit
def _focus(data: tuple, q_blocks: np.ndarray, mu: np.ndarray, g: np.ndarray, u: np.ndarray, y: np.ndarray,
           dim: int) -> None:
    """``_FOCUS_PASSES`` passes on ``g`` in place (``y`` kept) over the contacts that carry ``_FOCUS_SHARE``
    of the residual ``|F(g)|^2`` (``u = W g + q``) and the contacts that share a
    body velocity with them — in 3D the contacts of the same joints (:func:`_joint_labels`) — in the order of
    the contacts. ``data``: :func:`sweep_arrays`."""
    h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced = data
    m = mu.size
    f2 = np.empty(m)
    _contact_residuals(g, u, mu, dim, f2)
    order = np.argsort(-f2)
    share = np.cumsum(f2[order])
    hot = min(int(np.searchsorted(share, _FOCUS_SHARE * share[-1])) + 1, m)
    near = np.empty(m, dtype=np.int64)
    count = 0
    if dim == 3:
        joint = _joint_labels(bodies)
        hot_joints = np.sort(joint[order[:hot]])
        for c in range(m):
            at = np.searchsorted(hot_joints, joint[c])
            if at < hot and hot_joints[at] == joint[c]:
                near[count] = c
                count += 1
    else:
        touched = np.zeros(y.size, dtype=np.bool_)
        for h in range(hot):
            c = order[h]
            for e in range(h_ptr[c * dim], h_ptr[(c + 1) * dim]):
                touched[h_ind[e]] = True
        for c in range(m):
            for e in range(h_ptr[c * dim], h_ptr[(c + 1) * dim]):
                if touched[h_ind[e]]:
                    near[count] = c
                    count += 1
                    break
    _sweep_contacts(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks, bodies, h_rows, g_rows, reduced, q_blocks,
                    mu, g.reshape((m, dim)), y, near[:count], _FOCUS_PASSES)


@njit
def _joint_labels(bodies: np.ndarray) -> np.ndarray:
    """A label per 3D contact shared by the contacts between the same bodies (the points of one joint),
    from the first velocity indices of its bodies (:meth:`~.delassus.Delassus.contact_rows`: ascending,
    -1 for none) — one body for a contact with a fixed or driven body; a contact that touches none
    gets a label of its own."""
    span = bodies.max() + 2 if bodies.size else 1
    joint = np.empty(bodies.shape[0], dtype=np.int64)
    for c in range(bodies.shape[0]):
        first, second = bodies[c, 0], bodies[c, 1]
        joint[c] = first * span + second + 1 if first >= 0 else -1 - c
    return joint
