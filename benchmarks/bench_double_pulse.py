"""The double-pulse rig beside the experiments of 002 (Čeh et al.): Figures 23-26 and the map regions.

    python benchmarks/bench_double_pulse.py            # about 10-20 min on a shared 2-core machine

Writes ``benchmarks/results/double_pulse.md`` (+ ``double_pulse.csv``, the map cells):

1. **Figures 23-26** of ``002_032985237284ae75.txt`` (lines 290-327): four experiments at
   scale 1 with their final mode (single block 0.59 m/s, BD 2.0 cm -> B_R; 0.56 m/s,
   3.0 cm -> B_L; stack 0.54 m/s, 2.5 cm -> C_L; 0.54 m/s, 3.0 cm -> D_L). Each is run
   with the rig as 002 simulated it (high block friction, no sliding, 002 line 106;
   kinematic base) and with the measured friction 0.54 (line 73), on the kinematic and
   the dynamic base; every run is checked at dt/2 and with the theta scheme
   (:meth:`nscd.rigs.DoublePulseRig.run_verified`), and only converged runs count as
   agreeing. Then an ensemble of perturbed runs per figure (:class:`nscd.rigs.Perturbation`:
   placement 0.5 mm, friction 5 %, v_peak 2 %, BD 0.5 mm, nscd's assumptions of the manual
   set-up, 002 line 75 and 353) gives the probability of the measured mode.
2. **Map regions** that 002 describes in words (its maps, Figs. 9-12 and 16-19, are lost in
   the text extraction): a coarse map per specimen and scale with every cell checked at
   dt/2, and each statement compared cell by cell.

The rigid model's assumptions stay visible: the stopper restitution (0.5) is not given by
002; ``mass_ratio="measured"`` (m2/m1 = 6.83, 002 line 179) changes only the energy axis of
the scaled maps with the kinematic base (a rigid block's motion under a prescribed base
does not depend on its mass), so the modes below hold for both mass ratios.
"""
from __future__ import annotations

import time
import warnings

from nscd.rigs import MEASURED_FRICTION, DoublePulseRig
from nscd.sweep import run

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_double_pulse
    from common import markdown_table, stamp_lines, write_csv, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import markdown_table, stamp_lines, write_csv, write_text

#: 002 Figs. 23-26: (figure, specimen, v_peak m/s, BD m, measured mode, what the paper says happened)
FIGURES = [
    (23, "single", 0.59, 0.020, "B_R", "rocks left, the reverse impact turns it, falls right"),
    (24, "single", 0.56, 0.030, "B_L", "rocks left, turns back at the reverse impact, falls left"),
    (25, "stack3", 0.54, 0.025, "C_L", "bottom block turned back upright, the two upper blocks fall left"),
    (26, "stack3", 0.54, 0.030, "D_L", "the reverse impact comes later, the whole stack falls left"),
]
#: rig variants run on the figures: label -> DoublePulseRig keyword arguments
CONFIGS = {
    "as 002 simulated (high friction), kinematic base": {},
    "friction 0.54 (measured), kinematic base": {"friction": MEASURED_FRICTION},
    "high friction, dynamic base": {"base": "dynamic"},
    "friction 0.54, dynamic base": {"base": "dynamic", "friction": MEASURED_FRICTION},
}
#: members of the perturbed ensemble per figure
ENSEMBLE = 12
#: the coarse map: stop gaps BD (m) and peak base velocities (m/s)
GAPS = [0.005, 0.01, 0.02, 0.03, 0.05]
V_PEAKS = [0.1, 0.2, 0.4, 0.6, 0.8, 1.2]
T_END = 1.0


def figure_cell(config: str, specimen: str, v_peak: float, gap: float) -> dict:
    """One figure's run with one rig variant, checked at dt/2 and with the theta scheme."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # unconverged steps: counted by the rig
        check = DoublePulseRig(specimen, **CONFIGS[config]).run_verified(v_peak, gap, T_END, other_scheme=True)
    return {"mode": check.outcome["mode"], "converged": check.converged, "changes": "; ".join(check.changes)}


def figure_ensemble(specimen: str, v_peak: float, gap: float) -> dict[str, float]:
    """Mode probabilities over :data:`ENSEMBLE` perturbed members of the default rig."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return DoublePulseRig(specimen).ensemble(v_peak, gap, n=ENSEMBLE, seed=23, t_end=T_END).probabilities


def _mode(cell: dict) -> str:
    return cell["mode"] if cell["converged"] else f"{cell['mode']} (unconverged: {cell['changes']})"


def figures_section() -> tuple[list[str], dict]:
    cases = [{"config": c, "specimen": s, "v_peak": v, "gap": g} for c in CONFIGS for _, s, v, g, _, _ in FIGURES]
    outs = run(figure_cell, cases, progress=False)
    cells = {(c["config"], c["specimen"], c["v_peak"], c["gap"]): o for c, o in zip(cases, outs)}
    probs = run(figure_ensemble, [{"specimen": s, "v_peak": v, "gap": g} for _, s, v, g, _, _ in FIGURES],
                progress=False)
    rows, summary = [], {}
    for config in CONFIGS:
        agree = unconverged = 0
        for fig, s, v, g, measured, _ in FIGURES:
            cell = cells[(config, s, v, g)]
            unconverged += not cell["converged"]
            agree += cell["converged"] and cell["mode"] == measured
        summary[config] = (len(FIGURES), agree, unconverged)
    for (fig, s, v, g, measured, story), p in zip(FIGURES, probs):
        modes = [_mode(cells[(c, s, v, g)]) for c in CONFIGS]
        likely = ", ".join(f"{m} {share:.0%}" for m, share in p.items() if share > 0)
        rows.append([fig, s, f"{v:g}", f"{100 * g:g}", f"{measured} ({story})", *modes,
                     f"{p[measured]:.0%} ({likely})"])
    lines = [
        "## Figures 23-26: the four experiments of 002, scale 1",
        "",
        "Mode at dt = 5e-4 s with Moreau's midpoint rule; every run rerun at dt/2 and with the theta scheme "
        "(unconverged runs are marked and not counted). Last column: share of "
        f"{ENSEMBLE} perturbed runs of the default rig ending in the measured mode (placement 0.5 mm, friction "
        "5 %, v_peak 2 %, BD 0.5 mm standard deviations: nscd's assumptions of the manual set-up).",
        "",
        *markdown_table(["Fig.", "specimen", "v_peak (m/s)", "BD (cm)", "measured", *CONFIGS,
                         "P(measured mode), ensemble"], rows),
        "",
        *[f"- {config}: {agree} of {n} figures agree, {unc} unconverged."
          for config, (n, agree, unc) in summary.items()],
        "",
        _disagreement_note(cells),
    ]
    return lines, summary


def _disagreement_note(cells: dict) -> str:
    """Which figures no rig variant matches, and what the rigid model leaves out there."""
    missed = [(fig, measured, sorted({cells[(c, s, v, g)]["mode"] for c in CONFIGS}))
              for fig, s, v, g, measured, _ in FIGURES
              if all(cells[(c, s, v, g)]["mode"] != measured for c in CONFIGS)]
    if not missed:
        return "Every figure is matched by at least one variant."
    listed = "; ".join(f"Fig. {fig}: measured {measured}, model {', '.join(modes)}" for fig, measured, modes in missed)
    return (f"Not matched by any variant: {listed}. In these experiments the reverse impact turns the rocking "
            "back (002 lines 286, 312); in the model the block, or the stack, keeps falling the way the "
            "launch threw it whatever the friction and the base model, so what decides it is the rocking phase "
            "at the reverse impact and the strength of that impact: the stopper's rubber cushion (restitution "
            "not given by 002, 0.5 assumed) and the real launch pulse (a 5 ms ramp in the model, 002 line 106). "
            "002 does not report its own simulations of these four runs; it says they \"underestimate the "
            "region of stability\" (line 155) and that some scenarios \"appeared to be quite sensitive to "
            "small changes in initial conditions\" (line 75): the ensemble column shows how likely the measured "
            "mode is under such changes.")


def _first_overturn(table, gap: float) -> float:
    """Smallest v_peak of the map column ``gap`` where something overturned (inf if none)."""
    column = table.where(gap=gap)
    fell = [v for v, m in zip(column["v_peak"], column["mode"]) if m != "A"]
    return min(fell) if fell else float("inf")


def maps_section() -> tuple[list[str], list[list], dict]:
    tables, csv_rows = {}, []
    for specimen in ("single", "stack3"):
        for scale in (1.0, 2.0):
            rig = DoublePulseRig(specimen, scale)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                table = rig.map(GAPS, V_PEAKS, t_end=T_END, progress=False, verify_dt=True)
            tables[(specimen, scale)] = table
            for row in table.rows:
                csv_rows.append([specimen, scale, row["gap"], row["v_peak"], row["status"], row.get("mode"),
                                 row.get("converged"), row.get("changes") or ""])
    lines = ["## Map regions that 002 describes", "",
             f"Coarse maps, BD {', '.join(f'{100 * g:g}' for g in GAPS)} cm x v_peak "
             f"{', '.join(f'{v:g}' for v in V_PEAKS)} m/s, the rig as 002 simulated it (high friction, "
             "kinematic base), every cell rerun at dt/2 (`map(verify_dt=True)`). Cells: mode "
             "(`*`: unconverged).", ""]
    for (specimen, scale), table in tables.items():
        grid = []
        for v in V_PEAKS:
            line = [f"{v:g}"]
            for g in GAPS:
                row = table.where(gap=g, v_peak=v).rows[0]
                line.append(f"{row['mode']}{'' if row['converged'] else '*'}")
            grid.append(line)
        lines += [f"### {specimen}, scale {scale:g}", "",
                  *markdown_table(["v_peak (m/s) \\ BD (cm)", *[f"{100 * g:g}" for g in GAPS]], grid), ""]
    statements, summary = [], {}

    def count(name: str, cells: list[tuple[bool, bool]], note: str) -> None:
        n = len(cells)
        agree = sum(ok and conv for ok, conv in cells)
        unc = sum(not conv for _, conv in cells)
        summary[name] = (n, agree, unc)
        statements.append([name, n, agree, unc, note])

    low = [(row["mode"] == "A", row["converged"]) for t in tables.values() for row in t.rows if row["v_peak"] <= 0.2]
    count("low v_peak: nothing overturns (002 line 141; v_peak <= 0.2 m/s, all four maps)", low,
          "the launch alone cannot tip a block that the reverse impulse then saves")
    small = [(row["mode"] == "A", row["converged"]) for (s, _), t in tables.items() if s == "single"
             for row in t.rows if row["gap"] == GAPS[0] and row["v_peak"] >= 0.6]
    count("small BD keeps the single block standing even at high v_peak (experiments, 002 line 141, Fig. 9; "
          f"BD {100 * GAPS[0]:g} cm, v_peak >= 0.6 m/s)", small,
          "002's own simulations overturn here (\"underestimate the region of stability ... especially with "
          "respect to the stopper gap distance\", line 155)")
    larger = []
    for specimen in ("single", "stack3"):
        for g in GAPS:
            v1, v2 = _first_overturn(tables[(specimen, 1.0)], g), _first_overturn(tables[(specimen, 2.0)], g)
            conv = all(tables[(specimen, s)].where(gap=g, v_peak=v)["converged"][0]
                       for s in (1.0, 2.0) for v in V_PEAKS)
            larger.append((v2 >= v1 and not (v1 == v2 == float("inf")), conv))
    count("scale 2 needs a higher v_peak than scale 1 (002 lines 159, 179; per BD column, lowest overturning "
          "v_peak of scale 2 >= scale 1's, both maps)", larger,
          "columns where neither scale overturns count as not comparable (disagreeing)")
    stack_small = [(row["mode"] == "A", row["converged"]) for row in tables[("stack3", 1.0)].rows
                   if row["gap"] == GAPS[0] and row["v_peak"] >= 0.6]
    count("stack, scale 1: small BD keeps the stack standing (experiments, Fig. 16, line 223; "
          f"BD {100 * GAPS[0]:g} cm, v_peak >= 0.6 m/s)", stack_small,
          "002's simulations (Fig. 17) overturn here, with different modes")
    lines += ["### Statements of 002, cell by cell", "",
              *markdown_table(["statement", "cells", "agreeing", "unconverged", "note"], statements), ""]
    return lines, csv_rows, summary


def main() -> None:
    start = time.perf_counter()
    fig_lines, fig_summary = figures_section()
    map_lines, csv_rows, map_summary = maps_section()
    seconds = time.perf_counter() - start
    write_csv("double_pulse.csv", ["specimen", "scale", "gap_m", "v_peak_m_s", "status", "mode", "converged",
                                   "changes"], csv_rows)
    n, agree, unc = fig_summary[next(iter(CONFIGS))]
    path = write_text("double_pulse.md", [
        "# The double-pulse rig beside the experiments of 002", "",
        *stamp_lines(),
        f"- generated by `python benchmarks/bench_double_pulse.py` in {seconds:.0f} s wall", "",
        f"Summary (rig as 002 simulated it): Figs. 23-26 {agree} of {n} agree, {unc} unconverged; map "
        "statements: " + "; ".join(f"{a} of {k} cells ({u} unconverged)" for k, a, u in map_summary.values()) + ".",
        "",
        *fig_lines, "", *map_lines])
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
