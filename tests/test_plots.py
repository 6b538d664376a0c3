"""Figures: one encoding per meaning, codes explained, Greek symbols (matplotlib objects inspected)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from nscd import analysis  # noqa: E402
from nscd.plot.rocking import overturning_spectrum  # noqa: E402
from nscd.rocking import HousnerBlock  # noqa: E402


@pytest.fixture(scope="module")
def spectra():
    """The one-cosine spectra of seed 000 fig. 11 (alpha 0.25, p 2.14, eta 0.9) on a few wp/p."""
    return [analysis.overturning_spectrum(HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9, linear=linear),
                                          "one-cosine", np.linspace(0.5, 4.0, 6), amplitude_max=16.0, n_scan=41)
            for linear in (True, False)]


def test_each_boundary_kind_and_mode_has_its_own_marker_and_one_legend_order(spectra):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2)
    legends = []
    for ax, spec in zip(axes, spectra):
        overturning_spectrum(spec, ax=ax)
        legend = ax.get_legend()
        texts = [t.get_text() for t in legend.get_texts()]
        styles = [(h.get_marker(), h.get_fillstyle(), h.get_color()) for h in legend.legend_handles]
        # one meaning per encoding: no two legend entries look alike
        assert len(set(styles)) == len(styles) == len(texts)
        legends.append(dict(zip(texts, styles)))
        assert r"$\alpha$" in ax.get_title()
    # entries common to both panels are drawn alike and listed in the same order
    common = [t for t in legends[0] if t in legends[1]]
    assert common and all(legends[0][t] == legends[1][t] for t in common)
    assert common == [t for t in legends[1] if t in legends[0]]
    # "overturns (mode 2)" and "mode changes to (mode 2)" must not share a marker (seed 000 figs 8, 11)
    merged = {**legends[0], **legends[1]}
    starts = [s for t, s in merged.items() if t.startswith("overturning starts (mode 2")]
    changes = [s for t, s in merged.items() if t.startswith("mode changes to (mode 2")]
    assert starts and changes and starts[0] != changes[0]
    plt.close(fig)
