"""Minimum one-sine pulse amplitude that overturns a 0.5 m x 1.5 m block, both models.

Pulse (Makris & Zhang Type-A): a(t) = ap sin(wp t) for 0 <= t <= 2 pi / wp, with
wp / p = 2 by default. The Housner model's threshold comes from
``nscd.analysis.overturning_spectrum`` (scan + bisection, mode labelled); the 2D
engine's threshold is bisected around it (each engine run simulates the pulse and the
free motion after it until the block has fallen or cannot fall any more).

Run:  python examples/single_block/one_sine_pulse.py [--ratio 2] [--dt 1e-3]
"""
from __future__ import annotations

import argparse
import math

from tqdm import tqdm   # the optional extra "progress"

import nscd

WIDTH, HEIGHT = 0.5, 1.5  # m


def engine_overturns(amplitude: float, omega: float, p: float, dt: float) -> bool:
    """Does the engine's block overturn under a one-sine pulse of ``amplitude`` m/s^2?"""
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1),
                   motion=nscd.motion.OneSine(amplitude=amplitude, omega=omega))
    block = scene.add_block(nscd.box(WIDTH, HEIGHT), position=(0.0, HEIGHT / 2), density=2500.0)
    scene.set_contact(friction=0.8, restitution=0.0)
    t_end = 2 * math.pi / omega + 6.0 / p  # the pulse, then long enough to fall
    return nscd.simulate(scene, t_end=t_end, dt=dt).overturned(block)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ratio", type=float, default=2.0, help="wp / p")
    parser.add_argument("--dt", type=float, default=1e-3, help="engine time step, s")
    parser.add_argument("--rtol", type=float, default=2e-3, help="relative width of the engine's final bracket")
    args = parser.parse_args()

    housner = nscd.rocking.HousnerBlock(width=WIDTH, height=HEIGHT, eta=None)
    p, alpha, g = housner.p, housner.alpha, housner.g
    omega = args.ratio * p
    unit = alpha * g  # amplitudes in units of alpha g, as in the papers
    print(f"block {WIDTH} m x {HEIGHT} m: alpha = {alpha:.4f} rad, p = {p:.4f} rad/s, eta = {housner.eta:.4f}")
    print(f"one-sine pulse, wp/p = {args.ratio:g} (wp = {omega:.3f} rad/s)")

    spectrum = nscd.analysis.overturning_spectrum(housner, pulse="one-sine", wp_over_p=[args.ratio],
                                                  amplitude_max=20.0, executor=None)
    a_housner = float(spectrum.minimum[0])
    print(f"Housner 1-DOF model: minimum overturning amplitude {a_housner:.4f} alpha g "
          f"= {a_housner * unit:.4f} m/s^2 ({spectrum.minimum_mode[0]})")
    for b in spectrum.boundaries[0]:
        print(f"    boundary at {b.value:.4f} alpha g: {b.below} below, {b.above} above")

    lo, hi = 0.9 * a_housner, 1.1 * a_housner
    if engine_overturns(lo * unit, omega, p, args.dt) or not engine_overturns(hi * unit, omega, p, args.dt):
        print("engine threshold is outside +-10 % of Housner's; widen the bracket")
        return
    runs = 2
    halvings = math.ceil(math.log2((hi - lo) / (args.rtol * lo)))   # bracket width down to rtol
    with tqdm(total=halvings, desc="engine threshold, bisection", unit="run") as bar:
        while hi - lo > args.rtol * hi:
            mid = 0.5 * (lo + hi)
            runs += 1
            if engine_overturns(mid * unit, omega, p, args.dt):
                hi = mid
            else:
                lo = mid
            bar.update(1)
    a_engine = 0.5 * (lo + hi)
    print(f"2D engine (dt = {args.dt:g} s, {runs} runs): minimum overturning amplitude "
          f"{a_engine:.4f} alpha g = {a_engine * unit:.4f} m/s^2, "
          f"{100 * (a_engine / a_housner - 1):+.2f} % from Housner")


if __name__ == "__main__":
    main()
