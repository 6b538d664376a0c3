"""The event-location stage's plan of one step: its sub-steps, as compiled functions of arrays.

A step starts as a plain sub-step (the whole step) that stops at a predicted impact; its
scene then goes on under a plan: the approach in free flight up to the closing time (the
midpoint rule corrects the closing time from the state reached, up to ``APPROACHES``
approaches), the impact (a sub-step of zero length with the step's gap tolerance) and the
rest of the step, which stops at the next impact in the same way (up to ``IMPACTS`` in a
piece). A step in which a body turns fast is taken in pieces (``TURN_PER_PIECE``), each
planned as a step.

The plan is a small array per scene (``plan``, :data:`FIELDS` floats: its phase, the time
elapsed in the piece, what is left of the step, the counts of pieces, approaches and impacts,
the closing time, the lengths of the piece, of the step, of the last sub-step and of the
latest impulses' sub-step) advanced by three functions: :func:`plan_start` (a new step),
:func:`plan_request` (the next sub-step: its length, gap tolerance, pace of gap closing and
modes) and :func:`plan_receive` (its outcome: an impact located at a closing time, or the
sub-step taken). The warm start of each sub-step is the latest impulses scaled to its length
(:func:`nscd.state.scaled_impulses`, by the factor :func:`plan_request` gives); the next step's
warm start is each contact's impulse summed over the sub-steps (:func:`nscd.state.summed_impulses`).

One source for both paths: the general step (:class:`nscd.stepper._Plan`, in Python: these
functions are ``njit_helper`` functions, which run as plain Python there) and the compiled steps of a
small scene (:func:`nscd.compiled_step.plain_steps`, compiled inside it) call these same
functions, so a step's sub-steps are the same on either path, bit for bit (the arithmetic is
IEEE on both).
"""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper

#: Midpoint rule: approach sub-steps before a localised impact (the first from the free-flight
#: prediction, then corrections from the state reached until the contact is within 1 % of
#: the gap tolerance).
APPROACHES = 3

#: A step (or what is left of it) in which a body would turn by more than this angle, rad,
#: is taken in equal pieces, each stepped as a step of its own (at most ``PIECES`` in a
#: step). The end gaps of a step are linearised about its start: a body turning by ``a``
#: brings a corner at distance ``R`` closer than predicted by up to ``a^2 R / 2``; at
#: 0.04 rad that is 8e-4 R, below the overlap that warns (PENETRATION_TOLERANCE, 1e-3 R).
#: A plank spinning at 50 rad/s with dt = 1e-2 is taken in 13 pieces; a block rocking at
#: 2 rad/s is not, up to dt = 2e-2.
TURN_PER_PIECE = 0.04
PIECES = 16

#: Impacts localised one after the other within one piece of a step (a fast block hitting a
#: row of blocks: each later impact is approached, located and taken like the first); any
#: further one is taken by the plain step.
IMPACTS = 4

#: The phases of a plan: the plain sub-step of a piece, a correction of the closing time
#: (midpoint rule), the approach, the impact, the rest of the piece, and the step finished.
PLAIN, CORRECT, APPROACH, IMPACT, REST, FINISHED = 0, 1, 2, 3, 4, 5

#: The fields of a plan's array (:data:`FIELDS` floats): phase; time elapsed in the piece, s;
#: what is left of the step after the piece, s; pieces, approaches and impacts so far; the
#: closing time of the impact located, s from the start of its sub-step; the piece's length,
#: s; the step's length, s; whether the step is in pieces (0, 1); the length of the last
#: sub-step requested, s; the length of the sub-step the latest impulses were taken over, s.
(PHASE, ELAPSED, LEFT, PIECE_COUNT, APPROACH_COUNT, IMPACT_COUNT, CLOSING, PIECE, STEP, SPLIT, LENGTH,
 WARM_SPAN) = range(12)
FIELDS = 12


@njit_helper
def gap_tolerance(fixed, gravity, smallest_radius, span):
    """The gap tolerance (m) of a sub-step closing gaps over ``span`` seconds: ``fixed``
    (``Settings.gap_tolerance``; NaN: automatic), else ``min(g span^2, 1e-4 R_min)``
    (``gravity`` m/s^2, ``smallest_radius`` m)."""
    if not math.isnan(fixed):
        return fixed
    return min(gravity * span * span, 1e-4 * smallest_radius)


@njit_helper
def pace(span, midpoint, theta):
    """Time (s) over which ``v_{k+1}`` closes a gap target in a sub-step closing gaps over
    ``span`` seconds: ``span`` (midpoint rule: the next midpoint), ``theta span`` (theta scheme)."""
    return span if midpoint else theta * span


@njit_helper
def spin_squared(velocity):
    """``|omega|^2``, (rad/s)^2, of one body's velocity (nv,): ``(vx, vy, omega)`` in 2D
    (nv = 3), ``(v, omega)`` in 3D (nv = 6)."""
    first_angular = 2 if velocity.shape[0] == 3 else 3
    total = 0.0
    for j in range(first_angular, velocity.shape[0]):
        total += velocity[j] * velocity[j]
    return total


@njit
def largest_spin(v):
    """Largest ``|omega|`` (rad/s) of the bodies of each scene, (S,), from ``v`` (S, n_bodies, nv)."""
    S, n, _ = v.shape
    out = np.zeros(S)
    for s in range(S):
        for i in range(n):
            out[s] = max(out[s], spin_squared(v[s, i]))
    return np.sqrt(out)


@njit_helper
def plan_start(plan, step, spin):
    """A new step of ``step`` seconds in ``plan`` (:data:`FIELDS`,), in place; ``spin``: the
    largest ``|omega|`` of the scene's bodies at its start, rad/s (its first piece)."""
    for f in range(FIELDS):
        plan[f] = 0.0
    plan[STEP] = plan[LEFT] = plan[LENGTH] = plan[WARM_SPAN] = step
    _start_piece(plan, spin)


@njit_helper
def _start_piece(plan, spin):
    """The next piece of the step: all that is left of it, or an equal share of it when a
    body turning at ``spin`` rad/s would turn by more than ``TURN_PER_PIECE`` in that time
    (``PIECES`` pieces at most in a step)."""
    turn = spin * plan[LEFT]
    shares = 1
    if turn > TURN_PER_PIECE:
        shares = min(math.ceil(turn / TURN_PER_PIECE), PIECES - int(plan[PIECE_COUNT]))
    piece = plan[LEFT] / max(shares, 1)
    plan[PIECE] = piece
    plan[LEFT] = plan[LEFT] - piece
    plan[PIECE_COUNT] = plan[PIECE_COUNT] + 1.0
    plan[SPLIT] = 1.0 if plan[PIECE_COUNT] > 1.0 or shares > 1 else 0.0  # a step in pieces: a body turns fast
    plan[PHASE] = PLAIN
    plan[ELAPSED] = plan[APPROACH_COUNT] = plan[IMPACT_COUNT] = 0.0
    plan[CLOSING] = math.nan


@njit_helper
def plan_request(plan, fixed_tolerance, gravity, smallest_radius, midpoint, theta):
    """The next sub-step of ``plan``: ``(length s (0: an impact), gap tolerance m, pace s,
    localize, defer, watch, warm factor)``; ``localize``: stop at a closing instead of stepping
    across it; ``defer``: keep impacting contacts out of the active set (the approach);
    ``watch``: the sub-step looks at the contacts of the impact located (a correction; the
    impact of a step in pieces); the factor on the latest impulses that warm-starts it: its
    length over theirs (the contact forces of the step act through every sub-step; taken
    unscaled, an approach's impulses started an impact 10-100 times too large and an impact's
    percussions the rest of the step as many times too small; :func:`nscd.state.scaled_impulses`). The
    constants are the model's and settings' (:func:`gap_tolerance`, :func:`pace`).

    Midpoint rule: sub-steps close small gaps at the pace of the whole piece, not of the
    sub-step (a gap closed over a tiny sub-step would leave a large spurious velocity)."""
    phase = plan[PHASE]
    length, localize, defer, watch = plan[PIECE], True, False, False
    if phase == IMPACT:
        # contacts within the whole step's gap tolerance take part in the impact (also in a
        # piece); in a step taken in pieces, also the contacts located, whatever their gap:
        # a fast-turning body's located gaps err by its turning
        plan[LENGTH] = 0.0
        return (0.0, gap_tolerance(fixed_tolerance, gravity, smallest_radius, plan[STEP]), 0.0, False, False,
                plan[SPLIT] > 0.0, 0.0 / plan[WARM_SPAN])
    if phase == CORRECT:
        length, watch = plan[PIECE] - plan[ELAPSED], True
    elif phase == APPROACH:
        length, localize, defer = plan[CLOSING], False, True
    elif phase == REST:
        length, localize = plan[PIECE] - plan[ELAPSED], plan[IMPACT_COUNT] < IMPACTS
    span = plan[PIECE] if midpoint else length
    plan[LENGTH] = length
    return (length, gap_tolerance(fixed_tolerance, gravity, smallest_radius, span), pace(span, midpoint, theta),
            localize, defer, watch, length / plan[WARM_SPAN])


@njit_helper
def plan_receive(plan, closing_time, spin, n_active, midpoint):
    """The outcome of the sub-step just requested, into ``plan`` in place: an impact located
    ``closing_time`` s from its start (NaN: the sub-step was taken, with ``n_active`` active
    contacts; ``spin``: the largest ``|omega|`` of the scene's bodies at its end, rad/s, which
    sizes the next piece, if any is left); ``midpoint``: the midpoint rule. Returns whether the
    sub-step's impulses become the latest (taken over a sub-step of finite length: an impact's
    percussions are not kept)."""
    phase = plan[PHASE]
    if not math.isnan(closing_time):  # plain, correct or rest: an impact to locate
        if phase == REST:
            plan[APPROACH_COUNT] = 0.0
        plan[CLOSING] = closing_time
        plan[PHASE] = IMPACT if midpoint and closing_time <= 0.0 else APPROACH
        return False
    keep = n_active > 0 and plan[LENGTH] > 0.0
    if keep:
        plan[WARM_SPAN] = plan[LENGTH]
    if phase == PLAIN or phase == CORRECT or phase == REST:
        if plan[LEFT] > 0.0:
            _start_piece(plan, spin)
        else:
            plan[PHASE] = FINISHED
    elif phase == APPROACH:
        plan[ELAPSED] = plan[ELAPSED] + plan[CLOSING]
        plan[APPROACH_COUNT] = plan[APPROACH_COUNT] + 1.0
        plan[PHASE] = CORRECT if midpoint and plan[APPROACH_COUNT] < APPROACHES else IMPACT
    elif phase == IMPACT:
        plan[IMPACT_COUNT] = plan[IMPACT_COUNT] + 1.0
        plan[PHASE] = REST
    return keep
