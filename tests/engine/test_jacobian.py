"""The compressed Jacobian (Curtis, Powell & Reid) against plain forward mode, and every
model's ``channel_separable`` against its own derivatives."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models, synthesize
from brdffit.core.geometry import shading_geometry
from brdffit.engine import robust as robust_mod
from brdffit.engine.block_errors import BlockChunks, block_index
from brdffit.engine.jacobian import Colouring
from brdffit.engine.metrics import get_metric, prepare
from brdffit.engine.objective import Objective
from tests.cases import CASES, Case
from tests.helpers import random_pairs

WI, WO = random_pairs(3, 64)


def _checked_rows():
    """Every row; in the default suite, walter and, of each model whose separability
    depends on its options, the first row that is separable and the first that is not
    (a probe compiles for 0.3-5 s a row; ``benchmarks/slow_checks.sh`` runs the rest)."""
    seen, out = set(), []
    for c in CASES:
        model = c.build()[0]
        kind = (c.model, model.channel_separable)
        per_option = c.model in {"disney", "gltf", "principled", "openpbr"}
        fast = kind == ("walter", True) and kind not in seen or per_option and kind not in seen
        seen.add(kind)
        out.append(pytest.param(c, id=c.id, marks=() if fast else pytest.mark.slow))
    # He et al. is in no generic row (its series compiles for long)
    return [*out, pytest.param(Case("he"), id="he", marks=pytest.mark.slow)]


def _draws(model, rng, n: int) -> list[dict]:
    """The defaults and ``n - 1`` draws inside each parameter's bounds (a twentieth in from
    each finite bound; up to three times the default above an open one)."""
    out = [model.defaults()]
    for _ in range(n - 1):
        p = {}
        for q in model.parameters:
            lo, hi = q.bounds
            hi = hi if np.isfinite(hi) else lo + 3.0 * max(1.0, abs(q.default))
            pad = 0.05 * (hi - lo)
            p[q.name] = jnp.asarray(rng.uniform(lo + pad, hi - pad, size=q.shape))
        out.append(p)
    return out


@pytest.mark.parametrize("case", _checked_rows())
def test_channel_separable_is_what_the_derivatives_show(case):
    """A NaN tangent on one channel of an RGB parameter reaches every output the value
    depends on through arithmetic (NaN times anything is NaN): a separable model must
    leave the other channels' tangents exactly zero at every draw, and a model declared
    not separable must show a channel reaching another at some draw (else the
    declaration costs speed for nothing)."""
    model, _ = case.build()
    g = shading_geometry(jnp.asarray(WI), jnp.asarray(WO))
    rgb = [q for q in model.parameters if q.shape == (3,)]
    if not rgb:
        pytest.skip("no RGB parameter")
    tangents = []
    for q in rgb:
        for c in range(3):
            t = {p.name: jnp.zeros(p.shape) for p in model.parameters}
            t[q.name] = t[q.name].at[c].set(jnp.nan)
            tangents.append((q.name, c, t))
    stacked = jax.tree.map(lambda *a: jnp.stack(a), *[t for _, _, t in tangents])

    @jax.jit
    def reach(p):
        def one(t):
            return jax.jvp(lambda pp: model.evaluate(pp, g), (p,), (t,))[1]

        return jnp.isnan(jax.vmap(one)(stacked)).any(axis=1)  # (tangents, 3)

    crossed = set()
    for p in _draws(model, np.random.default_rng(0), 4):
        hit = np.asarray(reach({k: jnp.asarray(v, float) for k, v in p.items()}))
        for (name, c, _), row in zip(tangents, hit, strict=True):
            assert row[c], f"{case.id}: {name}[{c}] does not reach its own channel"
            crossed |= {f"{name}[{c}] -> {o}" for o in range(3) if o != c and row[o]}
    if model.channel_separable:
        assert not crossed, f"{case.id} is declared channel_separable: {sorted(crossed)}"
    else:
        assert crossed, f"{case.id} could be declared channel_separable"


def test_colouring_groups_the_channels_of_a_parameter_and_nothing_else():
    free = models.get("walter").parameters  # kd, ks, f0 RGB; alpha
    col = Colouring.of(free, separable=True)
    assert col.colour == (0, 0, 0, 1, 1, 1, 2, 2, 2, 3)
    assert col.channel == (0, 1, 2, 0, 1, 2, 0, 1, 2, -1)
    plain = Colouring.of(free, separable=False)
    assert plain.colour == tuple(range(10)) and set(plain.channel) == {-1}


@pytest.mark.parametrize(
    "name,options", [("walter", {}), ("disney", {"subsurface": False, "anisotropic": False})]
)
def test_jacobian_and_normal_equations_equal_plain_forward_mode(name, options):
    """Separable (walter, 4 passes for 10 scalars) and not (Disney with its tints, one
    pass per scalar): ``J``, ``J^T W r`` and ``J^T W J`` under a robust loss, and the
    covariance's moments in natural units, against dense forward-mode references."""
    model = models.get(name, **options)
    truth = {p.name: np.full(p.shape, p.default) for p in model.parameters}
    data = synthesize(model, truth, stride=(9, 9, 15), noise_mult=0.05, seed=2)
    prep = prepare(data, get_metric("low_e2"), cut_deg=80.0)
    obj = Objective.build(model).with_robust("cauchy", 0.01)
    z = jnp.asarray(obj.layout.to_solver(obj.layout.join(truth))) * 1.01
    ids, n_blocks = block_index(prep)
    chunks = BlockChunks.of(ids, n_blocks)

    @jax.jit
    def both(z, prep, chunks):
        ours = (
            obj.jacobian(z, prep), obj.linearize(z, prep), obj.cost(z, prep),
            obj.natural_moments(z, prep), obj.natural_block_moments(z, prep, chunks),
        )  # fmt: skip
        r = obj.residuals(z, prep)
        jac = jax.jacfwd(lambda zz: obj.residuals(zz, prep))(z)
        w = robust_mod.robust_weights(r, obj.robust, obj.scale)

        def robust(xn):
            rr = obj.residuals(obj.layout.to_solver(xn), prep)
            return robust_mod.robust_residuals(rr, obj.robust, obj.scale)

        x = obj.layout.from_solver(z)
        return ours, (jac, (jac * w[:, None]).T @ r, (jac * w[:, None]).T @ jac,
                      jax.jacfwd(robust)(x), robust(x))  # fmt: skip

    ours, (jac, g_ref, h_ref, jn, en) = jax.tree.map(np.asarray, both(z, prep, chunks))
    (_, j_ours), (cost, g, h), cost_ref, (jtj, meat, ee, _, grad), (jtj_b, _, scores, grams) = ours
    np.testing.assert_allclose(j_ours, jac, rtol=1e-13, atol=1e-13 * np.max(np.abs(jac)))
    np.testing.assert_allclose(cost, cost_ref, rtol=1e-14)
    np.testing.assert_allclose(g, g_ref, rtol=1e-12)
    np.testing.assert_allclose(h, h_ref, rtol=1e-12)
    np.testing.assert_allclose(jtj, jn.T @ jn, rtol=1e-12)
    np.testing.assert_allclose(meat, (jn * en[:, None] ** 2).T @ jn, rtol=1e-12)
    np.testing.assert_allclose(ee, en @ en, rtol=1e-13)
    np.testing.assert_allclose(grad, jn.T @ en, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(jtj_b, jn.T @ jn, rtol=1e-12)
    rows = np.repeat(ids, 3)
    for b in (0, n_blocks // 2, n_blocks - 1):
        jb, eb = jn[rows == b], en[rows == b]
        np.testing.assert_allclose(scores[b], jb.T @ eb, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(grams[b], jb.T @ jb, rtol=1e-11, atol=1e-14)
