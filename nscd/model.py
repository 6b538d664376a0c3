"""A scene compiled into arrays for the time step (built once per simulation).

:class:`Model` is the static, array form of a :class:`nscd.Scene` that the step
reads: masses, inertias, the map from dynamic bodies to velocity indices, and
the prescribed kinematics of fixed and driven bodies. It never changes during a run.
"""
from __future__ import annotations

import functools

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from nscd.rotation import quaternion_to_matrix
from nscd.scene import Body, Scene


@dataclass(frozen=True, eq=False)
class Model:
    """Array form of a scene.

    Attributes
    ----------
    scene : Scene
    dim, nq, nv : int
        Spatial dimension, coordinates and velocity components per body.
    dynamic : ndarray of bool, shape (n_bodies,)
    dof_of_body : ndarray of int, shape (n_bodies,)
        First index of each dynamic body in the velocity vector ``v``; -1 otherwise.
    n_dofs : int
        Length of ``v`` (``nv`` times the number of dynamic bodies).
    mass : ndarray, shape (n_bodies,)
        kg (inf for fixed and driven bodies).
    inertia_body : ndarray, shape (n_bodies,) in 2D or (n_bodies, 3, 3) in 3D
        kg m^2 about the centre of mass, body frame (zero rows for non-dynamic bodies).
    prescribed : list of Body
        Fixed and driven bodies, whose pose comes from their motion.
    dynamic_index : ndarray of int, shape (n_dyn,)
        Scene indices of the dynamic bodies, in velocity order.
    laws : dict
        Contact laws ``(friction, restitution)`` of body pairs ``(i, j)``, filled on first
        use by :meth:`contact_law` (the scene's laws do not change during a run).
    law_table : dict
        The same laws as sorted arrays for :meth:`contact_laws`: ``"keys"`` (k,) int64
        pair keys ``i * n_bodies + j`` and ``"values"`` (k, 2), filled on first use.
    constant_mass : dict
        2D only: the mass matrices of :meth:`mass_matrix` keyed by ``dense``, built on
        first use (a 2D mass matrix does not depend on the configuration).
    groups : list
        2D only: :meth:`polygon_groups`, built on first use.
    """

    scene: Scene
    dim: int
    nq: int
    nv: int
    dynamic: np.ndarray
    dof_of_body: np.ndarray
    n_dofs: int
    mass: np.ndarray
    inertia_body: np.ndarray
    prescribed: list
    dynamic_index: np.ndarray
    laws: dict = field(default_factory=dict)
    law_table: dict = field(default_factory=dict)
    constant_mass: dict = field(default_factory=dict)
    groups: list = field(default_factory=list)

    @classmethod
    def from_scene(cls, scene: Scene) -> "Model":
        bodies = scene.bodies
        if not any(b.is_dynamic for b in bodies):
            raise ValueError("the scene has no dynamic body: add one with scene.add_block(...).")
        dynamic = np.array([b.is_dynamic for b in bodies])
        dof = np.full(len(bodies), -1, dtype=int)
        dof[dynamic] = np.arange(int(dynamic.sum())) * scene.nv
        if scene.dim == 2:
            inertia = np.array([b.inertia if b.is_dynamic else 0.0 for b in bodies], dtype=float)
        else:
            inertia = np.array([np.asarray(b.inertia, float) if b.is_dynamic else np.zeros((3, 3))
                                for b in bodies])
        return cls(
            scene=scene, dim=scene.dim, nq=scene.nq, nv=scene.nv, dynamic=dynamic,
            dof_of_body=dof, n_dofs=int(dynamic.sum()) * scene.nv,
            mass=np.array([b.mass for b in bodies], dtype=float), inertia_body=inertia,
            prescribed=[b for b in bodies if not b.is_dynamic],
            dynamic_index=np.flatnonzero(dynamic),
        )

    @functools.cached_property
    def smallest_radius(self) -> float:
        """Smallest bounding radius of the dynamic bodies, m (the scene's length scale; computed once)."""
        return min(b.shape.radius for b in self.scene.bodies if b.is_dynamic)

    @property
    def bodies(self) -> list[Body]:
        return self.scene.bodies

    def prescribe(self, q: np.ndarray, v: np.ndarray, t: float) -> None:
        """Write the pose and velocity at time ``t`` of fixed and driven bodies into q and v."""
        for body in self.prescribed:
            q[body.index], v[body.index] = body.prescribed(t)

    def contact_law(self, i: int, j: int) -> tuple[float, float]:
        """Friction coefficient and restitution between bodies ``i`` and ``j`` (scene indices)."""
        law = self.laws.get((i, j))
        if law is None:
            found = self.scene.contact_law(self.bodies[i], self.bodies[j])
            law = self.laws[(i, j)] = (found.friction, found.restitution)
        return law

    def contact_laws(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised :meth:`contact_law` over body pairs ``(i[k], j[k])`` (scene indices, (p,) each).

        Returns
        -------
        friction, restitution : ndarray, shape (p,)
            Coulomb coefficient (>= 0) and Newton restitution (in [0, 1]) of each pair.
        """
        n = len(self.bodies)
        keys = np.asarray(i, dtype=np.int64) * n + np.asarray(j, dtype=np.int64)
        known = self.law_table.get("keys", np.zeros(0, dtype=np.int64))
        pos = np.minimum(np.searchsorted(known, keys), max(len(known) - 1, 0))
        if len(known) == 0 or not (known[pos] == keys).all():
            # pairs met for the first time: through the scene's rules once, then kept sorted
            new = np.setdiff1d(keys, known)
            values = np.array([self.contact_law(int(k // n), int(k % n)) for k in new]).reshape(-1, 2)
            merged = np.concatenate([known, new])
            order = np.argsort(merged)
            self.law_table["keys"] = known = merged[order]
            self.law_table["values"] = np.concatenate(
                [self.law_table.get("values", np.zeros((0, 2))), values])[order]
            pos = np.searchsorted(known, keys)
        values = self.law_table["values"][pos]
        return values[:, 0], values[:, 1]

    def polygon_groups(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """2D: the bodies grouped by vertex count, for vectorised posing and detection.

        Returns
        -------
        list of (index, vertices)
            One entry per vertex count ``n``, in increasing ``n``: the scene indices of
            the bodies with ``n`` vertices, ndarray of int (k,), and their body-frame
            vertices in m, ndarray (k, n, 2), counter-clockwise.
        """
        if self.dim != 2:
            raise ValueError(f"polygon_groups is for 2D scenes; this model has dim == {self.dim}.")
        if not self.groups:
            counts = np.array([len(b.shape.vertices) for b in self.bodies])
            for n in np.unique(counts):
                index = np.flatnonzero(counts == n)
                vertices = np.array([self.bodies[i].shape.vertices for i in index], dtype=float)
                self.groups.append((index, vertices))
        return self.groups

    def mass_matrix(self, q: np.ndarray, dense: bool) -> tuple[sp.csc_array | np.ndarray, np.ndarray]:
        """Block-diagonal mass matrix of the dynamic bodies at configuration ``q``.

        Returns the matrix, shape (n_dofs, n_dofs), dense or CSC, and its blocks: the
        per-dof diagonal (n_dofs,) in 2D (kg, kg, kg m^2; read-only, shared between
        calls), the 6x6 blocks (n_dyn, 6, 6) in 3D.
        """
        if self.dim == 2:
            if dense not in self.constant_mass:
                self.constant_mass[dense] = self._mass_matrix(q, dense)
            return self.constant_mass[dense]
        return self._mass_matrix(q, dense)

    def _mass_matrix(self, q: np.ndarray, dense: bool) -> tuple[sp.csc_array | np.ndarray, np.ndarray]:
        mass = self.mass[self.dynamic]
        inertia = self.world_inertia(q)
        if self.dim == 2:
            diag = np.column_stack([mass, mass, inertia]).ravel()
            matrix = np.diag(diag) if dense else sp.diags_array(diag, format="csc")
            for array in (diag, matrix if dense else matrix.data):
                array.setflags(write=False)
            return matrix, diag
        blocks = np.zeros((len(mass), 6, 6))
        blocks[:, 0, 0] = blocks[:, 1, 1] = blocks[:, 2, 2] = mass
        blocks[:, 3:, 3:] = inertia
        if dense:
            full = np.zeros((self.n_dofs, self.n_dofs))
            for k, block in enumerate(blocks):
                full[6 * k:6 * k + 6, 6 * k:6 * k + 6] = block
            return full, blocks
        return sp.block_diag(list(blocks), format="csc"), blocks

    def world_inertia(self, q: np.ndarray) -> np.ndarray:
        """Inertia of dynamic bodies in the world frame, kg m^2.

        ``q`` has shape (..., n_bodies, nq) (one configuration or a history); returns
        (n_dyn,) in 2D and (..., n_dyn, 3, 3) in 3D.
        """
        inertia = self.inertia_body[self.dynamic]
        if self.dim == 2:
            return inertia
        quat = q[..., self.dynamic_index, 3:]
        rot = np.moveaxis(quaternion_to_matrix(np.moveaxis(quat, -1, 0)), (0, 1), (-2, -1))
        return np.einsum("...ij,...jk,...lk->...il", rot, inertia, rot)
