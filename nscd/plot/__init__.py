"""Figures with matplotlib (the optional extra ``plot``: ``pip install nscd[plot]``).

Each function takes results or tables and returns a matplotlib Figure; nothing is
shown or saved unless asked (``fig.savefig(path)``). matplotlib is imported only
when a plotting function is called.
"""
