"""A stack of ten blocks resting on a fixed base: no creep, and each interface carries the weight above.

Run:  python examples/stacks/resting_stack.py [--t-end 10] [--dt 1e-3]
"""
from __future__ import annotations

import argparse

import numpy as np

import nscd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--t-end", type=float, default=10.0, help="simulated time, s")
    parser.add_argument("--dt", type=float, default=1e-3, help="time step, s")
    args = parser.parse_args()

    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.2), position=(0.0, -0.1))
    blocks = [scene.add_block(nscd.box(0.4, 0.3), position=(0.0, 0.15 + 0.3 * i), density=2000.0)
              for i in range(10)]
    scene.set_contact(friction=0.6, restitution=0.0)
    result = nscd.simulate(scene, t_end=args.t_end, dt=args.dt, store_impulses=True)
    print(f"{len(blocks)} blocks of {blocks[0].mass:.0f} kg (per m depth), {args.t_end:g} s at dt = {args.dt:g} s")
    print(f"solver: {result.report}")
    drift = max(np.max(np.linalg.norm(result.position(b) - result.position(b)[0], axis=1)) for b in blocks)
    print(f"largest displacement of any block: {drift:.2e} m")
    last = result.contacts[-1]
    weight = blocks[0].mass * scene.gravity
    print("interface below block   normal force (N)   weight above (N)")
    for k, b in enumerate(blocks):
        force = last["impulse"][last["body_b"] == b.index, 0].sum() / args.dt
        print(f"{k:21d}   {force:16.3f}   {(10 - k) * weight:16.3f}")


if __name__ == "__main__":
    main()
