"""NBRDF Keras files: the network, its errors, and conversion to a MERL table.

Tests on a small synthetic Keras pair written here run everywhere; tests on the
published reconstructions use the ``nbrdf_dir`` fixture and skip without them.
"""

from __future__ import annotations

import functools
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from brdffit import MeasurementFileError, MissingDependencyError, read_merl, read_nbrdf
from brdffit.core.geometry import MERL_SHAPE, halfdiff_to_io
from brdffit.io.merl_grid import merl_grid
from brdffit.io.nbrdf import NBRDF, nbrdf_to_merl
from tests.helpers import fails_cleanly

h5py = pytest.importorskip("h5py")

# The Lambda layer of the published files: base64 of the marshalled
# ``lambda x_: K.exp(x_) - 1`` (Keras 2.2.4, Python 3.7).
EXPM1_LAMBDA = (
    "4wEAAAAAAAAAAQAAAAMAAABTAAAAcw4AAAB0AKABfAChAWQBGABTACkCTukBAAAAKQLaAUvaA2V4\n"
    "cCkB2gJ4X6kAcgUAAAD6Ey4vbWVybF9yZWdyZXNzb3IucHnaCDxsYW1iZGE+VAAAAPMAAAAA\n"
)
MATERIAL = "alum-bronze"


def _architecture(units=(21, 21, 3), lam: str | None = EXPM1_LAMBDA) -> dict:
    acts = ["relu"] * (len(units) - 1) + ["linear"]
    layers = []
    for i, (u, a) in enumerate(zip(units, acts, strict=True)):
        cfg = {"name": f"dense_{i + 1}", "units": u, "activation": a, "use_bias": True}
        if i == 0:
            cfg["batch_input_shape"] = [None, 6]
        layers.append({"class_name": "Dense", "config": cfg})
    if lam is not None:
        fn = [lam, None, None]
        cfg = {"name": "lambda_1", "function": fn, "function_type": "lambda"}
        layers.append({"class_name": "Lambda", "config": cfg})
    return {"class_name": "Sequential", "config": {"name": "seq", "layers": layers}}


def _write_keras(stem: Path, weights: list[tuple[np.ndarray, np.ndarray]], arch: dict) -> Path:
    """A Keras 2 ``save_weights`` file and its JSON, as the NBRDF scripts write them."""
    stem.with_suffix(".json").write_text(json.dumps(arch))
    with h5py.File(stem.with_suffix(".h5"), "w") as f:
        names = [f"dense_{i + 1}" for i in range(len(weights))]
        f.attrs["layer_names"] = np.array([n.encode() for n in names])
        for name, (kernel, bias) in zip(names, weights, strict=True):
            g = f.create_group(name)
            g.attrs["weight_names"] = np.array(
                [f"{name}/kernel:0".encode(), f"{name}/bias:0".encode()]
            )
            g[f"{name}/kernel:0"] = kernel.astype(np.float32)
            g[f"{name}/bias:0"] = bias.astype(np.float32)
    return stem


def _random_weights(seed: int = 0, units=(21, 21, 3)) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    sizes = (6, *units)
    return [
        (rng.normal(0, 0.5, (a, b)).astype(np.float32), rng.normal(0, 0.1, b).astype(np.float32))
        for a, b in zip(sizes[:-1], sizes[1:], strict=True)
    ]


def _by_hand(weights: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
    """relu, relu, linear, exp(x) - 1, written out in float64."""
    (k1, b1), (k2, b2), (k3, b3) = [(k.astype(float), b.astype(float)) for k, b in weights]
    h = np.maximum(x @ k1 + b1, 0)
    h = np.maximum(h @ k2 + b2, 0)
    return np.exp(h @ k3 + b3) - 1


def _inputs(theta_h, theta_d, phi_d) -> np.ndarray:
    return np.stack(
        [
            np.sin(theta_h),
            np.zeros_like(theta_h),
            np.cos(theta_h),
            np.sin(theta_d) * np.cos(phi_d),
            np.sin(theta_d) * np.sin(phi_d),
            np.cos(theta_d),
        ],
        axis=-1,
    )


def _angles(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(0, np.pi / 2, n), rng.uniform(0, np.pi / 2, n), rng.uniform(0, np.pi, n)


@pytest.fixture
def synthetic(tmp_path) -> tuple[Path, list]:
    weights = _random_weights()
    return _write_keras(tmp_path / "toy", weights, _architecture()), weights


# --------------------------------------------------------------------------- synthetic file


def test_reads_layers_from_the_json(synthetic):
    stem, weights = synthetic
    for path in (stem, stem.with_suffix(".json"), stem.with_suffix(".h5")):
        net = read_nbrdf(path)
        assert net.name == "toy" and net.output == "exp(x) - 1"
        assert [lay.activation for lay in net.layers] == ["relu", "relu", "linear"]
        assert [lay.kernel.shape for lay in net.layers] == [(6, 21), (21, 21), (21, 3)]


def test_forward_matches_a_hand_written_pass(synthetic):
    stem, weights = synthetic
    net = read_nbrdf(stem)
    x = _inputs(*_angles(5000))
    # Same float64 arithmetic in another order (blocks, in-place bias): a few ulp.
    np.testing.assert_allclose(net.forward(x), _by_hand(weights, x), rtol=1e-12, atol=1e-14)


def test_eval_clamps_and_zeroes_below_horizon(synthetic):
    net = read_nbrdf(synthetic[0])
    th, td, pd = _angles(20_000, seed=1)
    raw = net.forward(_inputs(th, td, pd))
    got = net.eval_halfdiff(th, td, pd)
    wi, wo = halfdiff_to_io(th, td, pd)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert (raw[above] < 0).any(), "the toy weights should give some negative outputs"
    np.testing.assert_array_equal(got[above], np.maximum(raw[above], 0))
    assert (got[~above] == 0).all()
    # eval(wi, wo) recomputes the angles from the directions: agreement to round-off.
    np.testing.assert_allclose(net.eval(wi, wo), got, rtol=1e-9, atol=1e-12)
    assert net.eval_halfdiff(
        th.reshape(100, 200), td.reshape(100, 200), pd.reshape(100, 200)
    ).shape == (100, 200, 3)


def test_to_measurements_on_grid_and_directions(synthetic):
    net = read_nbrdf(synthetic[0])
    g = merl_grid((9, 9, 9))
    coarse = net.to_measurements("merl", stride=(9, 9, 9))
    assert coarse.grid is None and coarse.n == g.n
    np.testing.assert_array_equal(coarse.weights, g.weights)
    # The grid path adds the separable first layer in another order: round-off only.
    np.testing.assert_allclose(
        coarse.values, net.eval_halfdiff(g.theta_h, g.theta_d, g.phi_d), rtol=1e-12, atol=1e-14
    )
    direct = net.to_measurements((g.wi, g.wo))
    np.testing.assert_allclose(
        direct.values[g.above], coarse.values[g.above], rtol=1e-9, atol=1e-12
    )


def test_missing_h5py_names_the_extra(synthetic, monkeypatch):
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(ImportError, match=r"pip install brdffit\[nbrdf\]"):
        read_nbrdf(synthetic[0])


def test_nbrdf_without_h5py_raises_missing_dependency(tmp_path, monkeypatch, capsys):
    stem = _write_keras(tmp_path / "toy", _random_weights(), _architecture())
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(MissingDependencyError, match=r"brdffit\[nbrdf\]"):
        read_nbrdf(stem)
    fails_cleanly(capsys, ["info", stem.with_suffix(".json")], "h5py")


def _corrupt(stem: Path, case: str) -> Path:
    """Break one thing in a good pair; return the file the error must name."""
    js, h5 = stem.with_suffix(".json"), stem.with_suffix(".h5")
    if case == "missing json":
        js.unlink()
        return js
    if case == "missing h5":
        h5.unlink()
        return h5
    if case == "bad json":
        js.write_text('{"class_name": "Sequential", "config": {"layers": [')
        return js
    if case == "bad h5":
        h5.write_bytes(b"\x00garbage" * 100)
        return h5
    if case == "units mismatch":
        js.write_text(json.dumps(_architecture(units=(22, 21, 3))))
        return h5
    if case == "unknown lambda":
        js.write_text(json.dumps(_architecture(lam="AAAA")))
        return js
    if case == "unknown activation":
        arch = _architecture()
        arch["config"]["layers"][1]["config"]["activation"] = "selu"
        js.write_text(json.dumps(arch))
        return js
    raise AssertionError(case)


CORRUPTIONS = {
    "missing json": "no such file",
    "missing h5": "no such file",
    "bad json": "not valid JSON",
    "bad h5": "not a readable HDF5",
    "units mismatch": "kernel has shape (6, 21)",
    "unknown lambda": "not the exp(x) - 1",
    "unknown activation": "'selu'",
}


@pytest.mark.parametrize("case", CORRUPTIONS)
def test_bad_files_raise_naming_the_file(synthetic, case):
    named = _corrupt(synthetic[0], case)
    with pytest.raises(MeasurementFileError) as e:
        read_nbrdf(synthetic[0])
    assert e.value.path == str(named)
    assert CORRUPTIONS[case] in str(e.value), str(e.value)


# --------------------------------------------------------------------------- published files


@functools.cache
def _published(folder: str) -> tuple[NBRDF, object]:
    net = read_nbrdf(Path(folder) / MATERIAL)
    return net, net.to_measurements("merl")


def test_published_network_matches_a_hand_written_pass(nbrdf_dir):
    with h5py.File(nbrdf_dir / f"{MATERIAL}.h5", "r") as f:
        weights = [
            (f[f"dense_{i}/dense_{i}/kernel:0"][...], f[f"dense_{i}/dense_{i}/bias:0"][...])
            for i in (1, 2, 3)
        ]
    net, _ = _published(str(nbrdf_dir))
    x = _inputs(*_angles(5000))
    np.testing.assert_allclose(net.forward(x), _by_hand(weights, x), rtol=1e-12, atol=1e-14)


def test_published_values_positive_and_finite_on_the_merl_grid(nbrdf_dir):
    _, data = _published(str(nbrdf_dir))
    g = merl_grid()
    assert data.grid == MERL_SHAPE and data.n == g.n
    np.testing.assert_array_equal(data.valid, g.above)
    v = data.values[data.valid]
    assert np.isfinite(data.values).all() and (v >= 0).all()
    print(f"{MATERIAL}: min {v.min():.3g}, max {v.max():.4g} 1/sr, zeros {np.mean(v == 0):.2%}")
    assert np.mean(v == 0) < 0.01  # clamping is the exception, not the rule
    assert (data.values[~data.valid] == 0).all()


def test_published_to_merl_and_back(nbrdf_dir, tmp_path):
    _, data = _published(str(nbrdf_dir))
    out = tmp_path / f"{MATERIAL}.binary"
    written = nbrdf_to_merl(nbrdf_dir / MATERIAL, out)
    np.testing.assert_array_equal(written.values, data.values)
    back = read_merl(out)
    np.testing.assert_array_equal(back.valid, data.valid)
    # Network values are arbitrary floats: raw = v / s and back can be 1 ulp off
    # (see test_merl.test_round_trip_of_arbitrary_values_within_one_ulp).
    np.testing.assert_array_max_ulp(back.values[back.valid], data.values[data.valid], maxulp=1)


def test_corrupt_copy_of_a_published_file(nbrdf_dir, tmp_path):
    shutil.copy(nbrdf_dir / f"{MATERIAL}.json", tmp_path / "copy.json")
    data = (nbrdf_dir / f"{MATERIAL}.h5").read_bytes()
    (tmp_path / "copy.h5").write_bytes(data[: len(data) // 2])  # truncated weights
    with pytest.raises(MeasurementFileError) as e:
        read_nbrdf(tmp_path / "copy")
    assert str(tmp_path / "copy.h5") in str(e.value)
    with pytest.raises(MeasurementFileError, match="no such file") as e:
        read_nbrdf(nbrdf_dir / "no-such-material")
    assert "no-such-material.json" in str(e.value)
