"""Seed 001 (Sorrentino et al.): rocking curves of 240 blocks (alpha = 0.01 ... 0.30 rad,
R = 1.5 ... 5 m) under the 1940 El Centro NS record, and the overturning index per R.

The linearised model is used by default (exact, vectorised: seconds); ``--nonlinear``
runs the paper's nonlinear model block by block (minutes).

Writes out/rocking_curves_elcentro.png in the working directory.

    python examples/single_block/rocking_curves.py [--nonlinear]
"""
import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from nscd import analysis  # noqa: E402
from nscd.motion import Record  # noqa: E402
from nscd.plot.rocking import rocking_curves  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nonlinear", action="store_true", help="nonlinear model (slow)")
    args = parser.parse_args()
    out = Path.cwd() / "out"
    out.mkdir(exist_ok=True)
    record = Record.from_at2(Path(analysis.__file__).parent / "data" / "elcentro_1940_ns.AT2")
    start = time.perf_counter()
    print(f"rocking curves of {record.name}: one run per block (alpha, R)")
    curves = analysis.rocking_curves(record, linear=not args.nonlinear, progress=True)
    model = "nonlinear" if args.nonlinear else "linear"
    print(f"{curves.theta.size} blocks under {record.name} ({model}) in {time.perf_counter() - start:.1f} s")
    for R, index in zip(curves.R, analysis.overturning_index(curves)):
        print(f"  R = {R:3.1f} m: overturning index I_over = {index:.3f}")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), constrained_layout=True)
    for ax, quantity in zip(axes.ravel(), ("theta", "theta_dot", "energy", "dissipated")):
        rocking_curves(curves, quantity, ax=ax, R_values=[1.5, 2.5, 3.5, 5.0])
    fig.suptitle(f"Rocking curves, {record.name} ({model} model; circles: overturned)")
    path = out / "rocking_curves_elcentro.png"
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
