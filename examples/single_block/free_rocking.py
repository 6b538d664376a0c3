"""Free rocking of a 0.5 m x 1.5 m block: the 2D engine against Housner's model.

The block is released from rest, tilted about its right bottom corner by
theta0 = alpha / 2, on a fixed base with friction 0.8 and Newton restitution e = 0.
The engine (rigid polygons, Moreau–Jean, exact Coulomb) knows nothing of rocking:
Housner's restitution eta = 1 - 1.5 sin^2(alpha) must come out of its impacts.
The one-degree-of-freedom Housner model (nscd.rocking) is run beside it.

Writes into ``out/`` next to where it is run:
  free_rocking.png   theta/alpha and theta_dot/p of both models
  free_rocking.npz   the engine result (nscd.load("out/free_rocking.npz"))

Run:  python examples/single_block/free_rocking.py [--dt 1e-3] [--t-end 4] [--scheme midpoint|theta]

The default scheme is Moreau's midpoint rule (``nscd.Settings().scheme``); it is as accurate
at ``--dt 1e-2`` (10 times coarser). ``--scheme theta`` shows the first-order theta scheme.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import nscd

WIDTH, HEIGHT = 0.5, 1.5  # m


def amplitudes(theta: np.ndarray) -> np.ndarray:
    """|theta| at each local maximum of |theta|."""
    a = np.abs(theta)
    return a[np.flatnonzero((a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:])) + 1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dt", type=float, default=1e-3, help="engine time step, s")
    parser.add_argument("--t-end", type=float, default=4.0, help="simulated time, s")
    parser.add_argument("--scheme", default=nscd.Settings().scheme, choices=("midpoint", "theta"),
                        help="time integrator (nscd.Settings(scheme=...)); default: the Settings default")
    parser.add_argument("--out", default="out", help="output folder")
    args = parser.parse_args()

    housner = nscd.rocking.HousnerBlock(width=WIDTH, height=HEIGHT, eta=None)
    alpha, p, eta = housner.alpha, housner.p, housner.eta
    theta0 = alpha / 2
    print(f"block {WIDTH} m x {HEIGHT} m: alpha = {alpha:.4f} rad, p = {p:.4f} rad/s, "
          f"Housner eta = 1 - 1.5 sin^2(alpha) = {eta:.4f}")
    print(f"released at theta0 = alpha/2 = {theta0:.4f} rad; engine dt = {args.dt:g} s, scheme {args.scheme}")

    scene, block = nscd.tilted_block(WIDTH, HEIGHT, theta0)
    result = nscd.simulate(scene, t_end=args.t_end, dt=args.dt, settings=nscd.Settings(scheme=args.scheme))
    model = housner.simulate(None, t_end=args.t_end, theta0=-theta0)

    theta = result.angle(block)
    amps = np.concatenate([[theta0], amplitudes(theta)])
    print(f"\nengine: {result.report}")
    print("impact  t_engine (s)  t_housner (s)  eta_engine  error vs Housner")
    t_model = np.asarray(model.impacts.time)
    for k in range(min(5, len(amps) - 1, len(t_model))):
        ratio = math.sqrt((math.cos(alpha - amps[k + 1]) - math.cos(alpha))
                          / (math.cos(alpha - amps[k]) - math.cos(alpha)))
        t_engine = result.impacts["time"][k] if k < len(result.impacts["time"]) else float("nan")
        print(f"{k + 1:6d}  {t_engine:12.4f}  {t_model[k]:13.4f}  {ratio:10.4f}  {100 * (ratio / eta - 1):+8.2f} %")

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = result.save(out / "free_rocking.npz")
    print(f"\nengine result saved to {path} (reload with nscd.load)")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed (pip install 'nscd[plot]'): no figure written")
        return
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    axes[0].plot(result.time, theta / alpha, label=f"2D engine, dt = {args.dt:g} s")
    axes[0].plot(model.time, model.theta / alpha, "--", label="Housner 1-DOF model")
    axes[0].set_ylabel(r"$\theta / \alpha$")
    axes[0].legend()
    axes[1].plot(result.time, result.omega(block) / p)
    axes[1].plot(model.time, model.theta_dot / p, "--")
    axes[1].set_ylabel(r"$\dot\theta / p$")
    axes[1].set_xlabel("t (s)")
    fig.suptitle(r"Free rocking, 0.5 m $\times$ 1.5 m block, restitution $e$ = 0, friction $\mu$ = 0.8")
    fig.tight_layout()
    fig.savefig(out / "free_rocking.png", dpi=120)
    print(f"figure written to {out / 'free_rocking.png'}")


if __name__ == "__main__":
    main()
