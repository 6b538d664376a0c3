"""Overturning maps of the double-pulse rig of Čeh et al. (seed 002), single block and stack.

Runs the rig (kinematic base) over stop gaps BD and peak base velocities for one
specimen at scales 1 and 2, draws each map as in 002's Figures 10-19, and the
scaled overlay of both scales as in Figures 14 and 21.

    python examples/stacks/double_pulse_map.py --specimen stack3 --n 8

The CSV files are resumable: interrupt and rerun to continue. A 20 x 20 map is
the command ``nscd map --specimen stack3 --gap 0.005:0.05:20 --v-peak 0.1:1.5:20 -o map.csv``.
"""
from __future__ import annotations

import argparse

import numpy as np

from nscd.plot import maps
from nscd.rigs import DoublePulseRig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--specimen", choices=["single", "stack3"], default="stack3")
    parser.add_argument("--n", type=int, default=8, help="cells per axis")
    parser.add_argument("--out", default="double_pulse", help="prefix of the output files")
    args = parser.parse_args()

    gaps = np.linspace(0.006, 0.05, args.n)  # > v_peak * rise_time / 2 up to 2.1 m/s
    rigs, tables, written = [], [], []
    for scale in (1, 2):
        rig = DoublePulseRig(args.specimen, scale=scale)
        # the larger specimen needs larger velocities (002, Figures 11-12 and 18-19)
        v_peaks = np.linspace(0.1, 1.5, args.n) * np.sqrt(scale)
        csv = f"{args.out}_{args.specimen}_scale{scale}.csv"
        print(f"scale {scale}: {len(gaps) * len(v_peaks)} cells -> {csv}")   # names the progress bar below
        table = rig.map(gaps, v_peaks, out=csv)
        title = f"{args.specimen}, scale {scale} (kinematic base)"
        png = f"{args.out}_{args.specimen}_scale{scale}.png"
        maps.mode_map(table, title=title).savefig(png, dpi=150)
        written += [csv, png]
        rigs.append(rig)
        tables.append(table)
    fig = maps.scaled_map(tables, rigs, title=f"{args.specimen}: scales 1 (filled) and 2 (empty)")
    fig.savefig(f"{args.out}_{args.specimen}_scaled.png", dpi=150)
    written.append(f"{args.out}_{args.specimen}_scaled.png")
    print("wrote " + ", ".join(written))


if __name__ == "__main__":
    main()
