"""Direction sets and small harness functions shared by several tests (a command line
that must fail cleanly among them)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from brdffit.cli import main
from brdffit.core.geometry import spherical_to_vector, uniform_hemisphere
from brdffit.models.check import extreme_pairs, params_at_bounds  # noqa: F401  (re-exported)


def random_pairs(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` (wi, wo) pairs uniform on the upper hemisphere."""
    rng = np.random.default_rng(seed)
    return uniform_hemisphere(rng, n), uniform_hemisphere(rng, n)


def rotate_z(v: np.ndarray, angle: float) -> np.ndarray:
    """Rotate directions about the normal by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return v @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T


def random_params(model, rng: np.random.Generator) -> dict:
    """Parameters drawn uniformly in each one's optimiser space, mapped to natural units."""
    import jax.numpy as jnp

    out = {}
    for p in model.parameters:
        u = (
            rng.uniform(-3.0, 3.0, p.shape)
            if p.transform != "identity"
            else rng.uniform(-1, 1, p.shape)
        )
        out[p.name] = p.to_natural(jnp.asarray(u, float))
    return out


def hemisphere_integral(f, scale: float, n_phi: int = 512) -> float:
    """``int f(h) cos(theta) dw`` over the upper hemisphere for ``f`` peaked at the normal.

    Variable ``t = 1 - cos(theta)`` (``cos sin dtheta = (1 - t) dt``), Gauss-Legendre with
    24 nodes on 24 panels with geometric ends from ``scale / 16`` to 1 (resolving a peak
    of width ``scale`` in ``t`` and the tail), and the periodic trapezoid rule in ``phi``
    (spectrally accurate for a smooth periodic integrand). Fixed shapes: one compile.
    """
    ends = np.concatenate([[0.0], np.geomspace(scale / 16.0, 1.0, 24)])
    x, w = np.polynomial.legendre.leggauss(24)
    lo, hi = ends[:-1, None], ends[1:, None]
    t = (0.5 * (hi - lo) * x + 0.5 * (hi + lo)).ravel()
    wt = (0.5 * (hi - lo) * w).ravel()
    phi = np.arange(n_phi) * 2.0 * np.pi / n_phi
    tt, pp = np.meshgrid(t, phi, indexing="ij")
    s = np.sqrt(tt * (2.0 - tt))
    h = np.stack([s * np.cos(pp), s * np.sin(pp), 1.0 - tt], axis=-1).reshape(-1, 3)
    vals = np.asarray(f(jnp.asarray(h))).reshape(tt.shape)
    return float(np.sum(vals * ((1.0 - t) * wt)[:, None]) * 2.0 * np.pi / n_phi)


def half_vector_albedo(evaluate, params, theta_i, scale, n=150):
    """Directional albedo (red channel) at ``theta_i`` by quadrature over half vectors.

    ``dw_o = 4 (wi.h) dw_h``; ``scale`` is the lobe width in tan(theta_h).

    theta_h = arctan(scale x), x in [0, 8] Gauss-Legendre, phi_h midpoint rule.
    """
    x, wx = np.polynomial.legendre.leggauss(n)
    x, wx = 4.0 * (x + 1), 4.0 * wx
    th, dth = np.arctan(scale * x), scale / (1 + (scale * x) ** 2)
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    weight = ((wx * dth * np.sin(th))[:, None] * np.ones_like(PH)).ravel() * (np.pi / n)
    h = spherical_to_vector(TH, PH).reshape(-1, 3)
    wi = np.broadcast_to(spherical_to_vector(theta_i, 0.0), h.shape)
    d = np.sum(wi * h, -1)
    wo = 2 * d[:, None] * h - wi
    f = np.asarray(evaluate(params, wi, wo))[:, 0]
    return float(np.sum(np.where(d > 0, f * np.clip(wo[:, 2], 0, None) * 4 * d, 0) * weight))


def fails_cleanly(capsys, argv, *needles) -> str:
    """Run the CLI in-process: exit code 2, one stderr line holding every needle."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err
