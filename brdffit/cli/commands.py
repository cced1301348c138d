"""The ``brdffit`` subcommands; each one is one library call plus printing.

Bad input (a missing or malformed file, an unknown model, option or metric, a bad
model spec such as ``lafortune[n_lobes=two]``) raises a :class:`~brdffit.errors.BrdffitError`,
which :func:`brdffit.cli.main` prints as one line on stderr with exit code 2.
``brdffit check`` exits with code 1 when a numerical check fails. Models are given as
specs, ``name`` or ``name[k=v,...]`` (:func:`brdffit.models.parse_spec`).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

from brdffit import models, sweep
from brdffit.cli.demo import run_demo
from brdffit.engine.fit import fit
from brdffit.engine.sample import check_arguments, sample
from brdffit.errors import ParameterError
from brdffit.export import check_targets, default_prefix, render_note, write_exports
from brdffit.export.material import best_material
from brdffit.io.load import load_measurements
from brdffit.io.merl_grid import merl_grid
from brdffit.models import label
from brdffit.models.check import check_model, format_table
from brdffit.report.html import write_fit_html
from brdffit.report.markdown import write_report
from brdffit.report.posterior_figures import corner_figure
from brdffit.report.sweep_html import write_sweep_html
from brdffit.selection.families import read_families
from brdffit.selection.rank import fit_models, rank
from brdffit.selection.simplify import simplify
from brdffit.selection.sweep_results import load_sweep
from brdffit.util.atomic import save_figure, write_text


def _model(spec: str, options: Sequence[str] | None):
    """The model of ``spec`` (``name`` or ``name[k=v,...]``) plus ``--option`` KEY=VALUE items."""
    if options:
        extra = ",".join(options)
        spec = f"{spec[:-1]},{extra}]" if spec.endswith("]") else f"{spec}[{extra}]"
    return models.from_spec(spec)


def _specs(text: str) -> list[str]:
    """``--models`` split at the commas outside brackets."""
    return models.split_specs(text)


def _freeze(items: Sequence[str] | None):
    """``--freeze`` items as :func:`brdffit.fit`'s ``freeze``: names, or name -> value(s)."""
    if not items:
        return None
    out: dict[str, object] = {}
    names: list[str] = []
    for item in items:
        key, sep, value = item.partition("=")
        if sep:
            try:
                numbers = [float(v) for v in value.split(",")]
            except ValueError:
                raise ParameterError(
                    f"--freeze {item!r}: {value!r} is not a number; give NAME, NAME=VALUE "
                    "or NAME=R,G,B"
                ) from None
            out[key] = numbers if "," in value else numbers[0]
        else:
            names.append(key)
    if names and out:
        raise ParameterError("--freeze: give either NAME or NAME=VALUE for every parameter")
    return out or names


def _check_output(option: str, path: str | None) -> None:
    """Refuse, before any fit, an output path that cannot be written: a folder, or a file
    in a folder that does not exist or is not writable (``option`` names it)."""
    if path is None:
        return
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise ParameterError(f"{option} {path}: is a folder; give a file path")
    if not folder.is_dir():
        raise ParameterError(
            f"{option} {path}: folder {folder} does not exist; give a path in an existing folder"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ParameterError(f"{option} {path}: folder {folder} is not writable")


def _load(args):
    """The measurements of ``args.file``; a strided MERL grid says its stride in ``source``
    (the first line of every report names it)."""
    data = load_measurements(args.file, stride=tuple(args.stride))
    stride = tuple(args.stride)
    if stride != (1, 1, 1):
        data = data.replace(source=f"{data.source}, MERL grid at stride {stride}")
    return data


def _write(path: str, text: str) -> None:
    write_text(path, text)


def cmd_models(args) -> None:
    for name in models.available():
        print(models.get(name).describe())
        print()


def cmd_info(args) -> None:
    print(_load(args).summary())


def cmd_fit(args) -> None:
    for option, path in (("--json", args.json), ("--report", args.report)):
        _check_output(option, path)
    if args.export and args.export_prefix:
        _check_output("--export-prefix", args.export_prefix)
    freeze = _freeze(args.freeze)
    model, data = _model(args.model, args.option), _load(args)
    if args.export:  # refuse a target that cannot take the model before fitting
        check_targets(model, args.export)
    r = fit(
        model,
        data,
        args.metric,
        freeze=freeze,
        cut_deg=args.cut,
        n_restarts=args.restarts,
        screen=args.screen,
        seed=args.seed,
        robust=args.robust,
        robust_scale=args.robust_scale,
        errors=args.errors,
        throw=False,
    )
    print(r.report())
    if args.json:
        _write(args.json, r.to_json())
    written = []
    if args.export:
        prefix = args.export_prefix or default_prefix(args.file, args.json, label(model))
        written = write_exports(r, args.export, prefix)
        for e, paths in written:
            print(f"export {e.summary()} -> {', '.join(str(p) for p in paths)}")
        if note := render_note(r.metric):
            print(f"note: {note}")
    if args.report:
        write_fit_html(args.report, r, data, exports=written)


def _say(text: str) -> None:
    """A progress line on stderr, shown at once (stdout keeps the reports)."""
    sys.stderr.write(f"{text}\n")
    sys.stderr.flush()


def cmd_sample(args) -> None:
    """The LM fit (announced, then its report), the sampler (tqdm progress), the posterior
    summary; the sampler's warnings once each, as ``brdffit sample: warning: ...`` lines
    on stderr (not as Python warnings, and not again in the summary)."""
    for option, path in (("--json", args.json), ("--corner", args.corner)):
        _check_output(option, path)
    freeze = _freeze(args.freeze)
    model = _model(args.model, args.option)
    try:  # before the LM fit: a setting the sampler refuses must not cost a fit
        check_arguments(
            model, freeze=freeze, noise=args.noise, n_walkers=args.walkers,
            n_steps=args.steps, n_subsample=args.subsample,
        )  # fmt: skip
    except ParameterError as e:
        names = {"n_walkers": "--walkers", "n_steps": "--steps", "n_subsample": "--subsample"}
        text = str(e)
        for name, option in names.items():
            text = text.replace(f"{name}=", f"{option} ", 1) if text.startswith(name) else text
        raise ParameterError(text) from None
    data = _load(args)
    _say(f"fitting {model.name} to {data.source} by Levenberg-Marquardt ({args.metric}) ...")
    r = fit(model, data, args.metric, freeze=freeze, cut_deg=args.cut, throw=False)
    print(r.report(), end="\n\n", flush=True)
    _say(f"sampling the posterior with emcee ({args.steps} steps, noise {args.noise}) ...")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        post = sample(
            model,
            data,
            init=r,
            freeze=freeze,
            noise=args.noise,
            n_steps=args.steps,
            n_walkers=args.walkers,
            n_subsample=args.subsample,
            cut_deg=args.cut,
            seed=args.seed,
            progress=not args.no_progress,
        )
    for text in dict.fromkeys([*(str(w.message) for w in caught), *post.warnings]):
        _say(f"brdffit sample: warning: {' '.join(text.split())}")
    print(dataclasses.replace(post, warnings=()).summary())
    if args.corner:
        save_figure(corner_figure(post, fit=r), args.corner, dpi=80)
    if args.json:
        _write(args.json, post.to_json())


def cmd_rank(args) -> None:
    models_ = [_model(n, ()) for n in _specs(args.models)]  # validate every spec before fitting
    data = _load(args)
    results = fit_models(
        models_, data, args.metric, cut_deg=args.cut, seed=args.seed,
        progress=not args.no_progress,
    )  # fmt: skip
    print(rank(results, by=args.by).table(args.format))


def cmd_sweep(args) -> None:
    names = [n.strip() for n in (args.materials or "").split(",") if n.strip()] or None
    if args.merl_dir:
        materials = sweep.merl_materials(args.merl_dir, names)
    elif args.nbrdf_dir:
        materials = sweep.nbrdf_materials(args.nbrdf_dir, names)
    elif args.rgl_dir:
        materials = sweep.rgl_materials(args.rgl_dir, names)
    elif args.table_dir:
        materials = sweep.table_materials(args.table_dir, names)
    else:
        materials = sweep.synthetic_materials(args.synthetic, seed=args.seed)
    if not args.table_dir:  # a bad stride fails here, not in every task
        merl_grid(tuple(args.stride))
    if args.families:
        materials = sweep.with_families(materials, read_families(args.families))
    s = sweep.run_sweep(
        args.out,
        materials,
        _specs(args.models),
        [n.strip() for n in args.metrics.split(",") if n.strip()],
        stride=tuple(args.stride),
        cut_deg=args.cut,
        n_restarts=args.restarts,
        screen=args.screen,
        seed=args.seed,
        jobs=args.jobs,
        scheduler=args.scheduler,
        batch=args.batch,
        progress=not args.no_progress,
        simplify=args.simplify,
        announce=lambda line: print(line, file=sys.stderr),
    )
    print(
        f"{s.out}: {s.n_tasks} tasks, {s.n_skipped} already done, {s.n_done} fitted now "
        f"({s.n_unconverged} not converged), {s.n_errors} errors, {s.wall_time:.1f} s"
    )


def cmd_report(args) -> None:
    skipped = load_sweep(args.sweep_dir).unreadable
    if skipped:
        names = ", ".join(f"{path} ({why})" for path, why in skipped)
        _say(f"brdffit report: {len(skipped)} unreadable result files left out: {names}")
    md = write_report(args.sweep_dir, families=args.families)
    print(write_sweep_html(args.sweep_dir, families=args.families))
    print(md)


def cmd_check(args) -> int:
    """Model-level extremes table; exit code 1 when any row fails."""
    names = args.models or models.available()
    built = [_model(n, ()) for n in names]  # validate every name before checking
    rows = [row for m in built for row in check_model(m, args.dtype)]
    print(format_table(rows, args.format), end="")
    failed = sum(not r.passed for r in rows)
    if args.format == "text":
        print(f"{len(rows) - failed}/{len(rows)} checks passed")
    return 1 if failed else 0


def cmd_demo(args) -> None:
    run_demo(args.out, progress=not args.no_progress)


def cmd_simplify(args) -> None:
    """The reduction path table and the chosen label
    (:func:`brdffit.selection.simplify.simplify`)."""
    _check_output("--json", args.json)
    freeze = _freeze(args.freeze)
    r = simplify(
        _model(args.model, args.option),
        _load(args),
        args.metric,
        criterion=args.criterion,
        folds=args.folds,
        n_se=args.n_se,
        min_gain=args.min_gain,
        cut_deg=args.cut,
        seed=args.seed,
        freeze=freeze,
        progress=not args.no_progress,
        throw=False,
    )
    print(r.table(args.format))
    print(r.chosen)
    if args.json:
        _write(args.json, r.to_json())


def cmd_material(args) -> None:
    """Fit the target's forms, print each with its render-space error, write the chosen
    one (:func:`brdffit.export.material.best_material`)."""
    _check_output("--out", args.out)
    forms = _specs(args.forms) if args.forms else None
    reference = None if args.reference.lower() == "none" else args.reference
    data = _load(args)
    full = data if tuple(args.stride) == (1, 1, 1) else load_measurements(args.file)
    m = best_material(
        data,
        args.target,
        args.out,
        forms=forms,
        reference=reference,
        measured=full,
        cut_deg=args.cut,
        seed=args.seed,
        progress=None if args.no_progress else _say,
    )
    print(m.report())
