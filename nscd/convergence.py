"""Time-step convergence of a result, verified rather than assumed.

A Moreau–Jean run is a numerical answer: near a threshold (the onset of rocking,
the boundary between two overturning modes) a step that is too coarse can change
the *outcome*, not only its digits. :func:`verify_time_step` reruns whatever
produced an outcome at half the time step (and, on request, with the other
integration scheme at the same step) and says, quantity by quantity, what
changed. A published comparison with an experiment should only count cells whose
check passed.

An *outcome* is a mapping of named quantities: categorical ones (``str``,
``bool``, ``int``: a mode, a class such as "rocks", overturned or not) must be
equal; real ones (``float``: a peak angle) must agree within
``atol + rtol * max(|a|, |b|)``.

Example
-------
>>> def run(dt, scheme):                                    # doctest: +SKIP
...     res = nscd.simulate(scene, 4.0, dt=dt, settings=nscd.Settings(scheme=scheme))
...     return {"overturned": res.overturned("block"),
...             "peak angle": float(np.max(np.abs(res.rotation("block"))))}
>>> check = verify_time_step(run, dt=1e-3, other_scheme=True, atol={"peak angle": 1e-3})
>>> check.converged, check.changes                        # doctest: +SKIP
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["SCHEMES", "TimeStepCheck", "compare_outcomes", "verify_time_step"]

#: The integration schemes of :class:`nscd.Settings`.
SCHEMES = ("theta", "midpoint")

Outcome = Mapping[str, Any]


def _tolerance(atol: float | Mapping[str, float], key: str) -> float:
    value = atol.get(key, 0.0) if isinstance(atol, Mapping) else atol
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"atol[{key!r}] == {value}, must be finite and >= 0.")
    return value


def compare_outcomes(reference: Outcome, other: Outcome, *, rtol: float = 0.1,
                     atol: float | Mapping[str, float] = 0.0, label: str = "") -> list[str]:
    """What differs between two outcomes of the same run.

    Parameters
    ----------
    reference, other : mapping of str to scalar
        The same keys. ``bool``, ``str`` and ``int`` values must be equal; ``float``
        values agree when ``|a - b| <= atol + rtol * max(|a|, |b|)`` (nan equals nan).
    rtol : float
        Relative tolerance of real quantities, >= 0.
    atol : float or mapping of str to float
        Absolute tolerance of real quantities in their own unit, one for all or per key
        (missing keys: 0).
    label : str
        Prefix of each message (e.g. ``"dt/2"``).

    Returns
    -------
    list of str
        One message per quantity that changed, e.g. ``"dt/2: peak angle 0.000243 -> 0.0349"``;
        empty when everything agrees.
    """
    if not (math.isfinite(rtol) and rtol >= 0.0):
        raise ValueError(f"rtol == {rtol}, must be finite and >= 0.")
    if set(reference) != set(other):
        raise ValueError(f"outcomes have keys {sorted(reference)} and {sorted(other)}, must have the same.")
    prefix = f"{label}: " if label else ""
    changes = []
    for key, a in reference.items():
        b = other[key]
        if isinstance(a, (bool, str, numbers.Integral)) or isinstance(b, (bool, str, numbers.Integral)):
            if a != b:
                changes.append(f"{prefix}{key} {a} -> {b}")
            continue
        a, b = float(a), float(b)
        if math.isnan(a) and math.isnan(b):
            continue
        if not abs(a - b) <= _tolerance(atol, key) + rtol * max(abs(a), abs(b)):
            changes.append(f"{prefix}{key} {a:.4g} -> {b:.4g}")
    return changes


@dataclass(frozen=True)
class TimeStepCheck:
    """The outcome of a run beside its reruns at dt/2 and with the other scheme.

    Attributes
    ----------
    dt : float
        Time step of the checked run, s.
    scheme : str
        Its integration scheme (one of :data:`SCHEMES`).
    outcome : dict
        The checked run's outcome (at ``dt``, ``scheme``).
    refined : dict
        The same run at ``dt / 2``.
    other_scheme : dict or None
        The same run at ``dt`` with the other scheme, when asked for.
    changes : tuple of str
        What changed (see :func:`compare_outcomes`); empty when converged.
    """

    dt: float
    scheme: str
    outcome: dict
    refined: dict
    other_scheme: dict | None
    changes: tuple[str, ...]

    @property
    def converged(self) -> bool:
        """True when no rerun changed the outcome beyond the tolerances."""
        return not self.changes

    def to_row(self) -> dict[str, Any]:
        """The outcome's fields, ``converged`` and ``changes`` (``"; "``-joined) for a sweep's CSV."""
        return {**self.outcome, "converged": self.converged, "changes": "; ".join(self.changes)}


def verify_time_step(run: Callable[[float, str], Outcome], dt: float, *, scheme: str = "midpoint",
                     other_scheme: bool = False, rtol: float = 0.1,
                     atol: float | Mapping[str, float] = 0.0) -> TimeStepCheck:
    """Run ``run(dt, scheme)``, rerun at ``dt / 2`` (and the other scheme), compare the outcomes.

    Parameters
    ----------
    run : callable ``(dt, scheme) -> mapping``
        Produces the outcome of one run for a time step (s) and a scheme name
        (``"theta"`` or ``"midpoint"``, as :class:`nscd.Settings`). It must be
        deterministic: the same arguments give the same outcome.
    dt : float
        Time step to check, s (> 0).
    scheme : {"theta", "midpoint"}
        Scheme of the checked run.
    other_scheme : bool
        Also rerun at ``dt`` with the other scheme. Useful where both schemes can
        miss the same thing at ``dt`` and ``dt / 2`` alike (a first-order scheme
        can stay wrong by the same amount over one halving).
    rtol, atol
        Tolerances of real quantities (:func:`compare_outcomes`).

    Returns
    -------
    TimeStepCheck
        ``converged`` is True when neither rerun changed the outcome.
    """
    if not (isinstance(dt, numbers.Real) and math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt == {dt!r}, must be finite and > 0.")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme == {scheme!r}, must be one of {SCHEMES}.")
    outcome = dict(run(dt, scheme))
    refined = dict(run(0.5 * dt, scheme))
    changes = compare_outcomes(outcome, refined, rtol=rtol, atol=atol, label="dt/2")
    other = None
    if other_scheme:
        name = SCHEMES[1 - SCHEMES.index(scheme)]
        other = dict(run(dt, name))
        changes += compare_outcomes(outcome, other, rtol=rtol, atol=atol, label=name)
    return TimeStepCheck(float(dt), scheme, outcome, refined, other, tuple(changes))
