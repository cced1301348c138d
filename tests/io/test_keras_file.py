"""Keras files of an NBRDF read into dense layers; the activations as numpy functions.

The reader's errors on broken pairs are tested through :func:`brdffit.io.nbrdf.read_nbrdf`
in ``test_nbrdf.py``, whose small synthetic Keras pair is used here.
"""

from __future__ import annotations

import numpy as np

from brdffit.io.keras_file import ACTIVATIONS, OUTPUTS, read_keras_layers
from tests.io.test_nbrdf import _architecture, _random_weights, _write_keras


def test_layers_as_stored_and_no_lambda_is_a_linear_output(tmp_path):
    weights = _random_weights(units=(5, 3))
    stem = _write_keras(tmp_path / "toy", weights, _architecture(units=(5, 3), lam=None))
    layers, output = read_keras_layers(stem.with_suffix(".json"), stem.with_suffix(".h5"))
    assert output == "linear"
    assert [(lay.name, lay.activation) for lay in layers] == [
        ("dense_1", "relu"),
        ("dense_2", "linear"),
    ]
    for lay, (kernel, bias) in zip(layers, weights, strict=True):
        assert lay.kernel.dtype == np.float32 and not lay.kernel.flags.writeable
        np.testing.assert_array_equal(lay.kernel, kernel)
        np.testing.assert_array_equal(lay.bias, bias)


def test_activations_and_outputs_as_numpy_functions():
    x = np.array([-2.0, 0.0, 3.0])
    np.testing.assert_allclose(ACTIVATIONS["sigmoid"](x), 1 / (1 + np.exp(-x)), rtol=1e-15)
    np.testing.assert_allclose(ACTIVATIONS["softplus"](x), np.log1p(np.exp(x)), rtol=1e-15)
    np.testing.assert_array_equal(ACTIVATIONS["relu"](x.copy()), [0.0, 0.0, 3.0])
    np.testing.assert_array_equal(ACTIVATIONS["linear"](x), x)
    np.testing.assert_array_equal(OUTPUTS["exp(x) - 1"](x), np.expm1(x))
