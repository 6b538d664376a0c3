"""Contact detection: broad phase, 2D and 3D narrow phases, frames and Jacobians."""
from nscd.contact.broad import broad_phase
from nscd.contact.manifold import Manifold, Manifolds

__all__ = ["broad_phase", "Manifold", "Manifolds"]
