"""The fit engine: everything between prepared measurements and a fit's or posterior's result.

- ``metrics``: the fitting metrics: residual vectors, scalar losses, prepared data.
- ``objective``: the least-squares objective: model, parameter layout, robust loss, frozen values.
- ``lm``: bounded Levenberg-Marquardt as one jitted loop.
- ``race``: the starts' descents raced by successive halving.
- ``starts``: where a fit starts: screened, random and cross-metric candidates.
- ``batch``: the batched descents: starts raced and finished, for many problems at once.
- ``settings``: the keyword arguments of a fit, checked once.
- ``fit``: :func:`brdffit.fit` and :func:`brdffit.fit_many`.
- ``uncertainty``: standard errors: the covariance of a finished descent's scalars.
- ``assembly``: the :class:`~brdffit.core.result.FitResult` of a finished descent.
- ``sample``: :func:`brdffit.sample`, posterior sampling with emcee.
- ``posterior``: :class:`brdffit.Posterior`, the chains and their diagnostics.
- ``timing``: how long a model takes to evaluate.

The submodules are imported by name; this package re-exports nothing (``fit`` and
``sample`` name both a submodule and its public function, re-exported by :mod:`brdffit`).
"""
