"""brdffit.models.check and ``brdffit check``: real models pass, broken ones are flagged by name."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import pytest

from brdffit import ParameterError, models
from brdffit.cli import main
from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models.check import CheckRow, check_model, check_params, extreme_pairs, format_table

KD = Parameter("kd", (3,), (0.0, 1.0), 0.5, "logit", "diffuse albedo, RGB")
ROUGH = Parameter("rough", (), (0.0, 1.0), 0.5, "logit", "a made-up roughness")


class NegativeAtGrazing(AbstractModel):
    """Lambert minus 2/pi where the view is within ~0.06 degrees of the horizon."""

    name: ClassVar[str] = "negative_at_grazing"
    reference: ClassVar[str] = "test"

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD,)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        dip = jnp.where(g.cos_o < 1e-3, 2.0, 0.0).astype(g.cos_o.dtype)
        return (params["kd"][None, :] - dip[:, None]) / jnp.pi


class SqrtRough(AbstractModel):
    """Lambert plus ``sqrt(rough)``: finite values, infinite d f / d rough at rough = 0."""

    name: ClassVar[str] = "sqrt_rough"
    reference: ClassVar[str] = "test"

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD, ROUGH)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        f = params["kd"] / jnp.pi + jnp.sqrt(params["rough"])
        return jnp.broadcast_to(f, g.cos_i.shape + (3,))


class LeaksBelowHorizon(AbstractModel):
    """A constant that skips the horizon mask of :meth:`AbstractModel.evaluate`."""

    name: ClassVar[str] = "leaks_below_horizon"
    reference: ClassVar[str] = "test"

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD,)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        return jnp.broadcast_to(params["kd"] / jnp.pi, g.cos_i.shape + (3,))

    def evaluate(self, params: Params, g: ShadingGeometry) -> jax.Array:
        return self.core(params, g)


class GrazingPower(AbstractModel):
    """Lambert plus ``(1 / cos_o)^(60 rough)``: overflows at grazing for large ``rough``.

    ``rough = 1`` at cos_o = 1e-6 is 1e360, past every float (3e26 at cos_o 0.36);
    ``sign`` = -1 makes the same value NaN instead (``inf - inf``), the defect the check
    must still catch.
    """

    sign: float = 1.0
    name: ClassVar[str] = "grazing_power"
    reference: ClassVar[str] = "test"

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD, ROUGH)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        big = jnp.exp(-60.0 * params["rough"] * jnp.log(g.cos_o))
        spike = big if self.sign > 0 else big - big
        return params["kd"][None, :] / jnp.pi + spike[:, None]


@pytest.mark.parametrize("name", ["lambert", "walter"])
def test_real_models_pass_every_set_and_dtype(name):
    rows = check_model(models.get(name))
    n_pairs = extreme_pairs()[0].shape[0]
    assert [(r.params, r.dtype) for r in rows] == [
        (s, d) for s in ("defaults", "low", "high") for d in ("float32", "float64")
    ]
    for r in rows:
        assert r.passed and r.note == "" and r.n == n_pairs, r
        assert r.max_f >= 0
    assert "FAIL" not in format_table(rows)


def test_negative_values_at_grazing_fail_and_name_the_pairs():
    rows = check_model(NegativeAtGrazing(), "float64")
    assert [r.dtype for r in rows] == ["float64"] * 3
    for r in rows:
        assert not r.passed and r.nonfinite_f == 0 and r.nonfinite_grad == 0
        # Pairs whose wo is grazing: normal/grazing, grazing=grazing, /mirror, /90deg.
        assert r.negative_f == 4 and "normal/grazing" in r.bad_pairs
        assert "bad f at: normal/grazing" in r.note
    assert "FAIL" in format_table(rows)


def test_overflow_to_inf_is_counted_apart_and_allowed_but_nan_fails():
    high = {"kd": jnp.full(3, 0.5), "rough": jnp.asarray(1.0)}
    for dtype in ("float32", "float64"):
        over = check_params(GrazingPower(), high, dtype, "high")
        # wo grazing: normal/grazing, grazing=grazing, grazing/mirror, grazing/90deg
        assert over.passed and over.overflow_f == 4 and over.nonfinite_f == 0, over
        assert over.nonfinite_grad == 0  # gradients over the finite pairs
        assert "overflow (+inf, allowed) at: normal/grazing" in over.note
        nan = check_params(GrazingPower(sign=-1.0), high, dtype, "high")
        assert not nan.passed and nan.nonfinite_f == 4 and nan.overflow_f == 0, nan


def test_nonfinite_gradient_names_its_parameter_only():
    rows = {(r.params, r.dtype): r for r in check_model(SqrtRough())}
    for dtype in ("float32", "float64"):
        low = rows[("low", dtype)]
        assert not low.passed and low.bad_grad == ("rough",), low
        assert low.nonfinite_f == 0 and low.negative_f == 0 and low.nonfinite_grad == 1
        assert "nonfinite grad: rough" in low.note
        assert rows[("defaults", dtype)].passed and rows[("high", dtype)].passed


def test_values_below_horizon_must_be_zero():
    row = check_model(LeaksBelowHorizon(), "float32")[0]
    assert not row.passed and row.below_horizon_nonzero > 0 and "below horizon" in row.note


def test_table_formats_and_bad_arguments():
    rows = check_model(models.get("lambert"), "float64")
    csv_lines = format_table(rows, "csv").splitlines()
    assert csv_lines[0].startswith("model,params,dtype,n,") and len(csv_lines) == 4
    md = format_table(rows, "markdown").splitlines()
    assert md[0].startswith("| model | params |") and md[1].startswith("|---|")
    assert isinstance(rows[0], CheckRow)
    with pytest.raises(ParameterError, match="float16"):
        check_model(models.get("lambert"), "float16")
    with pytest.raises(ParameterError, match="fmt='latex'"):
        format_table(rows, "latex")


def test_cli_check_lambert_prints_a_table_and_exits_0(capsys):
    code = main(["check", "lambert"])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].split()[:3] == ["model", "params", "dtype"]
    assert sum(line.startswith("lambert ") for line in lines) == 6
    assert "6/6 checks passed" in out and "FAIL" not in out


def test_cli_check_markdown_one_dtype(capsys):
    code = main(["check", "lambert", "--dtype", "float32", "--format", "markdown"])
    out, _ = capsys.readouterr()
    assert code == 0 and out.count("| lambert |") == 3 and "float64" not in out


def test_cli_check_exits_1_when_a_check_fails(capsys, monkeypatch):
    import brdffit.cli.commands as cli

    monkeypatch.setattr(cli, "_model", lambda name, options: SqrtRough())
    code = main(["check", "sqrt_rough", "--dtype", "float64"])
    out, _ = capsys.readouterr()
    assert code == 1 and "FAIL" in out and "nonfinite grad: rough" in out


def test_cli_check_unknown_model_is_one_line_and_exit_2(capsys):
    code = main(["check", "lambert", "nope"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "unknown model 'nope'" in err


def test_cli_check_a_variant_labels_its_rows(capsys):
    code = main(["check", "lafortune[n_lobes=2]", "--dtype", "float64", "--format", "csv"])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    assert [line.split(",")[0] for line in out.splitlines()[1:]] == ["lafortune[n_lobes=2]"] * 3
