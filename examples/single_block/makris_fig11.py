"""Seed 000 (Makris & Zhang), figure 11: overturning spectra under a one-cosine pulse,
linear against nonlinear formulation (alpha = 0.25 rad, p = 2.14 rad/s, eta = 0.9),
with the time histories of figures 12-13 at wp/p = 3 (nonlinear: the paper's numbers).

Writes out/makris_fig11.png and out/makris_fig12_13.png in the working directory.

    python examples/single_block/makris_fig11.py
"""
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nscd import analysis  # noqa: E402
from nscd.motion import OneCosine  # noqa: E402
from nscd.plot.rocking import overturning_spectrum, time_history  # noqa: E402
from nscd.rocking import HousnerBlock  # noqa: E402


def main() -> None:
    out = Path.cwd() / "out"
    out.mkdir(exist_ok=True)
    ratios = np.linspace(0.1, 10.0, 50)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.5), sharey=True, constrained_layout=True)
    for ax, linear in zip(axes, (True, False)):
        block = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9, linear=linear)
        start = time.perf_counter()
        name = "linear" if linear else "nonlinear"
        spec = analysis.overturning_spectrum(block, "one-cosine", ratios, amplitude_max=16.0, n_scan=81,
                                             progress=True)
        print(f"{name}: {len(ratios)} values of wp/p in {time.perf_counter() - start:.1f} s")
        overturning_spectrum(spec, ax=ax)
        ax.set_title(f"{name} formulation (seed 000 fig. 11)", fontsize=10)
    path = out / "makris_fig11.png"
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")

    block = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9)
    fig, axes = plt.subplots(3, 6, figsize=(19, 6.5), sharex=True, constrained_layout=True)
    for j, level in enumerate((1.91, 1.92, 6.54, 6.55, 11.18, 11.19)):
        pulse = OneCosine(level * block.alpha * block.g, 3.0 * block.p)
        result = block.simulate(pulse, t_end=6.0)
        outcome = f"overturns ({result.mode})" if result.overturned else "safe"
        time_history(result, pulse, axes=axes[:, j], title=rf"$a_p$ = {level} $\alpha g$: {outcome}")
        print(f"  a_p = {level:5.2f} alpha g: {'overturns, ' + str(result.mode) if result.overturned else 'safe'}")
    path = out / "makris_fig12_13.png"
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
