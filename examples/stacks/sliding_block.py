"""A block launched along a floor: exact Coulomb friction against the relaxed cone.

Exact Coulomb (the De Saxcé fixed point) stops the block after v0^2 / (2 mu g) and
keeps it on the floor; the relaxed second-order cone (one convex solve, no fixed
point) makes a sliding contact separate at speed mu |u_t| — the block takes off.

Run:  python examples/stacks/sliding_block.py [--v0 1] [--mu 0.3]
"""
from __future__ import annotations

import argparse

import numpy as np

import nscd


def run(v0: float, mu: float, coulomb: str):
    scene = nscd.Scene()
    scene.add_base(nscd.box(20.0, 0.2), position=(0.0, -0.1))
    block = scene.add_block(nscd.box(0.4, 0.2), position=(-5.0, 0.1), density=2000.0, velocity=(v0, 0.0))
    scene.set_contact(friction=mu, restitution=0.0)
    settings = nscd.Settings(solver=nscd.solver.SolverSettings(coulomb=coulomb))
    t_end = 1.5 * v0 / (mu * scene.gravity)
    return nscd.simulate(scene, t_end=t_end, dt=1e-3, settings=settings), block, scene.gravity


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--v0", type=float, default=1.0, help="launch speed, m/s")
    parser.add_argument("--mu", type=float, default=0.3, help="friction coefficient")
    args = parser.parse_args()
    for coulomb in ("exact", "relaxed"):
        result, block, g = run(args.v0, args.mu, coulomb)
        x = result.position(block)
        travelled = x[-1, 0] - x[0, 0]
        expected = args.v0 ** 2 / (2 * args.mu * g)
        lift = np.max(x[:, 1] - x[0, 1])
        print(f"{coulomb:8s}: travelled {travelled:.5f} m (theory {expected:.5f} m, "
              f"{100 * (travelled / expected - 1):+.2f} %), largest lift-off {lift:.2e} m")


if __name__ == "__main__":
    main()
