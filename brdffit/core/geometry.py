"""Directions, Rusinkiewicz half/difference angles and the MERL grid.

Conventions (DESIGN.md): unit vectors in the local shading frame, z the normal,
x the tangent, y the bitangent; ``wi`` points toward the light and ``wo`` toward
the viewer, both away from the surface. Angles are in radians.

Two halves:

* data-side functions in numpy (conversions, the MERL grid, solid-angle weights,
  the horizon mask), used once per data set by readers and generators;
* :class:`ShadingGeometry`, the per-sample cosines in JAX that every model core
  takes, computed once per data set and passed to jitted functions as an argument.

Rusinkiewicz (1998): ``h = normalize(wi + wo)``, ``d = R_y(-theta_h) R_z(-phi_h) wi``.
MERL tables are isotropic and store ``phi_d`` folded into [0, pi) by the symmetry
``f(phi_d) = f(phi_d + pi)``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

MERL_SHAPE: tuple[int, int, int] = (90, 90, 180)
"""(n_theta_h, n_theta_d, n_phi_d) of a MERL table."""


def _rot_y(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def _rot_z(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def spherical_to_vector(theta: float | np.ndarray, phi: float | np.ndarray) -> np.ndarray:
    """Unit vector(s) with polar angle ``theta`` from +z and azimuth ``phi`` from +x."""
    theta, phi = np.asarray(theta, float), np.asarray(phi, float)
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def halfdiff_to_io(
    theta_h: np.ndarray,
    theta_d: np.ndarray,
    phi_d: np.ndarray,
    phi_h: np.ndarray | float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Rusinkiewicz (theta_h, theta_d, phi_d[, phi_h]) -> (wi, wo), each (..., 3).

    ``wi = R_z(phi_h) R_y(theta_h) d`` with ``d`` the difference vector, and ``wo`` the
    same rotation of ``d`` mirrored about the half vector (``(-dx, -dy, dz)``).
    """
    theta_h, theta_d, phi_d = np.broadcast_arrays(
        np.asarray(theta_h, float), np.asarray(theta_d, float), np.asarray(phi_d, float)
    )
    phi_h = np.broadcast_to(np.asarray(phi_h, float), theta_h.shape)
    d = spherical_to_vector(theta_d, phi_d)
    d_mirror = d * np.array([-1.0, -1.0, 1.0])
    wi = _rot_z(_rot_y(d, theta_h), phi_h)
    wo = _rot_z(_rot_y(d_mirror, theta_h), phi_h)
    return wi, wo


def io_to_halfdiff(
    wi: np.ndarray, wo: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(wi, wo) -> (theta_h, theta_d, phi_d, phi_h), ``phi_d`` and ``phi_h`` in (-pi, pi].

    For ``wi = -wo`` the half vector is undefined; it is taken as +z.
    """
    wi = np.asarray(wi, float)
    wo = np.asarray(wo, float)
    h = wi + wo
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    h = np.where(norm > 1e-12, h / np.where(norm > 1e-12, norm, 1.0), np.array([0.0, 0.0, 1.0]))
    # arctan2 rather than arccos keeps full precision near theta = 0 (wi ~ wo).
    theta_h = np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    d = _rot_y(_rot_z(wi, -phi_h), -theta_h)
    theta_d = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    phi_d = np.arctan2(d[..., 1], d[..., 0])
    return theta_h, theta_d, phi_d, phi_h


def fold_phi_d(phi_d: np.ndarray) -> np.ndarray:
    """Fold ``phi_d`` from (-pi, pi] into [0, pi) as MERL does (add pi when negative)."""
    phi_d = np.asarray(phi_d, float)
    phi_d = np.where(phi_d < 0.0, phi_d + np.pi, phi_d)
    return np.where(phi_d >= np.pi, phi_d - np.pi, phi_d)


def merl_indices(
    theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MERL bin indices, each clamped to its range, exactly as MERL's reference reader.

    ``i_th = floor(90 sqrt(theta_h / (pi/2)))``, ``i_td = floor(90 theta_d / (pi/2))``,
    ``i_pd = floor(180 phi_d / pi)`` after folding ``phi_d`` into [0, pi).
    """
    n_th, n_td, n_pd = MERL_SHAPE
    th = np.clip(np.asarray(theta_h, float), 0.0, None)
    i_th = np.floor(n_th * np.sqrt(th / (np.pi / 2))).astype(np.int64)
    i_td = np.floor(n_td * np.asarray(theta_d, float) / (np.pi / 2)).astype(np.int64)
    i_pd = np.floor(n_pd * fold_phi_d(phi_d) / np.pi).astype(np.int64)
    return np.clip(i_th, 0, n_th - 1), np.clip(i_td, 0, n_td - 1), np.clip(i_pd, 0, n_pd - 1)


def merl_bin_centres() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles at the centre of every MERL bin, each shaped ``MERL_SHAPE`` (file order).

    We use the bin-centre convention: ``theta_h = ((i + 0.5)/90)^2 pi/2``,
    ``theta_d = (j + 0.5)/90 pi/2``, ``phi_d = (k + 0.5)/180 pi``. Unlike the bin-start
    convention it maps back to the same index under :func:`merl_indices`.
    """
    n_th, n_td, n_pd = MERL_SHAPE
    u = (np.arange(n_th) + 0.5) / n_th
    theta_h = (np.pi / 2) * u**2
    theta_d = (np.arange(n_td) + 0.5) / n_td * (np.pi / 2)
    phi_d = (np.arange(n_pd) + 0.5) / n_pd * np.pi
    return np.meshgrid(theta_h, theta_d, phi_d, indexing="ij")


def merl_solid_angle_weights(
    theta_h: np.ndarray, theta_d: np.ndarray, shape: tuple[int, int, int] = MERL_SHAPE
) -> np.ndarray:
    """Measure ``dwi dwo`` (sr^2) of each cell of a (strided) MERL-type grid.

    ``dwi dwo = 4 cos(td) sin(th) sin(td) dth dphi_h dtd dphi_d`` (Rusinkiewicz), with
    ``dth = pi u du`` for ``theta_h = (pi/2) u^2``, ``dphi_h = 2 pi`` (isotropy) and the
    folded ``phi_d`` cell counted twice. ``shape`` gives the bin counts the grid is
    divided into, so a coarser grid gets proportionally larger cells. Over the cells
    with both directions above the horizon the weights sum to ``(2 pi)^2``.
    """
    n_th, n_td, n_pd = shape
    u = np.sqrt(np.clip(theta_h, 0.0, None) / (np.pi / 2))
    d_th = np.pi * u / n_th
    d_td = (np.pi / 2) / n_td
    d_pd = 2.0 * np.pi / n_pd
    return (
        4.0 * np.cos(theta_d) * np.sin(theta_h) * np.sin(theta_d) * d_th * d_td * d_pd * 2.0 * np.pi
    )


def above_horizon(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """True where both directions are strictly above the surface (z > 0)."""
    return (np.asarray(wi)[..., 2] > 0.0) & (np.asarray(wo)[..., 2] > 0.0)


def uniform_hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` directions drawn uniformly on the upper hemisphere (pdf ``1/(2 pi)``)."""
    z = rng.uniform(0.0, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    r = np.sqrt(np.clip(1.0 - z**2, 0.0, None))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


class ShadingGeometry(eqx.Module):
    """Per-sample shading quantities every model core takes (JAX arrays, shape (N,)).

    Samples below the horizon are replaced by ``wi = wo = +z`` so that no term of any
    model meets a zero cosine or an undefined half vector there (the first half of
    the "double where"); models mask them back to zero through ``above``.

    Fields: ``wi``, ``wo`` and the unit half vector ``h`` (N, 3); ``cos_i = wi.z``,
    ``cos_o = wo.z``, ``cos_h = h.z``, ``cos_d = wi.h = wo.h``; ``above`` (N,) bool.
    """

    wi: Float[Array, "n 3"]
    wo: Float[Array, "n 3"]
    h: Float[Array, "n 3"]
    cos_i: Float[Array, " n"]
    cos_o: Float[Array, " n"]
    cos_h: Float[Array, " n"]
    cos_d: Float[Array, " n"]
    above: Bool[Array, " n"]


@jax.jit
def shading_geometry(wi: Float[ArrayLike, "n 3"], wo: Float[ArrayLike, "n 3"]) -> ShadingGeometry:
    """Compute :class:`ShadingGeometry` from unit directions (jittable, any float dtype)."""
    wi = jnp.asarray(wi)
    wo = jnp.asarray(wo)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    up = jnp.zeros_like(wi).at[:, 2].set(1)
    wi = jnp.where(above[:, None], wi, up)
    wo = jnp.where(above[:, None], wo, up)
    s = wi + wo
    h = s / jnp.linalg.norm(s, axis=-1, keepdims=True)
    return ShadingGeometry(
        wi=wi,
        wo=wo,
        h=h,
        cos_i=wi[:, 2],
        cos_o=wo[:, 2],
        cos_h=h[:, 2],
        cos_d=jnp.clip(jnp.sum(wi * h, axis=-1), 0, 1),
        above=above,
    )


def in_plane_directions(
    theta_i_deg: float, theta_o_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) in the plane of incidence (x-z plane; ``phi_d = 0``).

    ``wi = (-sin theta_i, 0, cos theta_i)``, ``wo = (sin theta_o, 0, cos theta_o)``: a
    positive ``theta_o`` lies on the specular side (mirror direction at ``theta_o =
    theta_i``), a negative one on the side of the light (backscatter at ``-theta_i``).
    """
    to = np.deg2rad(np.asarray(theta_o_deg, float))
    ti = np.deg2rad(theta_i_deg)
    wi = np.broadcast_to([-np.sin(ti), 0.0, np.cos(ti)], (to.size, 3)).copy()
    wo = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=-1)
    return wi, wo
