"""Which fitted scalars the data leave undetermined: a standard error compared with the
parameter's allowed range, every scalar that moves along a null direction of J, and the
"not identified" flag and warning a result carries."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from brdffit import FitResult, Measurements, Status, models, synthesize
from brdffit.engine import metrics as metrics_mod
from brdffit.engine.assembly import Outcome, assemble, unidentified
from brdffit.engine.objective import Objective, freeze_map
from brdffit.engine.uncertainty import conditioning, covariance


def _result_at(
    model, params: dict, data: Measurements, freeze: dict | None = None, *,
    held: tuple = (), errors: str = "classic",
) -> FitResult:  # fmt: skip
    """The FitResult of ``model`` at ``params`` (no descent): the real error path, with
    the scalars of the parameters ``held`` held on a bound by the active set."""
    params = {k: jnp.asarray(v, float) for k, v in params.items()}
    obj = Objective.build(model, freeze_map(model, freeze, params))
    z = obj.layout.solver_vector(params)
    binding = np.array([lab.split("[")[0] in held for lab in obj.layout.labels()], bool)
    out = Outcome(
        z=z, status=Status.CONVERGED, binding=binding, start=obj.params(jnp.asarray(z)),
        n_steps=0, n_starts=1, coarse=(0, 0), robust_scale=None,
    )  # fmt: skip
    preps = metrics_mod.prepare_all(data, cut_deg=80.0)
    return assemble(
        obj, metrics_mod.get_metric("low_e2"), out, preps, errors=errors, cut=80.0,
        source="test", t0=time.perf_counter(),
    )  # fmt: skip


def test_a_scalar_with_an_enormous_error_is_named_not_identified_and_warned():
    # the specular lobe's weight at 1e-13: its exponent n barely moves the residuals, so
    # its column of J is tiny but not zero; J^T J scaled by its own columns is perfectly
    # conditioned (the old rule saw nothing), while the error of n is enormous
    bp = models.get("blinn_phong")
    truth = {"kd": [0.2, 0.3, 0.4], "ks": [1e-13] * 3, "n": 50.0}
    data = synthesize(bp, truth, stride=(9, 9, 9), noise_mult=0.03, seed=5)
    r = _result_at(bp, truth, data, {"ks": truth["ks"]})
    assert float(r.stderr["n"]) > 1e6 * 50.0
    assert r.condition_number < 10  # why the column-scaled eigen rule misses it
    assert r.not_identified == ("n",)
    assert any("not identified by the data: n" in w for w in r.warnings)
    assert "[not identified" in next(x for x in r.report().splitlines() if "    n " in x)


def test_unidentified_rule_compares_the_error_with_the_allowed_range():
    layout = Objective.build(models.get("walter")).layout
    labels = layout.labels()
    params = {"kd": np.array([0.2, 0.3, 0.4]), "f0": np.full(3, 0.5), "alpha": 0.01}
    params["ks"] = np.ones(3)
    params = {p.name: params[p.name] for p in layout.free}
    sd = np.full(len(labels), 1e-3)
    sd[labels.index("kd[g]")] = 1.5  # kd spans [0, 1]: wider than the whole range
    sd[labels.index("f0[r]")] = 0.9  # inside the range: identified, if loosely
    sd[labels.index("alpha")] = 0.02  # a scale fitted in ln alpha: 200% of its value
    sd[labels.index("kd[b]")] = np.nan  # held on a bound: the at-bound flag's business
    assert unidentified(layout, params, sd) == ["kd[g]", "alpha"]
    # the column-scaled rule of covariance() cannot see a tiny column
    jtj = np.diag([1.0, 1e-30])
    assert not covariance(jtj, jtj, 1.0, 100, "classic")[3].any()


def test_every_scalar_that_moves_along_a_null_direction_is_named():
    # J's columns 0-2 are dependent along v; column 3 is free of it. Scalar 2 moves little
    # along v (8% of the unit vector, under the old rule's 0.3), yet the data fix it no
    # better than the others: all of its variance lies on that direction.
    rng = np.random.default_rng(3)
    v = np.array([1.0, 0.3, 0.08, 0.0])
    v /= np.linalg.norm(v)
    a = rng.normal(size=(60, 4))
    a -= np.outer(a @ v, v)  # J v = 0
    cond, reason, weak = conditioning(a.T @ a)
    assert reason is not None and cond > 1e15
    assert weak.tolist() == [True, True, True, False]


def _sandwich(model, params: dict, data: Measurements, keep: np.ndarray) -> np.ndarray:
    """``A^-1 J^T diag(e^2) J A^-1`` (``A = J^T J``) over the scalars ``keep``, from JAX's
    own Jacobian over all."""
    obj = Objective.build(model)
    layout = obj.layout
    prep = metrics_mod.prepare(data, metrics_mod.get_metric("low_e2"), cut_deg=80.0)
    x = jnp.asarray(layout.natural_vector({k: jnp.asarray(v, float) for k, v in params.items()}))
    e = obj.residuals(layout.to_solver(x), prep)
    jac = np.asarray(jax.jacfwd(lambda xn: obj.residuals(layout.to_solver(xn), prep))(x))
    j, e = jac[:, keep], np.asarray(e)
    bread = np.linalg.inv(j.T @ j)
    return bread @ (j.T * e**2) @ j @ bread


def test_errors_beside_a_loosely_held_scalar_are_its_marginal_block():
    """``f0`` held at its bound 1, where the data's own optimum is (the truth): the
    unbounded step moves it out by less than 1.96 of its errors, so it is uncertain
    towards the inside and the free scalars' covariance is their block of the one over
    all ten scalars (Andrews 1999), checked against the sandwich from JAX's own
    Jacobian; ``ks``, which trades off against ``f0`` (the lobe's colour ``ks f0`` near
    normal incidence), is wider than conditional on the held value."""
    walter = models.get("walter")
    truth = {"kd": [0.2, 0.3, 0.4], "ks": [0.3] * 3, "f0": [1.0] * 3, "alpha": 0.1}
    data = synthesize(walter, truth, stride=(9, 9, 9), noise_mult=0.03, seed=5)
    r = _result_at(walter, truth, data, held=("f0",), errors="sandwich")
    held = np.array([lab.startswith("f0") for lab in r.labels])
    full = _sandwich(walter, truth, data, np.ones(held.size, bool))
    conditional = _sandwich(walter, truth, data, ~held)
    ix = np.ix_(~held, ~held)
    np.testing.assert_allclose(r.covariance[ix], full[ix], rtol=1e-8)
    assert np.all(np.isnan(r.covariance[held])) and np.all(np.isnan(r.stderr["f0"]))
    ks = [lab.startswith("ks") for lab in np.array(r.labels)[~held]]
    assert np.all(np.sqrt(np.diag(conditional))[ks] < 0.8 * r.stderr["ks"])


def test_errors_beside_a_firmly_held_scalar_are_conditional_on_it():
    """``ks`` held at its bound 1 while the data's lobe has weight 1.5: the unbounded step
    takes it far beyond, the bound binds in every replication, and the free scalars'
    covariance is the one conditional on the held value (over the free scalars only)."""
    walter = models.get("walter")
    at = {"kd": [0.2, 0.3, 0.4], "ks": [1.0] * 3, "f0": [0.3] * 3, "alpha": 0.1}
    base = synthesize(walter, at, stride=(9, 9, 9))
    extra = synthesize(walter, {**at, "kd": [0.0] * 3, "ks": [0.5] * 3}, stride=(9, 9, 9))
    rng = np.random.default_rng(5)
    values = (base.values + extra.values) * np.exp(0.03 * rng.standard_normal(base.values.shape))
    data = Measurements.from_directions(base.wi, base.wo, values)
    r = _result_at(walter, at, data, held=("ks",), errors="sandwich")
    held = np.array([lab.startswith("ks") for lab in r.labels])
    conditional = _sandwich(walter, at, data, ~held)
    np.testing.assert_allclose(r.covariance[np.ix_(~held, ~held)], conditional, rtol=1e-8)
