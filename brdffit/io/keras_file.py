"""Keras model files of neural BRDFs: the JSON architecture and the HDF5 weights.

Each NBRDF material (Sztrajman et al. 2021, :mod:`brdffit.io.nbrdf`) is a Keras
``Sequential`` model: ``<name>.json`` (architecture) and ``<name>.h5`` (weights, Keras 2
``save_weights`` layout). The published MERL reconstructions are a 6-21-21-3 MLP, Dense
relu, Dense relu, Dense linear, then a Lambda layer ``K.exp(x) - 1``. The layer list is
read from the JSON (units, activation, use_bias), not assumed; the weights are checked
against it. :func:`read_keras_layers` returns the layers (:class:`DenseLayer`) and the
output transform, with the activations and transforms as numpy functions
(:data:`ACTIVATIONS`, :data:`OUTPUTS`). h5py is an optional dependency
(``pip install brdffit[nbrdf]``), imported only when weights are read.
"""

from __future__ import annotations

import base64
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float

from brdffit.errors import MeasurementFileError, MissingDependencyError

N_INPUTS: int = 6
N_OUTPUTS: int = 3


def _relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0, out=x)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "linear": lambda x: x,
    "relu": _relu,
    "tanh": np.tanh,
    "sigmoid": _sigmoid,
    "softplus": lambda x: np.logaddexp(0.0, x),
}
"""The activations a Dense layer may name, as numpy functions (``relu`` works in place)."""

# The Lambda layer is marshalled Python 3 bytecode. It is never executed: we recognise
# ``lambda x_: K.exp(x_) - 1`` by its instructions LOAD_GLOBAL K, LOAD_METHOD exp,
# LOAD_FAST x_, CALL_METHOD 1, LOAD_CONST 1, BINARY_SUBTRACT, RETURN_VALUE, the name
# ``exp`` and the constant int 1.
_EXPM1_BYTECODE = b"t\x00\xa0\x01|\x00\xa1\x01d\x01\x18\x00S\x00"
_EXPM1_MARKERS = (_EXPM1_BYTECODE, b"\xda\x03exp", b"\xe9\x01\x00\x00\x00")
OUTPUTS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "linear": lambda x: x,
    "exp(x) - 1": np.expm1,
}
"""Output transforms as numpy functions: none (``linear``) or the published ``exp(x) - 1``."""


@dataclass(frozen=True, eq=False)
class DenseLayer:
    """One Keras ``Dense`` layer: ``activation(x @ kernel + bias)``.

    Fields: ``name`` (Keras layer name), ``kernel`` (n_in, n_out) and ``bias`` (n_out,)
    as stored (float32, read-only; bias zero when the layer has none), ``activation``
    (a key of the supported activations: linear, relu, tanh, sigmoid, softplus).
    """

    name: str
    kernel: Float[np.ndarray, "n_in n_out"]
    bias: Float[np.ndarray, " n_out"]
    activation: str


def read_keras_layers(json_path: Path, h5_path: Path) -> tuple[tuple[DenseLayer, ...], str]:
    """The dense layers and the output transform (a key of :data:`OUTPUTS`) of a Keras pair.

    Arguments:
    - ``json_path``: the architecture, ``<stem>.json``.
    - ``h5_path``: the weights, ``<stem>.h5`` (needs h5py).

    Raises as :func:`brdffit.io.nbrdf.read_nbrdf`.
    """
    layer_specs, output = _parse_architecture(json_path)
    weights = _read_weights(h5_path, [s["name"] for s in layer_specs])
    layers = _build_layers(h5_path, layer_specs, weights)
    return layers, output


def _parse_architecture(json_path: Path) -> tuple[list[dict[str, Any]], str]:
    """Dense layer specs (name, units, activation, use_bias, n_in) and the output transform."""
    try:
        spec = json.loads(json_path.read_text())
    except FileNotFoundError:
        raise MeasurementFileError(json_path, "no such file (NBRDF architecture)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise MeasurementFileError(json_path, f"cannot be read: {e}") from None
    except json.JSONDecodeError as e:
        raise MeasurementFileError(json_path, f"not valid JSON: {e}") from None
    config = spec.get("config") if isinstance(spec, dict) else None
    raw_layers = config.get("layers") if isinstance(config, dict) else config
    if not isinstance(raw_layers, list) or not raw_layers:
        raise MeasurementFileError(
            json_path, "no layer list found; expected a Keras Sequential model JSON"
        )
    dense: list[dict[str, Any]] = []
    output = "linear"
    for i, layer in enumerate(raw_layers):
        kind = layer.get("class_name") if isinstance(layer, dict) else None
        cfg = layer.get("config", {}) if isinstance(layer, dict) else {}
        if not isinstance(cfg, dict):
            raise MeasurementFileError(json_path, f"layer {i} has a config that is not an object")
        if kind == "Dense" and output == "linear":
            dense.append(_dense_spec(json_path, i, cfg))
        elif kind == "Lambda" and i == len(raw_layers) - 1 and output == "linear":
            output = _lambda_output(json_path, cfg)
        else:
            raise MeasurementFileError(
                json_path,
                f"layer {i} ({kind}) is not supported; accepted: Dense layers, then at most "
                "one final Lambda layer exp(x) - 1",
            )
    if not dense:
        raise MeasurementFileError(json_path, "no Dense layer")
    return dense, output


def _dense_spec(json_path: Path, i: int, cfg: dict[str, Any]) -> dict[str, Any]:
    activation = cfg.get("activation", "linear")
    if not isinstance(activation, str) or activation not in ACTIVATIONS:
        raise MeasurementFileError(
            json_path,
            f"layer {i} has activation {activation!r}; accepted: {sorted(ACTIVATIONS)}",
        )
    units = cfg.get("units")
    if not isinstance(units, int) or units < 1:
        raise MeasurementFileError(
            json_path, f"layer {i} has units={units!r}; expected an int >= 1"
        )
    shape = cfg.get("batch_input_shape")
    n_in = shape[-1] if isinstance(shape, list) and shape else None
    if n_in is not None and (not isinstance(n_in, int) or isinstance(n_in, bool)):
        raise MeasurementFileError(
            json_path, f"layer {i} has batch_input_shape {shape!r}; expected [null, 6]"
        )
    return {
        "name": str(cfg.get("name", f"dense_{i + 1}")),
        "units": units,
        "activation": activation,
        "use_bias": bool(cfg.get("use_bias", True)),
        "n_in": n_in,
    }


def _lambda_output(json_path: Path, cfg: dict[str, Any]) -> str:
    function = cfg.get("function")
    code = function[0] if isinstance(function, list) and function else function
    try:
        payload = base64.b64decode(code) if isinstance(code, str) else b""
    except ValueError:
        payload = b""
    if cfg.get("function_type") != "lambda" or not all(m in payload for m in _EXPM1_MARKERS):
        raise MeasurementFileError(
            json_path,
            f"Lambda layer {cfg.get('name')!r} is not the exp(x) - 1 of Sztrajman et al. "
            "2021; other Python code is not evaluated",
        )
    return "exp(x) - 1"


def _read_weights(h5_path: Path, names: list[str]) -> dict[str, dict[str, np.ndarray]]:
    """``{layer: {"kernel": array, "bias": array}}`` from a Keras 2 weights file."""
    try:
        import h5py  # deferred: optional dependency
    except ImportError:
        raise MissingDependencyError(
            f"{h5_path}: reading NBRDF weights needs h5py; install it with: "
            "pip install brdffit[nbrdf]"
        ) from None
    if not h5_path.is_file():
        raise MeasurementFileError(h5_path, "no such file (NBRDF weights)")
    try:
        with h5py.File(h5_path, "r") as f:
            root = f["model_weights"] if "model_weights" in f else f
            return {name: _layer_weights(h5_path, root, name) for name in names}
    except MeasurementFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError, AttributeError) as e:
        # a damaged file fails anywhere inside h5py: all of them are "not readable"
        raise MeasurementFileError(h5_path, f"not a readable HDF5 weights file: {e}") from None


def _layer_weights(h5_path: Path, root: Any, name: str) -> dict[str, np.ndarray]:
    if name not in root:
        raise MeasurementFileError(h5_path, f"no weights for layer {name!r}")
    group = root[name]
    found: dict[str, np.ndarray] = {}
    for wname in group.attrs.get("weight_names", []):
        wname = wname.decode() if isinstance(wname, bytes) else str(wname)
        key = wname.rsplit("/", 1)[-1].split(":")[0]
        if key in ("kernel", "bias"):
            found[key] = np.asarray(group[wname])
    return found


def _build_layers(
    h5_path: Path, specs: list[dict[str, Any]], weights: dict[str, dict[str, np.ndarray]]
) -> tuple[DenseLayer, ...]:
    layers = []
    n_in = specs[0]["n_in"] or N_INPUTS
    if n_in != N_INPUTS:
        raise MeasurementFileError(h5_path, f"the model takes {n_in} inputs; expected {N_INPUTS}")
    for spec in specs:
        w = weights[spec["name"]]
        expected = {"kernel": (n_in, spec["units"])}
        if spec["use_bias"]:
            expected["bias"] = (spec["units"],)
        for key, shape in expected.items():
            got = w[key].shape if key in w else "missing"
            if got != shape:
                raise MeasurementFileError(
                    h5_path,
                    f"layer {spec['name']!r} {key} has shape {got}; the architecture "
                    f"(units={spec['units']}, {n_in} inputs) expects {shape}",
                )
        bias = w["bias"] if spec["use_bias"] else np.zeros(spec["units"], np.float32)
        kernel, bias = np.array(w["kernel"]), np.array(bias)
        if not (np.isfinite(kernel).all() and np.isfinite(bias).all()):
            raise MeasurementFileError(h5_path, f"layer {spec['name']!r} has NaN/Inf weights")
        kernel.setflags(write=False)
        bias.setflags(write=False)
        layers.append(DenseLayer(spec["name"], kernel, bias, spec["activation"]))
        n_in = spec["units"]
    if n_in != N_OUTPUTS:
        raise MeasurementFileError(h5_path, f"the model gives {n_in} outputs; expected {N_OUTPUTS}")
    return tuple(layers)
