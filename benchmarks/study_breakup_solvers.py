"""Contact solvers on the steps of a breaking-up wall: which method reaches which accuracy, at what cost.

The contact problems are those of the README's running-bond wall (13 courses x 7 blocks,
97 bodies, 0.4 x 0.2 m, friction 0.7) on a base shaken at 8 m/s^2 (above mu g = 6.87
m/s^2), 2 Hz, one-cycle ramp, dt = 1 ms: the simulation is run with the shipped
solver up to ``--t-end`` and the velocity-form problem of every ``--every``-th step
from ``--t-start`` on is captured (mass diagonal, free velocity, Jacobian, offset,
friction, warm start). Each captured problem is then solved, from the stepper's warm
start, by:

- ``shipped``: :func:`nscd.solver.core.solve` as the stepper calls it (two-level NSGS,
  plain sweeps once the mixing stalls, Newton polish, the interior-point fixed point,
  with its own stopping rules), with the default tolerance and with ``tol_relative = 1e-4``;
- ``NSGS``: the nonsmooth Gauss–Seidel of :mod:`nscd.solver.nsgs` alone
  (symmetric sweeps, no acceleration), ``--sweeps`` sweeps;
- ``NSGS + Anderson``: :func:`nscd.solver.nsgs.solve` without the coarse level,
  ``--sweeps`` sweeps at most (its own stagnation stop);
- ``NSGS + coarse``: the same with the body-space coarse correction (:mod:`nscd.solver.coarse`);
- ``APGD``: Nesterov-accelerated projected gradient with adaptive restart
  (Mazhar, Heyn, Negrut, Tasora 2015, the Chrono solver), the De Saxcé shift
  ``mu ||u_T||`` refreshed every iteration, step ``1 / L`` (``L`` by power iteration);
- ``ADMM``: alternating directions on the velocity form with the factor of
  ``M + H^T R H`` kept over the iterations (``R = 3 / W_NN`` per contact, over-relaxation
  1.6), the De Saxcé shift refreshed every iteration;
- ``interior point``: the Clarabel fixed point on the De Saxcé shift + Newton polish
  (:func:`nscd.solver.core.solve` with the large-problem path off);
- ``relaxed (convex)``: the same on the convex relaxation (``coulomb="relaxed"``),
  *not* exact Coulomb: the diagnosis of what makes the exact problem hard.

Accuracy is measured two ways: the FCLIB merit (absolute; the shipped target is 1e-8)
and the merit relative to the problem's own scale that ``SolverSettings.tol_relative``
tests (:meth:`nscd.solver.core._Scaled.relative`: the De Saxcé residual in the energy
norm of ``W`` over the larger of the impulses' and the free velocities' norms). The share of loaded contacts at the friction limit (``|r_T| >= 0.95 mu r_N``)
in the best answer is reported too.

Writes ``benchmarks/results/breakup_solvers.md`` and ``breakup_solvers.csv``.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_breakup_solvers.py [--quick]``
"""
from __future__ import annotations

import argparse
import dataclasses
import time
import warnings
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import nscd
import nscd.stepper
from nscd.motion import Harmonic
from nscd.solver import SolverSettings, cone, core, nsgs
from nscd.solver.coarse import CoarseCorrection
from nscd.solver.delassus import Delassus

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.study_breakup_solvers
    from common import log, markdown_table, stamp_lines, write_csv, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import log, markdown_table, stamp_lines, write_csv, write_text

WALL = dict(n_courses=13, n_per_course=7, block_width=0.4, block_height=0.2, friction=0.7)
BASE = dict(amplitude=8.0, frequency=2.0, ramp_cycles=1.0)   # m/s^2, Hz, cycles
DT = 1e-3
TARGET = 1e-8           # the shipped absolute FCLIB merit
RELATIVE_LEVELS = (1e-4, 1e-5, 1e-6)
LIMIT_SHARE = 0.95      # |r_T| >= this * mu r_N counts as "at the friction limit"


@dataclasses.dataclass
class Problem:
    """A captured velocity-form problem and its condensed reaction form."""

    t: float
    mass: np.ndarray
    v_free: np.ndarray
    H: sp.csr_matrix
    offset: np.ndarray
    mu: np.ndarray
    warm: np.ndarray

    @property
    def W(self) -> Delassus:
        return Delassus(self.H, (sp.diags(1.0 / self.mass) @ self.H.T).tocsr(), 2)

    @property
    def q(self) -> np.ndarray:
        return self.H @ self.v_free + self.offset


def capture(t_start: float, t_end: float, every: int) -> list[Problem]:
    """Simulate the wall with the shipped solver and capture every ``every``-th problem from ``t_start``."""
    scene, _ = nscd.wall(**WALL, motion=Harmonic(BASE["amplitude"], frequency=BASE["frequency"],
                                                 ramp_cycles=BASE["ramp_cycles"]))
    sim = nscd.Simulator(scene, dt=DT)
    captured: list[Problem] = []
    original = nscd.stepper.solve_velocity_unchecked
    step_index = [0]

    def recording(mass, v_free, H, offset, mu, dim, settings, warm_start=None, coarse=None):
        if sim.state.t >= t_start - 1e-12 and step_index[0] % every == 0 and mass.ndim == 1 and mu.size * dim > 120:
            captured.append(Problem(sim.state.t, mass.copy(), v_free.copy(), sp.csr_matrix(H, copy=True),
                                    offset.copy(), mu.copy(),
                                    np.zeros(mu.size * dim) if warm_start is None else warm_start.ravel().copy()))
        return original(mass, v_free, H, offset, mu, dim, settings, warm_start, coarse)

    nscd.stepper.solve_velocity_unchecked = recording
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            while sim.state.t < t_end - 1e-12:
                step_index[0] += 1
                sim.step()
                if step_index[0] % 50 == 0:
                    log(f"  captured {len(captured)} problems, t = {sim.state.t:.3f} s")
    finally:
        nscd.stepper.solve_velocity_unchecked = original
    return captured


@dataclasses.dataclass
class Outcome:
    merit: float        # FCLIB merit of the best iterate
    relative: float     # relative merit of the best iterate
    seconds: float
    limit_share: float  # loaded contacts at the friction limit


def _relative_merit(p: Problem, r: np.ndarray, exact: bool) -> float:
    """The solver's relative merit (:meth:`nscd.solver.core._Scaled.relative`) of the impulses ``r``."""
    P = _scaled(p, SolverSettings(coulomb="exact" if exact else "relaxed"))
    r_s = r / (P.sigma * P.d)
    return P.relative(r_s, P.W @ r_s + P.q)


def _outcome(p: Problem, r: np.ndarray, seconds: float, exact: bool = True) -> Outcome:
    """Accuracy of ``r`` (``exact=False``: merit of the relaxed problem) and its share at the friction limit."""
    W, q = p.W, p.q
    R, U = r.reshape(-1, 2), (W @ r + q).reshape(-1, 2)
    merit = cone.merit(R, U, p.mu, float(np.linalg.norm(q)), exact)
    loaded = R[:, 0] > 0.0
    share = float(np.mean(np.abs(R[loaded, 1]) >= LIMIT_SHARE * p.mu[loaded] * R[loaded, 0])) if loaded.any() else 0.0
    return Outcome(merit, _relative_merit(p, r, exact), seconds, share)


def _scaled(p: Problem, settings: SolverSettings | None = None) -> core._Scaled:
    return core._Scaled(p.W, p.q, p.mu, 2, settings or SolverSettings())


def _best_of(P: core._Scaled, iterate: Callable[[np.ndarray], np.ndarray], x: np.ndarray, iterations: int,
             check: int) -> np.ndarray:
    """Run ``x = iterate(x)`` ``iterations`` times; the iterate of smallest merit (checked every ``check``)."""
    best, best_merit = x.copy(), P.stop(x, P.W @ x + P.q)[0]
    for k in range(1, iterations + 1):
        x = iterate(x)
        if k % check == 0:
            value = P.stop(x, P.W @ x + P.q)[0]
            if value < best_merit:
                best, best_merit = x.copy(), value
            if P.stop(x, P.W @ x + P.q)[1]:
                break
    return best


def run_shipped(p: Problem, sweeps: int) -> np.ndarray:
    return core.solve(p.W, p.q, p.mu, 2, SolverSettings(), p.warm, (CoarseCorrection(), p.mass)).r


def run_shipped_relative(p: Problem, sweeps: int) -> np.ndarray:
    return core.solve(p.W, p.q, p.mu, 2, SolverSettings(tol_relative=1e-4), p.warm, (CoarseCorrection(), p.mass)).r


def run_interior_point(p: Problem, sweeps: int) -> np.ndarray:
    return core.solve(p.W.tocsr(), p.q, p.mu, 2, SolverSettings(large_problem_unknowns=10**9), p.warm).r


def run_relaxed(p: Problem, sweeps: int) -> np.ndarray:
    return core.solve(p.W.tocsr(), p.q, p.mu, 2, SolverSettings(coulomb="relaxed", large_problem_unknowns=10**9),
                      p.warm).r


def run_nsgs_plain(p: Problem, sweeps: int) -> np.ndarray:
    P = _scaled(p)
    arrays = nsgs.sweep_arrays(P.W)
    shape = (p.mu.size, 2)
    q_blocks = P.q.reshape(shape)

    def sweep(x: np.ndarray) -> np.ndarray:
        nsgs._symmetric_sweep_body(*arrays, q_blocks, P.mu, x.reshape(shape), P.W.MinvHT @ x)
        return x

    return P.sigma * P.d * _best_of(P, sweep, p.warm / (P.sigma * P.d), sweeps, 10)


def _run_nsgs(p: Problem, sweeps: int, coarse: bool) -> np.ndarray:
    P = _scaled(p)
    res = nsgs.solve(P.W, P.q, P.mu, 2, p.warm / (P.sigma * P.d), sweeps, 5,
                     nsgs.StopTest(P.d, P.sigma, P.q_norm, P.exact, P.tol, 0.0),
                     (CoarseCorrection(), p.mass) if coarse else None)
    return P.sigma * P.d * res.r


def run_nsgs_anderson(p: Problem, sweeps: int) -> np.ndarray:
    return _run_nsgs(p, sweeps, False)


def run_nsgs_coarse(p: Problem, sweeps: int) -> np.ndarray:
    return _run_nsgs(p, sweeps, True)


def run_apgd(p: Problem, sweeps: int) -> np.ndarray:
    """Chrono's APGD (Mazhar et al. 2015, Algorithm 1 without the step backtracking), De Saxcé shift per iteration."""
    P = _scaled(p)
    m = p.mu.size
    x = np.random.default_rng(0).standard_normal(P.q.size)
    lipschitz = 1.0
    for _ in range(50):
        x = P.W @ x
        lipschitz = float(np.linalg.norm(x))
        x /= lipschitz
    step = 1.0 / lipschitz
    state = {"gamma": p.warm / (P.sigma * P.d), "theta": 1.0}
    state["y"] = state["gamma"].copy()

    def iterate(_: np.ndarray) -> np.ndarray:
        y, gamma, theta = state["y"], state["gamma"], state["theta"]
        u = P.W @ y + P.q
        grad = u.copy()
        grad[::2] += P.mu * np.abs(u[1::2])
        new = cone.project((y - step * grad).reshape(m, 2), P.mu).ravel()
        theta_new = 0.5 * (-theta**2 + theta * np.sqrt(theta**2 + 4.0))
        beta = theta * (1.0 - theta) / (theta**2 + theta_new)
        y_new = new + beta * (new - gamma)
        if grad @ (new - gamma) > 0.0:  # adaptive restart (O'Donoghue & Candès)
            y_new, theta_new = new.copy(), 1.0
        state.update(gamma=new, y=y_new, theta=theta_new)
        return new

    return P.sigma * P.d * _best_of(P, iterate, state["gamma"], sweeps, 10)


def _project_dual(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Projection onto the dual cone ``{u : u_N >= mu |u_T|}`` per contact (2D rows [N, T])."""
    n, t = x[:, 0], np.abs(x[:, 1])
    a = 1.0 / np.maximum(mu, 1e-300)   # |u_T| <= a u_N
    out = x.copy()
    polar = a * t <= -n
    middle = ~(t <= a * n) & ~polar
    alpha = (n + a * t) / (1.0 + a * a)
    out[polar] = 0.0
    out[middle, 0] = alpha[middle]
    out[middle, 1] = np.sign(x[middle, 1]) * a[middle] * alpha[middle]
    return out


def run_admm(p: Problem, sweeps: int) -> np.ndarray:
    """ADMM on ``min 1/2 |v - v_free|_M^2`` s.t. ``H v + offset + s e_N`` in the dual cone; factor kept."""
    W = p.W
    m = p.mu.size
    rho = np.repeat(3.0 / W.blocks()[:, 0, 0], 2)
    factor = spla.splu((sp.diags(p.mass) + p.H.T @ sp.diags(rho) @ p.H).tocsc())
    P = _scaled(p)
    f = p.mass * p.v_free
    state = {"y": -p.warm / rho, "z": None}
    v = p.v_free + (p.H.T @ p.warm) / p.mass
    state["u"] = p.H @ v + p.offset
    state["z"] = state["u"].copy()

    def iterate(_: np.ndarray) -> np.ndarray:
        y, z, u = state["y"], state["z"], state["u"]
        shift = np.zeros_like(u)
        shift[::2] = p.mu * np.abs(u[1::2])
        b = p.offset + shift
        v = factor.solve(f + p.H.T @ (rho * (z - y - b)))
        w = 1.6 * (p.H @ v + b) + (1.0 - 1.6) * z
        z = _project_dual((w + y).reshape(m, 2), p.mu).ravel()
        y = y + w - z
        state.update(y=y, z=z, u=p.H @ v + p.offset)
        return -rho * y / (P.sigma * P.d)

    return P.sigma * P.d * _best_of(P, iterate, p.warm / (P.sigma * P.d), sweeps, 10)


METHODS = {
    "shipped (2-level NSGS, polish, interior point)": run_shipped,
    "shipped, tol_relative = 1e-4": run_shipped_relative,
    "NSGS": run_nsgs_plain,
    "NSGS + Anderson": run_nsgs_anderson,
    "NSGS + Anderson + coarse": run_nsgs_coarse,
    "APGD (Chrono)": run_apgd,
    "ADMM, factor kept": run_admm,
    "interior-point fixed point + polish": run_interior_point,
    "relaxed (convex) interior point": run_relaxed,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-start", type=float, default=0.30, help="first captured step, s")
    parser.add_argument("--t-end", type=float, default=0.45, help="end of the simulation, s")
    parser.add_argument("--every", type=int, default=5, help="capture every this many steps")
    parser.add_argument("--sweeps", type=int, default=2000, help="iterations of the first-order methods")
    parser.add_argument("--quick", action="store_true",
                        help="every 10th step of 0.38-0.40 s (a few problems: a step may call the solver more than "
                             "once), 300 iterations")
    args = parser.parse_args()
    if args.quick:
        args.t_start, args.t_end, args.every, args.sweeps = 0.38, 0.40, 10, 300
    log(f"simulating the wall to t = {args.t_end} s, capturing from {args.t_start} s")
    problems = capture(args.t_start, args.t_end, args.every)
    log(f"{len(problems)} problems captured")
    for p in problems[:1]:  # compile the kernels outside the timings
        for run in METHODS.values():
            run(p, 20)
    results: dict[str, list[Outcome]] = {name: [] for name in METHODS}
    csv_rows = []
    for p in problems:
        for name, run in METHODS.items():
            start = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = run(p, args.sweeps)
            outcome = _outcome(p, r, time.process_time() - start, exact=run is not run_relaxed)
            results[name].append(outcome)
            csv_rows.append((f"{p.t:.3f}", p.mu.size, name, f"{outcome.merit:.3e}", f"{outcome.relative:.3e}",
                             f"{outcome.seconds:.4f}", f"{outcome.limit_share:.3f}"))
        log(f"  t = {p.t:.3f} s: " + ", ".join(f"{n.split(' ')[0]} {results[n][-1].merit:.0e}" for n in METHODS))
    write_csv("breakup_solvers.csv", ("t", "contacts", "method", "fclib_merit", "relative_merit", "cpu_s",
                                      "limit_share"), csv_rows)
    rows = []
    for name, outs in results.items():
        merit = np.array([o.merit for o in outs])
        rel = np.array([o.relative for o in outs])
        sec = np.array([o.seconds for o in outs])
        rows.append((name, f"{(merit <= TARGET).sum()} / {merit.size}",
                     *(f"{(rel <= level).sum()} / {rel.size}" for level in RELATIVE_LEVELS),
                     f"{np.median(merit):.1e}", f"{merit.max():.1e}", f"{np.median(rel):.1e}",
                     f"{1e3 * np.median(sec):.0f}", f"{1e3 * sec.max():.0f}"))
    share = np.array([o.limit_share for o in results["relaxed (convex) interior point"]])
    share_exact = np.array([min(outs, key=lambda o: o.merit).limit_share
                            for outs in zip(*results.values())])
    lines = ["# Contact solvers on the steps of a breaking-up wall", "", *stamp_lines(), "",
             f"Wall: 13 x 7 running bond (97 blocks), friction 0.7, base {BASE['amplitude']} m/s^2 at "
             f"{BASE['frequency']} Hz (one-cycle ramp), dt = {DT * 1e3:g} ms. {len(problems)} velocity-form problems "
             f"captured every {args.every} steps from t = {args.t_start} s to {args.t_end} s "
             f"({min(p.mu.size for p in problems)}-{max(p.mu.size for p in problems)} contacts), each solved from "
             f"the stepper's warm start; first-order methods get {args.sweeps} iterations (sweeps) at most. "
             "CPU time per problem, one core.", "",
             *markdown_table(("method", f"FCLIB merit <= {TARGET:g}",
                              *(f"relative merit <= {level:g}" for level in RELATIVE_LEVELS),
                              "median merit", "worst merit", "median relative", "median ms", "worst ms"), rows),
             "",
             f"Loaded contacts at the friction limit (|r_T| >= {LIMIT_SHARE} mu r_N): median "
             f"{np.median(share_exact):.0%} in the best exact answer per problem, {np.median(share):.0%} in the "
             "relaxed (convex) one. The relaxed row's merits are those of the relaxed problem (it is not exact "
             "Coulomb: a sliding contact separates at mu |u_T|).", "",
             "Run: `OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_breakup_solvers.py"
             + (" --quick" if args.quick else f" --t-start {args.t_start:g} --t-end {args.t_end:g} "
                f"--every {args.every} --sweeps {args.sweeps}")
             + "` (see `docs/solver.md` for the reading)."]
    path = write_text("breakup_solvers.md", lines)
    log(f"wrote {path}")


if __name__ == "__main__":
    main()
