"""Neural BRDFs (NBRDF, Sztrajman et al. 2021) stored as Keras files, evaluated in numpy.

Sztrajman, Rainer, Ritschel, Weyrich, "Neural BRDF Representation and Importance
Sampling", Computer Graphics Forum 40(6), 2021. Each material is a Keras ``Sequential``
model: ``<name>.json`` (architecture) and ``<name>.h5`` (weights), read by
:mod:`brdffit.io.keras_file`: the layer list is read from the JSON, not assumed; the
weights are checked against it.

Input per sample: ``(hx, hy, hz, dx, dy, dz)``, the half vector with ``phi_h = 0``,
``(sin th, 0, cos th)``, and the difference vector ``(sin td cos pd, sin td sin pd, cos td)``
(the network was trained on ``phi_d`` over [0, 2 pi), so unfolded angles are fine).
Output: RGB BRDF in 1/sr, no cosine, MERL channel scales already applied.

``exp(x) - 1`` is slightly negative where the network's last layer is (down to -1):
evaluation clamps such outputs to 0 (a BRDF is non-negative) and returns 0 below the
horizon. :meth:`NBRDF.forward` is the raw network, without either.

Evaluation is numpy float64 (float32 weights as stored, upcast) in chunks of
:data:`CHUNK` rows: small matrix products stay single-threaded in OpenBLAS, which on
two busy cores measured faster than both large blocks and a jitted JAX version (see
``benchmarks/read_merl.py``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike, Float

from brdffit.core.geometry import io_to_halfdiff
from brdffit.core.measurements import Measurements
from brdffit.errors import ParameterError
from brdffit.io.keras_file import ACTIVATIONS, N_OUTPUTS, OUTPUTS, DenseLayer, read_keras_layers
from brdffit.io.merl import write_merl
from brdffit.io.merl_grid import MerlGrid, merl_grid, merl_grid_measurements

CHUNK: int = 2048
"""Rows per block in :meth:`NBRDF.forward` (keeps OpenBLAS on one thread per product)."""


@dataclass(frozen=True, eq=False)
class NBRDF:
    """A neural BRDF: a stack of dense layers and an output transform.

    Fields: ``name`` (material, the file stem), ``source`` (the JSON path), ``layers``
    (:class:`DenseLayer` tuple, 6 inputs to 3 outputs), ``output`` (``"exp(x) - 1"`` for
    the published files, or ``"linear"`` when the model has no Lambda layer).
    """

    name: str
    source: str
    layers: tuple[DenseLayer, ...]
    output: str

    def forward(self, inputs: Float[ArrayLike, "n 6"]) -> Float[np.ndarray, "n 3"]:
        """The raw network on (hx, hy, hz, dx, dy, dz) rows: no clamping, no horizon.

        Arguments:
        - ``inputs``: (n, 6) half and difference vectors, see the module docstring.

        Returns: (n, 3) float64 network outputs (1/sr for the published files).
        """
        x = np.asarray(inputs, dtype=np.float64)
        prepared = self._prepared()
        out_fn = OUTPUTS[self.output]
        out = np.empty((x.shape[0], N_OUTPUTS))
        for start in range(0, x.shape[0], CHUNK):
            out[start : start + CHUNK] = out_fn(_apply(x[start : start + CHUNK], prepared))
        return out

    def _prepared(self) -> list[tuple[np.ndarray, np.ndarray, Callable[[np.ndarray], np.ndarray]]]:
        """(kernel, bias, activation) per layer, weights upcast to float64."""
        return [
            (
                lay.kernel.astype(np.float64),
                lay.bias.astype(np.float64),
                ACTIVATIONS[lay.activation],
            )
            for lay in self.layers
        ]

    def _grid_values(self, g: MerlGrid) -> np.ndarray:
        """(N, 3) clamped values on a MERL grid, 0 below the horizon.

        The first layer is separable on a grid: with ``hy = 0`` its pre-activation is
        ``A[theta_h] + B[theta_d, phi_d]``, so it costs an addition per sample instead of
        the trigonometry and a matrix product (1.2-1.6x faster than :meth:`eval_halfdiff`).
        """
        (k, b, act), *rest = self._prepared()
        th = g.theta_h.reshape(g.shape)[:, 0, 0]
        td = g.theta_d.reshape(g.shape)[0].ravel()
        pd = g.phi_d.reshape(g.shape)[0].ravel()
        a = np.sin(th)[:, None] * k[0] + np.cos(th)[:, None] * k[2] + b
        sd = np.sin(td)
        bb = (sd * np.cos(pd))[:, None] * k[3] + (sd * np.sin(pd))[:, None] * k[4]
        bb += np.cos(td)[:, None] * k[5]
        out_fn = OUTPUTS[self.output]
        out = np.empty((g.n, N_OUTPUTS))
        m = bb.shape[0]
        for i in range(a.shape[0]):
            for start in range(0, m, CHUNK):
                h = act(bb[start : start + CHUNK] + a[i])
                out[i * m + start : i * m + start + h.shape[0]] = out_fn(_apply(h, rest))
        np.maximum(out, 0.0, out=out)
        out[~g.above] = 0.0
        return out

    def eval_halfdiff(
        self,
        theta_h: Float[ArrayLike, "*s"],
        theta_d: Float[ArrayLike, "*s"],
        phi_d: Float[ArrayLike, "*s"],
    ) -> Float[np.ndarray, "*s 3"]:
        """BRDF at Rusinkiewicz angles (radians, ``phi_h = 0``): 1/sr, no cosine.

        Negative network outputs are clamped to 0, and angles whose directions lie below
        the horizon (``wi.z = cos td cos th - sin td cos pd sin th <= 0`` or ``wo.z``,
        the same with ``+``) give 0.

        Arguments:
        - ``theta_h``, ``theta_d``, ``phi_d``: angles of one shape (any ``phi_d`` range).

        Returns: RGB values of that shape plus a trailing 3.
        """
        th, td, pd = np.broadcast_arrays(
            np.asarray(theta_h, dtype=np.float64),
            np.asarray(theta_d, dtype=np.float64),
            np.asarray(phi_d, dtype=np.float64),
        )
        shape = th.shape
        th, td, pd = th.ravel(), td.ravel(), pd.ravel()
        out = np.empty((th.size, N_OUTPUTS))
        for start in range(0, th.size, 16 * CHUNK):
            sl = slice(start, start + 16 * CHUNK)
            out[sl] = self._eval_block(th[sl], td[sl], pd[sl])
        return out.reshape(*shape, N_OUTPUTS)

    def _eval_block(self, th: np.ndarray, td: np.ndarray, pd: np.ndarray) -> np.ndarray:
        sh, ch = np.sin(th), np.cos(th)
        sd, cd = np.sin(td), np.cos(td)
        cp = np.cos(pd)
        x = np.stack([sh, np.zeros_like(th), ch, sd * cp, sd * np.sin(pd), cd], axis=1)
        values = np.maximum(self.forward(x), 0.0)
        a, b = cd * ch, sd * cp * sh
        values[(a - b <= 0.0) | (a + b <= 0.0)] = 0.0
        return values

    def eval(
        self, wi: Float[ArrayLike, "n 3"], wo: Float[ArrayLike, "n 3"]
    ) -> Float[np.ndarray, "n 3"]:
        """BRDF f(wi, wo) in 1/sr, no cosine; 0 below the horizon, negatives clamped to 0.

        Arguments:
        - ``wi``, ``wo``: (n, 3) unit directions toward the light and the viewer (local
          frame, z the normal). They are rotated to half/difference form (``phi_h``
          dropped: the model is isotropic).

        Returns: (n, 3) RGB values.
        """
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        theta_h, theta_d, phi_d, _ = io_to_halfdiff(wi, wo)
        values = self.eval_halfdiff(theta_h, theta_d, phi_d)
        values[(wi[:, 2] <= 0.0) | (wo[:, 2] <= 0.0)] = 0.0
        return values

    def to_measurements(
        self,
        grid: str | tuple[np.ndarray, np.ndarray] = "merl",
        *,
        stride: tuple[int, ...] | int = (1, 1, 1),
    ) -> Measurements:
        """Evaluate on the MERL grid or at given directions, as :class:`Measurements`.

        Arguments:
        - ``grid``: ``"merl"`` for the MERL bin centres (``grid=MERL_SHAPE`` with the
          default stride; cells below the horizon invalid), or ``(wi, wo)``, two (n, 3)
          arrays (solid-angle weights then default to equal weights).
        - ``stride``: a coarser MERL sub-grid, as in :func:`brdffit.io.merl_grid.merl_grid`.

        Returns: :class:`Measurements` in 1/sr with ``channel_scales`` 1 and
        ``source = "NBRDF <name> (<json path>)"``.
        """
        source = f"NBRDF {self.name} ({self.source})"
        if isinstance(grid, str):
            if grid != "merl":
                raise ParameterError(f"grid={grid!r}; accepted: 'merl' or a (wi, wo) pair")
            g = merl_grid(stride)
            values = self._grid_values(g)
            cube = values.T.reshape(3, *g.shape)  # a view: no copy
            return merl_grid_measurements(cube, source=source, stride=g.stride)
        wi, wo = grid
        return Measurements.from_directions(wi, wo, self.eval(wi, wo), source=source)


def _apply(
    h: np.ndarray, prepared: list[tuple[np.ndarray, np.ndarray, Callable[[np.ndarray], np.ndarray]]]
) -> np.ndarray:
    for kernel, bias, act in prepared:
        h = h @ kernel
        h += bias
        h = act(h)
    return h


def read_nbrdf(path: str | os.PathLike[str]) -> NBRDF:
    """Read an NBRDF from ``<stem>.json`` and ``<stem>.h5`` (needs h5py).

    Arguments:
    - ``path``: the stem (``.../alum-bronze``) or either file (``.json`` / ``.h5``).

    Returns: :class:`NBRDF`.

    Raises :class:`MeasurementFileError` naming the file when a file is missing,
    unreadable or malformed, when the layers are not supported, or when the weights do
    not match the architecture; :class:`~brdffit.errors.MissingDependencyError` (an
    ``ImportError``) naming ``pip install brdffit[nbrdf]`` when h5py is missing.

    This returns the network; :func:`read_nbrdf_measurements` returns the
    :class:`Measurements` that :func:`brdffit.fit` takes.
    """
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".json", ".h5") else p
    json_path = stem.with_name(stem.name + ".json")
    h5_path = stem.with_name(stem.name + ".h5")
    layers, output = read_keras_layers(json_path, h5_path)
    return NBRDF(name=stem.name, source=str(json_path), layers=layers, output=output)


def read_nbrdf_measurements(
    path: str | os.PathLike[str], *, stride: tuple[int, int, int] | int = (1, 1, 1)
) -> Measurements:
    """The NBRDF at ``path`` evaluated on the (strided) MERL grid, as :class:`Measurements`.

    The reader of the format (README, Input files): ``read_nbrdf(path)`` then
    :meth:`NBRDF.to_measurements`; ``path`` and errors as :func:`read_nbrdf`, ``stride``
    as :func:`brdffit.io.merl_grid.merl_grid`.
    """
    return read_nbrdf(path).to_measurements(stride=stride)


def nbrdf_to_merl(path: str | os.PathLike[str], out_path: str | os.PathLike[str]) -> Measurements:
    """Evaluate an NBRDF on the full MERL grid and write it as a MERL binary file.

    Arguments:
    - ``path``: the NBRDF, as in :func:`read_nbrdf`.
    - ``out_path``: the ``.binary`` file to write (atomically, cells below the horizon
      as -1, see :func:`brdffit.io.merl.write_merl`).

    Returns: the :class:`Measurements` that were written.
    """
    data = read_nbrdf(path).to_measurements("merl")
    write_merl(out_path, data)
    return data
