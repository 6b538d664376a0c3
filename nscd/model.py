"""The structure of a scene, frozen for the time step: :class:`Model`.

A :class:`Model` holds what every run of a scene shares and never changes during a
run -- dimension, gravity, the bodies' kinds, shapes, masses and inertias, their
contact laws, which bodies are fixed or driven and along which direction. It holds no
reference to the mutable :class:`nscd.Scene`, no motion and no initial state: those
are per-scene inputs and live in :class:`nscd.state.Data` beside ``t``, ``q``, ``v``.
Scenes that compile to equal models can be stepped together as one batch
(:meth:`Model.difference` says which body or field differs when they cannot).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from nscd._jit import njit
from nscd.rotation import rotation_matrices
from nscd.scene import BodyKind, Scene


@dataclass(frozen=True, eq=False)
class BodyModel:
    """The structure of one body: what must agree between scenes stepped together.

    Attributes
    ----------
    index : int
        Row of the body in ``q`` and ``v``.
    name : str
    kind : BodyKind
    shape : Polygon or Polyhedron
    mass : float
        kg (``inf`` for fixed and driven bodies).
    inertia : float or ndarray (3, 3)
        kg m^2 about the centre of mass, body frame.
    material : str
    direction : ndarray or None
        Unit direction of a driven body's horizontal motion.
    """

    index: int
    name: str
    kind: BodyKind
    shape: Any
    mass: float
    inertia: Any
    material: str
    direction: np.ndarray | None

    @property
    def is_dynamic(self) -> bool:
        return self.kind is BodyKind.DYNAMIC

    def fields(self) -> dict:
        """The compared fields (see :meth:`Model.difference`)."""
        return {"name": self.name, "kind": self.kind.value, "vertices": np.asarray(self.shape.vertices),
                "mass": self.mass, "inertia": np.asarray(self.inertia, dtype=float), "material": self.material,
                "direction": None if self.direction is None else np.asarray(self.direction)}


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    return a == b


@dataclass(frozen=True, eq=False)
class Model:
    """The frozen structure of a scene (see the module docstring). Build it with :meth:`from_scene`.

    Attributes
    ----------
    dim, nq, nv : int
        Spatial dimension, coordinates and velocity components per body.
    gravity : float
        m/s^2, along -y (2D) or -z (3D).
    bodies : tuple of BodyModel
    dynamic : ndarray of bool, shape (n_bodies,)
    dof_of_body : ndarray of int, shape (n_bodies,)
        First index of each dynamic body in the velocity vector of the dynamic bodies; -1 otherwise.
    n_dofs : int
        Velocity unknowns (``nv`` times the number of dynamic bodies).
    mass : ndarray, shape (n_bodies,)
        kg (inf for fixed and driven bodies).
    inertia_body : ndarray, shape (n_bodies,) in 2D or (n_bodies, 3, 3) in 3D
        kg m^2 about the centre of mass, body frame (zero rows for non-dynamic bodies).
    dynamic_index, prescribed_index : ndarray of int
        Indices of the dynamic bodies (velocity order) and of the fixed and driven ones.
    smallest_radius : float
        Smallest bounding radius of the dynamic bodies, m (the scene's length scale).
    radius : ndarray, shape (n_bodies,)
        Bounding radius of each body's shape about its centre of mass, m.
    thinnest : float
        Smallest thickness (``shape.thickness``) of any body, fixed and driven ones
        included, m: the depth a fast body can pass through within one step.
    law_material : ndarray of int, shape (n_bodies,)
        Row of each body's material in ``law_table``.
    law_table : ndarray, shape (k, k, 2)
        ``(friction, restitution)`` between materials (the scene's default where unset).
    law_keys : ndarray of int, shape (o,)
        The pairs of bodies ``(i, j)``, ``i < j``, whose contact law is set for the pair, as
        ``i * n_bodies + j``, sorted.
    law_values : ndarray, shape (o, 2)
        Their friction coefficient and restitution.
    mass_diagonal : ndarray, shape (n_dofs,) or None
        2D: the diagonal of the mass matrix of the dynamic bodies (kg, kg, kg m^2).
    polygons : tuple of ndarray or None
        2D: body-frame vertices of every body laid end to end (V, 2) in m, each
        vertex's body (V,), each body's first vertex (n_bodies + 1,).
    polyhedra : PolyhedronBatch or None
        3D: every body's shape laid end to end for the narrow phase.
    """

    dim: int
    nq: int
    nv: int
    gravity: float
    bodies: tuple
    dynamic: np.ndarray
    dof_of_body: np.ndarray
    n_dofs: int
    mass: np.ndarray
    inertia_body: np.ndarray
    dynamic_index: np.ndarray
    prescribed_index: np.ndarray
    smallest_radius: float
    radius: np.ndarray
    thinnest: float
    law_material: np.ndarray
    law_table: np.ndarray
    law_keys: np.ndarray
    law_values: np.ndarray
    mass_diagonal: np.ndarray | None
    polygons: tuple | None
    polyhedra: Any

    @classmethod
    def from_scene(cls, scene: Scene) -> "Model":
        """The structure of ``scene`` (a snapshot: later edits of the scene do not reach it).

        Raises
        ------
        ValueError
            If the scene has no dynamic body.
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"scene is a {type(scene).__name__}, must be a Scene.")
        bodies = tuple(BodyModel(b.index, b.name, b.kind, b.shape, b.mass, b.inertia, b.material,
                                 None if b.direction is None else np.array(b.direction, dtype=float))
                       for b in scene.bodies)
        if not any(b.is_dynamic for b in bodies):
            raise ValueError("the scene has no dynamic body: add one with scene.add_block(...).")
        dynamic = np.array([b.is_dynamic for b in bodies])
        dof = np.full(len(bodies), -1, dtype=int)
        dof[dynamic] = np.arange(int(dynamic.sum())) * scene.nv
        mass = np.array([b.mass for b in bodies], dtype=float)
        if scene.dim == 2:
            inertia = np.array([b.inertia if b.is_dynamic else 0.0 for b in bodies], dtype=float)
            mass_diagonal = np.column_stack([mass[dynamic], mass[dynamic], inertia[dynamic]]).ravel()
            mass_diagonal.setflags(write=False)
            shapes = [np.asarray(b.shape.vertices, dtype=float) for b in bodies]
            counts = np.array([len(s) for s in shapes])
            polygons = (np.concatenate(shapes), np.repeat(np.arange(len(shapes)), counts),
                        np.concatenate(([0], np.cumsum(counts))))
            polyhedra = None
        else:
            from nscd.shapes3d import PolyhedronBatch

            inertia = np.array([np.asarray(b.inertia, float) if b.is_dynamic else np.zeros((3, 3))
                                for b in bodies])
            mass_diagonal, polygons = None, None
            polyhedra = PolyhedronBatch([b.shape for b in bodies])
        materials = sorted({b.material for b in bodies})
        law_table = np.empty((len(materials), len(materials), 2))
        for a, name_a in enumerate(materials):
            for b, name_b in enumerate(materials):
                law = scene._material_laws.get(frozenset((name_a, name_b)), scene.default_contact)
                law_table[a, b] = law.friction, law.restitution
        overrides = {}
        for pair, law in scene._body_laws.items():
            i, j = sorted(pair)
            if dynamic[i] or dynamic[j]:
                overrides[i * len(bodies) + j] = (law.friction, law.restitution)
        law_keys = np.array(sorted(overrides), dtype=np.int64)
        return cls(
            dim=scene.dim, nq=scene.nq, nv=scene.nv, gravity=float(scene.gravity), bodies=bodies,
            dynamic=dynamic, dof_of_body=dof, n_dofs=int(dynamic.sum()) * scene.nv, mass=mass, inertia_body=inertia,
            dynamic_index=np.flatnonzero(dynamic), prescribed_index=np.flatnonzero(~dynamic),
            smallest_radius=min(b.shape.radius for b in bodies if b.is_dynamic),
            radius=np.array([b.shape.radius for b in bodies], dtype=float),
            thinnest=min(b.shape.thickness for b in bodies),
            law_material=np.array([materials.index(b.material) for b in bodies], dtype=np.int64), law_table=law_table,
            law_keys=law_keys, law_values=np.array([overrides[key] for key in law_keys.tolist()]).reshape(-1, 2),
            mass_diagonal=mass_diagonal, polygons=polygons, polyhedra=polyhedra,
        )

    def contact_law(self, i: int, j: int) -> tuple[float, float]:
        """Friction coefficient and restitution between bodies ``i`` and ``j`` (body indices)."""
        friction, restitution = self.contact_laws(np.array([i]), np.array([j]))
        return float(friction[0]), float(restitution[0])

    def contact_laws(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised :meth:`contact_law` over body pairs ``(i[k], j[k])`` ((p,) each)
        (:func:`pair_laws`).

        Returns
        -------
        friction, restitution : ndarray, shape (p,)
            Coulomb coefficient (>= 0) and Newton restitution (in [0, 1]) of each pair.
        """
        return pair_laws(np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64),
                         self.law_material, self.law_table, self.law_keys, self.law_values)

    def difference(self, other: "Model", this: str = "this model") -> str | None:
        """What differs between this model and ``other`` (None if they are the same structure).

        Compared: dimension, gravity, the number of bodies, every body's name, kind,
        shape vertices, mass, inertia, material and direction of motion, and the
        contact laws. Motions and initial states are not part of a model. ``this`` names
        this model in the message (e.g. ``"scenes[0]"``).
        """
        for name in ("dim", "gravity"):
            if getattr(self, name) != getattr(other, name):
                return f"{name} == {getattr(other, name)!r}, {this} has {getattr(self, name)!r}"
        if len(self.bodies) != len(other.bodies):
            return f"{len(other.bodies)} bodies, {this} has {len(self.bodies)}"
        for mine, theirs in zip(self.bodies, other.bodies):
            ref = mine.fields()
            for field_name, value in theirs.fields().items():
                if not _same(value, ref[field_name]):
                    return (f"body {theirs.index} ({theirs.name!r}) {field_name} == {value!r}, "
                            f"{this} has {ref[field_name]!r}")
        n = len(self.bodies)
        pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if self.dynamic[i] or self.dynamic[j]]
                         ).reshape(-1, 2)
        if len(pairs):
            mine = np.column_stack(self.contact_laws(pairs[:, 0], pairs[:, 1]))
            theirs = np.column_stack(other.contact_laws(pairs[:, 0], pairs[:, 1]))
            bad = np.flatnonzero((mine != theirs).any(axis=1))
            if bad.size:
                i, j = pairs[bad[0]]
                return (f"contact law (friction, restitution) between bodies {i} and {j} == "
                        f"{tuple(theirs[bad[0]].tolist())}, {this} has {tuple(mine[bad[0]].tolist())}")
        return None

    def world_inertia(self, q: np.ndarray) -> np.ndarray:
        """Inertia of dynamic bodies in the world frame, kg m^2.

        ``q`` has shape (..., n_bodies, nq) (one configuration or a history); returns
        (n_dyn,) in 2D and (..., n_dyn, 3, 3) in 3D.
        """
        inertia = self.inertia_body[self.dynamic]
        if self.dim == 2:
            return inertia
        quat = q[..., self.dynamic_index, 3:]
        flat = np.ascontiguousarray(quat.reshape(-1, 4))
        body = np.ascontiguousarray(np.broadcast_to(inertia, quat.shape[:-1] + (3, 3)).reshape(-1, 3, 3))
        return rotated_inertia(rotation_matrices(flat), body).reshape(quat.shape[:-1] + (3, 3))


@njit
def rotated_inertia(rot, inertia):
    """``R I R^T`` (m, 3, 3), kg m^2, of body-frame inertias ``inertia`` and rotations ``rot`` (m, 3, 3)."""
    out = np.empty(rot.shape)
    for k in range(rot.shape[0]):
        for i in range(3):
            for l in range(3):
                total = 0.0
                for j in range(3):
                    inner = 0.0
                    for m in range(3):
                        inner += inertia[k, j, m] * rot[k, l, m]
                    total += rot[k, i, j] * inner
                out[k, i, l] = total
    return out


@njit
def pair_laws(a, b, material, table, keys, values):
    """Friction coefficient and restitution (p,) each of the body pairs ``(a[k], b[k])`` (p,):
    the law of their materials (``table[material[a], material[b]]``), or the law set for the
    pair (``values`` (o, 2) of the pairs ``keys`` (o,), ``i * n_bodies + j`` with ``i < j``,
    sorted; :class:`Model`)."""
    n = material.shape[0]
    friction = np.empty(a.shape[0])
    restitution = np.empty(a.shape[0])
    for k in range(a.shape[0]):
        friction[k] = table[material[a[k]], material[b[k]], 0]
        restitution[k] = table[material[a[k]], material[b[k]], 1]
        if keys.shape[0] == 0:
            continue
        key = min(a[k], b[k]) * n + max(a[k], b[k])
        low, high = 0, keys.shape[0]  # bisection: the first key >= key
        while low < high:
            middle = (low + high) // 2
            if keys[middle] < key:
                low = middle + 1
            else:
                high = middle
        if low < keys.shape[0] and keys[low] == key:
            friction[k], restitution[k] = values[low, 0], values[low, 1]
    return friction, restitution
