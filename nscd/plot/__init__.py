"""Figures with matplotlib (the optional extra ``plot``: ``pip install nscd[plot]``).

Each function takes results or tables and returns a matplotlib Figure; nothing is
shown or saved unless asked (``fig.savefig(path)``). matplotlib is imported only
when a plotting function is called.
"""
from nscd.plot.maps import mode_map, probability_map, scaled_map
from nscd.plot.rocking import overturning_spectrum, rocking_curves, rocking_spectrum, time_history

__all__ = ["time_history", "overturning_spectrum", "rocking_curves", "rocking_spectrum",
           "mode_map", "scaled_map", "probability_map"]
