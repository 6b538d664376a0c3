"""Loader for the FCLIB / Siconos frictional contact test problems converted to ``.npz``.

The files (``shared/data/fclib/``, Apache-2.0, Copyright INRIA — see the LICENSE file
there) hold ``u = W r + q`` problems: ``W`` dense (``W``) or CSR (``W_data``,
``W_indices``, ``W_indptr``, ``W_shape``), ``q``, ``mu`` (per contact), ``dim``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class FclibProblem:
    """One frictional contact problem ``u = W r + q``.

    Attributes
    ----------
    name : str
        File stem, e.g. ``"Capsules-i101-404"``.
    W : ndarray or scipy.sparse.csr_matrix, shape (n, n)
        Delassus matrix, ``n = dim * contacts``, rows per contact ``[N, T1, (T2)]``.
    q : ndarray, shape (n,)
        Free relative velocity.
    mu : ndarray, shape (n // dim,)
        Friction coefficients.
    dim : int
        2 or 3.
    info : str
        Description from the source file.
    kind : str
        ``"local"`` or ``"global (condensed)"``.
    M_diag, H, f, w : ndarray, scipy.sparse.csr_matrix, ndarray, ndarray or None
        Only for the FCLIB *global* problems (else None): ``M v = H r + f``,
        ``u = H^T v + w`` with ``M = diag(M_diag)`` (n,), ``H`` (n, m * dim), ``f`` (n,),
        ``w`` (m * dim,); ``W = H^T M^-1 H``, ``q = H^T M^-1 f + w``. In nscd's velocity
        form (:func:`nscd.solver.solve_velocity`): ``v_free = f / M_diag``, Jacobian ``H^T``,
        ``offset = w``.
    """

    name: str
    W: np.ndarray | sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    dim: int
    info: str = ""
    kind: str = ""
    M_diag: np.ndarray | None = None
    H: sp.csr_matrix | None = None
    f: np.ndarray | None = None
    w: np.ndarray | None = None

    @property
    def contacts(self) -> int:
        """Number of contacts."""
        return self.mu.size


def load(path: str | Path) -> FclibProblem:
    """Read one converted FCLIB/Siconos problem.

    Parameters
    ----------
    path : str or Path
        ``.npz`` file.

    Returns
    -------
    FclibProblem

    Raises
    ------
    ValueError
        When the file lacks ``q``, ``mu``, ``dim`` or ``W``.
    """
    path = Path(path)
    with np.load(path, allow_pickle=False) as data:
        keys = set(data.files)
        missing = {"q", "mu", "dim"} - keys
        if missing or not ({"W"} <= keys or {"W_data", "W_indices", "W_indptr", "W_shape"} <= keys):
            lacking = sorted(missing) or ["W"]
            raise ValueError(f"path == {str(path)!r} is not an FCLIB problem file (missing {lacking}).")
        if "W" in keys:
            W = np.array(data["W"], dtype=float)
        else:
            shape = tuple(int(s) for s in data["W_shape"])
            W = sp.csr_matrix((data["W_data"], data["W_indices"], data["W_indptr"]), shape=shape)
        extra = {k: str(data[k]) if k in keys else "" for k in ("info", "kind")}
        if {"M_diag", "H_data", "H_indices", "H_indptr", "H_shape", "f", "w"} <= keys:
            shape = tuple(int(s) for s in data["H_shape"])
            extra.update(M_diag=np.array(data["M_diag"], dtype=float), f=np.array(data["f"], dtype=float),
                         w=np.array(data["w"], dtype=float),
                         H=sp.csr_matrix((data["H_data"], data["H_indices"], data["H_indptr"]), shape=shape))
        return FclibProblem(name=path.stem, W=W, q=np.array(data["q"], dtype=float),
                            mu=np.atleast_1d(np.array(data["mu"], dtype=float)), dim=int(data["dim"]), **extra)
