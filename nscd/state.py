"""The mutable part of a simulation, as an immutable snapshot: time, positions, velocities."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class State:
    """Positions and velocities of every body of a scene at time ``t``.

    Attributes
    ----------
    t : float
        Time in s.
    q : ndarray, shape (n_bodies, nq)
        Generalised positions: 2D ``(x, y, angle)`` in m, m, rad (CCW);
        3D ``(x, y, z, qw, qx, qy, qz)`` (unit quaternion, body to world).
    v : ndarray, shape (n_bodies, nv)
        Velocities: 2D ``(vx, vy, omega)`` in m/s, m/s, rad/s;
        3D ``(vx, vy, vz, wx, wy, wz)`` with omega in the world frame.

    Rows of fixed and driven bodies hold their prescribed pose and velocity.
    The arrays are read-only: a step returns a new ``State``.
    """

    t: float
    q: np.ndarray
    v: np.ndarray

    def __post_init__(self) -> None:
        for arr in (self.q, self.v):
            arr.setflags(write=False)
