"""Speed of the 1-DOF rocking toolkit (nscd.rocking, nscd.analysis); prints a Markdown table.

    python benchmarks/bench_rocking.py

Cases (wall-clock, default executor = local process pool over all cores):
1. overturning spectrum, one-sine, linear, 100 values of wp/p in [0.1, 10], amplitudes up to
   16 alpha g, 61 scan points, every boundary bisected to 1e-3 relative (goal < 10 s);
2. the same with the nonlinear formulation, 20 values of wp/p (for scale);
3. rocking curves of 240 blocks (alpha 0.01..0.30 x R 1.5..5 m) under El Centro 1940 NS,
   linear model, vectorised exact flights (goal < 10 s);
4. the same 240 blocks in one process (wall and CPU time of the vectorised integrator);
5. one nonlinear block under El Centro (solve_ivp, rtol 1e-10), per block.

On a shared machine the load average is printed with the table: wall times scale with it.
"""
import os
import platform
import time
from pathlib import Path

import numpy as np

from nscd import analysis
from nscd.motion import Record
from nscd.rocking import HousnerBlock, linear_record_peaks


def timed(func):
    start = time.perf_counter()
    value = func()
    return time.perf_counter() - start, value


def main() -> None:
    rows = []
    ratios = np.linspace(0.1, 10.0, 100)
    lin = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9, linear=True)
    seconds, spec = timed(lambda: analysis.overturning_spectrum(lin, "one-sine", ratios, 16.0, rtol=1e-3))
    n_b = sum(len(c) for c in spec.boundaries)
    rows.append(("overturning spectrum, linear, 100 wp/p, rtol 1e-3", seconds, f"{n_b} boundaries", "< 10 s"))
    non = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9)
    seconds, spec = timed(lambda: analysis.overturning_spectrum(non, "one-sine", np.linspace(0.5, 10, 20), 16.0))
    rows.append(("overturning spectrum, nonlinear, 20 wp/p, rtol 1e-3", seconds,
                 f"{sum(len(c) for c in spec.boundaries)} boundaries", "-"))
    record = Record.from_at2(Path(analysis.__file__).parent / "data" / "elcentro_1940_ns.AT2")
    seconds, curves = timed(lambda: analysis.rocking_curves(record, linear=True))
    rows.append(("rocking curves, 240 blocks, El Centro, linear", seconds,
                 f"{int(curves.overturned.sum())} overturned", "< 10 s"))
    alphas, Rs = np.tile(curves.alpha, curves.R.size), np.repeat(curves.R, curves.alpha.size)
    blocks = [HousnerBlock.from_alpha_R(a, r) for a, r in zip(alphas, Rs)]
    cpu0 = time.process_time()
    seconds, _ = timed(lambda: linear_record_peaks([b.alpha for b in blocks], [b.p for b in blocks],
                                                   [b.eta for b in blocks], record, record.duration + 5.0))
    rows.append(("same 240 blocks in one process (linear_record_peaks)", seconds,
                 f"CPU {time.process_time() - cpu0:.2f} s", "-"))
    block = HousnerBlock.from_alpha_R(0.15, 3.0)
    seconds, r = timed(lambda: block.simulate(record, t_end=record.duration + 5.0))
    rows.append(("one nonlinear block under El Centro (59 s)", seconds, f"{len(r.impacts)} impacts", "-"))
    print(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}\n")
    print("| case | wall time (s) | result | goal |")
    print("| --- | ---: | --- | --- |")
    for name, seconds, result, goal in rows:
        print(f"| {name} | {seconds:.2f} | {result} | {goal} |")


if __name__ == "__main__":
    main()
