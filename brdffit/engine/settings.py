"""The settings of a fit, checked once: what :func:`brdffit.fit` and :func:`brdffit.fit_many`
take as keyword arguments and hand to the engine (:mod:`brdffit.engine.batch`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from brdffit.engine import lm
from brdffit.engine import robust as robust_mod
from brdffit.engine.uncertainty import CHOICES
from brdffit.errors import ParameterError

Freeze = Mapping[str, object] | Sequence[str] | None
"""Parameters held fixed: names (at their start values) or a name -> value mapping."""

COARSE = 8_000
"""Default largest number of thinned samples the starts descend on. The starts only rank
basins (the stress suite recovers every identifiable case from 2,000 random samples);
evenly thinned MERL data keep every theta_h row (its order is theta_h-major and a
stride below 180 keeps every row), so a near-mirror peak stays sampled: 8,000 of the
full grid's 909,696 cells are a stride of 114. Against 25,000 (the default before) on
four NBRDF materials at full resolution (chrome-steel, blue-metallic-paint,
green-plastic, beige-fabric), 7 models (walter, cook_torrance, ward, blinn_phong, low,
ashikhmin_shirley, sgd) x both metrics: every final loss equal to 5e-11 relative, the
same statuses, the fits 19% faster in all (``benchmarks/results/fit_lm.md``). Data of
fewer than ``COARSE`` x ``COARSE_SHARE`` (256,000) samples are thinned by
:data:`brdffit.engine.batch.COARSE_SHARE` instead."""


@dataclass(frozen=True)
class Settings:
    """The keyword arguments of :func:`fit`, checked."""

    init: Mapping[str, object] | None = None
    freeze: Freeze = None
    cut_deg: float | None = 80.0
    n_restarts: int = 1
    screen: int = 32
    seed: int = 0
    max_steps: int = lm.Tolerances.max_steps
    ftol: float = lm.Tolerances.ftol
    xtol: float = lm.Tolerances.xtol
    gtol: float = lm.Tolerances.gtol
    errors: str = "auto"
    robust: str | None = None
    robust_scale: float | None = None
    coarse: int | None = COARSE
    throw: bool = True

    def __post_init__(self) -> None:
        if self.errors not in CHOICES:
            raise ParameterError(f"errors={self.errors!r}: use one of {', '.join(CHOICES)}")
        robust_mod.check_kind(self.robust)
        rs = self.robust_scale
        if rs is not None and not (math.isfinite(rs) and rs > 0):
            raise ParameterError(f"robust_scale={rs!r}: must be a positive number")
        if self.screen < 0 or self.n_restarts < 0:
            raise ParameterError(
                f"screen={self.screen!r}, n_restarts={self.n_restarts!r}: must be >= 0"
            )
        ms = self.max_steps
        if isinstance(ms, bool) or not (isinstance(ms, int | np.integer) and ms >= 1):
            raise ParameterError(f"max_steps={ms!r}: must be an integer >= 1")
        if self.coarse is not None and self.coarse < 100:
            raise ParameterError(f"coarse={self.coarse!r}: use None or at least 100 samples")
        for name in ("ftol", "xtol", "gtol"):
            v = getattr(self, name)
            if not (isinstance(v, float | int) and 0 <= v < 1):
                raise ParameterError(f"{name}={v!r}: use a number in [0, 1)")

    @property
    def tolerances(self) -> lm.Tolerances:
        return lm.Tolerances(int(self.max_steps), self.ftol, self.xtol, self.gtol).as_inputs()
