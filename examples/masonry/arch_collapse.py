"""Horizontal collapse load factor of a semicircular voussoir arch on a tilting table.

Builds ``nscd.arch(radius, thickness, n_voussoirs)`` (centreline radius R = 1 m by default),
ramps the springers' horizontal acceleration slowly (``nscd.analysis.collapse_load_factor``)
and prints the load factor at collapse (acceleration / g) and the four hinges of the
mechanism: joint number (0 = left springing), side (intrados / extrados) and polar angle.
Writes the run to ``out/arch_collapse.npz`` (``nscd.load``) and, with matplotlib, a
drawing of the arch at detection with the hinges marked to ``out/arch_collapse.png``.

    python examples/masonry/arch_collapse.py --thickness 0.15 --voussoirs 16
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import nscd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--radius", type=float, default=1.0, help="centreline radius R, m")
    parser.add_argument("--thickness", type=float, default=0.15, help="ring thickness t, m")
    parser.add_argument("--voussoirs", type=int, default=16)
    parser.add_argument("--friction", type=float, default=0.8)
    parser.add_argument("--start", type=float, default=0.1, help="load factor at t = 0 (skip the range it stands)")
    parser.add_argument("--out", default="out", help="output directory")
    args = parser.parse_args()

    scene, voussoirs = nscd.arch(args.radius, args.thickness, args.voussoirs, friction=args.friction)
    collapse = nscd.analysis.collapse_load_factor(scene, start=args.start)
    print(f"semicircular arch, t/R = {args.thickness / args.radius:.4f}, {args.voussoirs} voussoirs, "
          f"friction {args.friction}")
    print(f"ramp {collapse.rate:.4g} 1/s (quasi-static bound {nscd.limit.QUASI_STATIC_RISE} per "
          f"T = {collapse.characteristic_time:.3f} s), solver: {collapse.result.report}")
    if not collapse.collapsed:
        print("no collapse up to the largest load factor")
        return
    print(f"collapse load factor lambda = {collapse.load_factor:.4f} (onset at t = {collapse.onset_time:.3f} s)")
    step = math.pi / args.voussoirs
    for joint in collapse.joints:
        for pivot in joint.points:
            polar = math.acos(pivot[0] / np.linalg.norm(pivot))
            side = "extrados" if np.linalg.norm(pivot) > args.radius else "intrados"
            print(f"  {joint.kind} at joint {round((math.pi - polar) / step):2d} ({side}), "
                  f"{math.degrees(polar):6.1f} deg")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    saved = collapse.result.save(out / "arch_collapse.npz")
    print(f"wrote {saved}")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no figure (pip install -e '.[plot]')")
        return
    result, last = collapse.result, -1
    shift = collapse.result.q[last, 0, 0] - scene.bodies[0].q0[0]   # springers' displacement
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for body in scene.bodies:
        q = result.q[last, body.index]
        corners = body.shape.world_vertices((q[0] - shift, q[1]), q[2])
        ax.fill(*np.vstack([corners, corners[:1]]).T, fc="0.8" if body.is_dynamic else "0.5", ec="k", lw=0.6)
    pivots = np.vstack([j.points for j in collapse.hinges if len(j.points)])
    ax.plot(pivots[:, 0], pivots[:, 1], "ro", ms=6, label="hinges")
    ax.set_aspect("equal")
    ax.set_title(f"t/R = {args.thickness / args.radius:.3f}: lambda = {collapse.load_factor:.3f} "
                 "(supports accelerating to +x)")
    ax.legend(loc="lower center")
    fig.savefig(out / "arch_collapse.png", dpi=130, bbox_inches="tight")
    print(f"wrote {out / 'arch_collapse.png'}")


if __name__ == "__main__":
    main()
