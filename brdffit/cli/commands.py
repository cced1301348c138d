"""The ``brdffit`` command line; each subcommand is one library call plus printing.

Bad input (a missing or malformed file, an unknown model, option or metric, a bad
model spec such as ``lafortune[n_lobes=two]``) prints one line on stderr naming the
problem and exits with code 2. ``brdffit check`` exits with code 1 when a numerical
check fails. Models are given as specs, ``name`` or ``name[k=v,...]``
(:func:`brdffit.models.parse_spec`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from brdffit.errors import BrdffitError, ParameterError

MODELS_HELP = (
    "comma-separated model specs: name or name[k=v,...] for a variant with static options, "
    "e.g. walter,lafortune[n_lobes=2] (quote it in the shell)"
)


SEED_HELP = "seed of the random starts and subsamples (default 0): same seed, same answer"
NO_PROGRESS_HELP = "no progress bar or progress lines on stderr"
FMT_HELP = "table format (default text)"

FAMILIES_HELP = (
    "CSV file of material,family rows; replaces the family guessed from the material name "
    "(unknown names are 'other')"
)


def _seed(text: str) -> int:
    """``--seed``: an integer >= 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; give an integer >= 0")
    return value


def _count(text: str) -> int:
    """A count option (``--restarts``, ``--screen``): an integer >= 0."""
    return _seed(text)


def _cut(text: str) -> float:
    """``--cut``: a zenith cut in degrees, finite and in (0, 90]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 < value <= 90.0:
        raise argparse.ArgumentTypeError(f"{value:g} degrees; give a zenith cut in (0, 90]")
    return value


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2
        sys.stderr.write(f"brdffit: {message}\n")
        raise SystemExit(2)


def _model(spec: str, options: Sequence[str] | None):
    """The model of ``spec`` (``name`` or ``name[k=v,...]``) plus ``--option`` KEY=VALUE items."""
    from brdffit import models

    if options:
        extra = ",".join(options)
        spec = f"{spec[:-1]},{extra}]" if spec.endswith("]") else f"{spec}[{extra}]"
    return models.from_spec(spec)


def _specs(text: str) -> list[str]:
    """``--models`` split at the commas outside brackets."""
    from brdffit import models

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
    from pathlib import Path

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
    from brdffit.io.load import load_measurements

    data = load_measurements(args.file, stride=tuple(args.stride))
    stride = tuple(args.stride)
    if stride != (1, 1, 1):
        data = data.replace(source=f"{data.source}, MERL grid at stride {stride}")
    return data


def _write(path: str, text: str) -> None:
    from brdffit.util.atomic import write_text

    write_text(path, text)


def cmd_models(args) -> None:
    from brdffit import models

    for name in models.available():
        print(models.get(name).describe())
        print()


def cmd_info(args) -> None:
    print(_load(args).summary())


def cmd_fit(args) -> None:
    from brdffit.engine.fit import fit

    for option, path in (("--json", args.json), ("--report", args.report)):
        _check_output(option, path)
    if args.export and args.export_prefix:
        _check_output("--export-prefix", args.export_prefix)
    freeze = _freeze(args.freeze)
    model, data = _model(args.model, args.option), _load(args)
    if args.export:  # refuse a target that cannot take the model before fitting
        from brdffit.export import check_targets

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
    if args.export:
        from brdffit.export import default_prefix, render_note, write_exports
        from brdffit.models import label

        prefix = args.export_prefix or default_prefix(args.file, args.json, label(model))
        for e, paths in write_exports(r, args.export, prefix):
            print(f"export {e.summary()} -> {', '.join(str(p) for p in paths)}")
        if note := render_note(r.metric):
            print(f"note: {note}")
    if args.report:
        from brdffit.report.html import write_fit_html

        write_fit_html(args.report, r, data)


def _say(text: str) -> None:
    """A progress line on stderr, shown at once (stdout keeps the reports)."""
    sys.stderr.write(f"{text}\n")
    sys.stderr.flush()


def cmd_sample(args) -> None:
    """The LM fit (announced, then its report), the sampler (tqdm progress), the posterior
    summary; the sampler's warnings once each, as ``brdffit sample: warning: ...`` lines
    on stderr (not as Python warnings, and not again in the summary)."""
    import dataclasses
    import warnings

    from brdffit.engine.fit import fit
    from brdffit.engine.sample import check_arguments, sample

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
        import matplotlib

        matplotlib.use("Agg")
        from brdffit.util.atomic import save_figure

        save_figure(post.corner(), args.corner, dpi=80)
    if args.json:
        _write(args.json, post.to_json())


def cmd_rank(args) -> None:
    from brdffit.selection.rank import fit_models, rank

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
        from brdffit.io.merl import merl_grid

        merl_grid(tuple(args.stride))
    if args.families:
        from brdffit.selection.families import read_families

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
    from brdffit.report.html import write_sweep_html
    from brdffit.report.markdown import write_report
    from brdffit.selection.crossrank import load_sweep

    skipped = load_sweep(args.sweep_dir).unreadable
    if skipped:
        names = ", ".join(f"{path} ({why})" for path, why in skipped)
        _say(f"brdffit report: {len(skipped)} unreadable result files left out: {names}")
    md = write_report(args.sweep_dir, families=args.families)
    print(write_sweep_html(args.sweep_dir, families=args.families))
    print(md)


def cmd_check(args) -> int:
    """Model-level extremes table; exit code 1 when any row fails."""
    from brdffit import models
    from brdffit.models.check import check_model, format_table

    names = args.models or models.available()
    built = [_model(n, ()) for n in names]  # validate every name before checking
    rows = [row for m in built for row in check_model(m, args.dtype)]
    print(format_table(rows, args.format), end="")
    failed = sum(not r.passed for r in rows)
    if args.format == "text":
        print(f"{len(rows) - failed}/{len(rows)} checks passed")
    return 1 if failed else 0


def cmd_demo(args) -> None:
    from brdffit.cli.demo import run_demo

    run_demo(args.out, progress=not args.no_progress)


def cmd_simplify(args) -> None:
    """The reduction path table and the chosen label (:func:`brdffit.selection.simplify.simplify`)."""
    from brdffit.selection.simplify import simplify

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


def _stride_arg(sp: argparse.ArgumentParser) -> None:
    sp.add_argument(
        "--stride",
        type=int,
        nargs=3,
        default=(1, 1, 1),
        metavar=("TH", "TD", "PD"),
        help="fit a MERL sub-grid (odd divisors of 90 90 180)",
    )


def build_parser() -> argparse.ArgumentParser:
    from brdffit import __version__
    from brdffit.engine.metrics import METRICS

    p = _Parser(prog="brdffit", description="Fit analytic BRDF models to measured reflectance.")
    p.add_argument(
        "--version", action="version", version=f"brdffit {__version__ or 'unknown (not installed)'}"
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def data_args(sp):
        sp.add_argument(
            "file",
            help="measurements: MERL binary, NBRDF .json/.h5, RGL-EPFL .bsdf (needs "
            "brdffit[rgl]), or a table of samples .csv/.npz (columns: brdffit.io.table)",
        )
        _stride_arg(sp)

    def fit_args(sp, with_model=True):
        if with_model:
            sp.add_argument(
                "--model", required=True, help="model name (brdffit models) or name[k=v,...]"
            )
            sp.add_argument(
                "--option",
                action="append",
                metavar="KEY=VALUE",
                help="static model option, repeatable",
            )
            sp.add_argument(
                "--freeze",
                action="append",
                metavar="NAME[=VALUE]",
                help="hold a parameter out of the fit, at its start value or at VALUE "
                "(R,G,B for a colour); repeatable",
            )
        sp.add_argument(
            "--metric",
            default="low_e2",
            choices=sorted(METRICS),
            help="fitting metric (default low_e2; see README, Fitting metrics)",
        )
        sp.add_argument("--cut", type=_cut, default=80.0, help="zenith cut, degrees")
        sp.add_argument("--seed", type=_seed, default=0, help=SEED_HELP)

    s = sub.add_parser("models", help="list every model with parameters and options")
    s.set_defaults(func=cmd_models)
    s = sub.add_parser("info", help="summarise a measurement file")
    data_args(s)
    s.set_defaults(func=cmd_info)
    s = sub.add_parser("fit", help="Levenberg-Marquardt fit of one model")
    data_args(s)
    fit_args(s)
    s.add_argument("--restarts", type=_count, default=1, help="random starts near the first")
    s.add_argument(
        "--screen",
        type=_count,
        default=32,
        help="candidates spread over the ranges; the cheapest 8 become starts (0: none)",
    )
    s.add_argument(
        "--robust", choices=["huber", "cauchy"], help="robust loss on the residuals (outliers)"
    )
    s.add_argument("--robust-scale", type=float, help="its scale, residual units (default: MAD)")
    s.add_argument(
        "--errors",
        default="sandwich",
        choices=["sandwich", "classic", "blocks"],
        help="standard errors; blocks: for measured data, admits model error shared by "
        "neighbouring cells",
    )
    s.add_argument("--json", metavar="OUT", help="write the result as JSON")
    s.add_argument("--report", metavar="HTML", help="write a one-file HTML report with figures")
    s.add_argument(
        "--export",
        metavar="TARGETS",
        help="write the fitted material for renderers: comma-separated mitsuba,gltf,materialx "
        "(each line says exact or approximate and the measured error)",
    )
    s.add_argument(
        "--export-prefix",
        metavar="PATH",
        help="file prefix of the exports (PATH.mitsuba.xml, PATH.gltf, ...); default: the "
        "--json path without .json, else INPUT-STEM.MODEL in the current folder",
    )
    s.set_defaults(func=cmd_fit)
    s = sub.add_parser("sample", help="emcee posterior of one model, started at the LM fit")
    data_args(s)
    fit_args(s)
    s.add_argument(
        "--noise",
        default="mixed",
        choices=["mixed", "multiplicative", "additive", "constant"],
        help="likelihood's noise model (default mixed: an absolute plus a relative scale)",
    )
    s.add_argument(
        "--steps", type=int, default=2000, help="steps per walker (>= 2; a third is burn-in)"
    )
    s.add_argument(
        "--walkers",
        type=int,
        default=None,
        help="emcee walkers (>= 2 x sampled dimension; default max(32, 4 x dimension))",
    )
    s.add_argument(
        "--subsample",
        type=int,
        default=10_000,
        help="samples drawn at random for the likelihood (default 10000)",
    )
    s.add_argument("--corner", metavar="PNG", help="write a corner plot of the posterior")
    s.add_argument("--json", metavar="OUT", help="write the posterior summary as JSON")
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.set_defaults(func=cmd_sample)
    s = sub.add_parser("rank", help="fit several models and rank them")
    data_args(s)
    fit_args(s, with_model=False)
    s.add_argument("--models", required=True, help=MODELS_HELP)
    s.add_argument(
        "--by", default="loss", choices=["loss", "aic", "bic"], help="rank by (default loss)"
    )
    s.add_argument("--format", default="text", choices=["text", "markdown", "csv"], help=FMT_HELP)
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.set_defaults(func=cmd_rank)
    s = sub.add_parser("sweep", help="fit materials x models x metrics, resumable")
    s.add_argument("out", help="sweep folder (created; an existing one is resumed)")
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument("--merl-dir", metavar="DIR", help="folder of MERL *.binary files")
    src.add_argument("--nbrdf-dir", metavar="DIR", help="folder of NBRDF *.json + *.h5")
    src.add_argument("--rgl-dir", metavar="DIR", help="folder of RGL-EPFL *.bsdf files")
    src.add_argument(
        "--table-dir", metavar="DIR", help="folder of sample tables *.csv/*.npz (read as they are)"
    )
    src.add_argument("--synthetic", type=int, metavar="N", help="N seeded synthetic materials")
    s.add_argument("--materials", help="comma-separated material names to pick")
    s.add_argument("--models", required=True, help=MODELS_HELP)
    s.add_argument("--metrics", default="low_e2", help="comma-separated metric names")
    _stride_arg(s)
    s.add_argument("--cut", type=_cut, default=80.0, help="zenith cut, degrees")
    s.add_argument("--restarts", type=_count, default=1, help="random starts near the first")
    s.add_argument(
        "--screen",
        type=_count,
        default=32,
        help="candidates spread over the ranges; the cheapest 8 become starts (0: none)",
    )
    s.add_argument("--seed", type=_seed, default=0, help=SEED_HELP)
    s.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="worker processes of the local Dask cluster (default: cores; 1: this process)",
    )
    s.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on the Dask cluster whose scheduler is at ADDRESS (tcp://host:8786)",
    )
    s.add_argument(
        "--batch",
        type=int,
        default=1,
        metavar="N",
        help="fit up to N materials of one model and metric in one batched call (same "
        "answers; faster on a GPU and on small grids)",
    )
    s.add_argument(
        "--simplify",
        nargs="?",
        const="cv",
        choices=["cv", "bic"],
        help="after each fit, leave out the features the data do not support (criterion, "
        "default cv); stored in each result file",
    )
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.add_argument("--families", metavar="CSV", help=FAMILIES_HELP)
    s.set_defaults(func=cmd_sweep)
    s = sub.add_parser("report", help="Markdown and one-file HTML report of a sweep folder")
    s.add_argument("sweep_dir", help="a folder written by brdffit sweep")
    s.add_argument("--families", metavar="CSV", help=FAMILIES_HELP)
    s.set_defaults(func=cmd_report)
    s = sub.add_parser("check", help="values and gradients at extreme directions and bounds")
    s.add_argument(
        "models", nargs="*", metavar="MODEL", help="model names or name[k=v,...] (default: all)"
    )
    s.add_argument(
        "--dtype",
        default="both",
        choices=["float32", "float64", "both"],
        help="precision of the checks (default both)",
    )
    s.add_argument("--format", default="text", choices=["text", "markdown", "csv"], help=FMT_HELP)
    s.set_defaults(func=cmd_check)
    s = sub.add_parser("demo", help="synthetic material -> fits -> ranking -> posterior")
    s.add_argument("--out", default="demo-out", help="output folder")
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.set_defaults(func=cmd_demo)
    s = sub.add_parser("simplify", help="leave out the features the data do not support")
    data_args(s)
    fit_args(s)
    s.add_argument(
        "--criterion",
        default="cv",
        choices=["cv", "bic"],
        help="cv: held-out loss over blocks of cells, a paired t-test over the folds; "
        "bic: n = residuals",
    )
    s.add_argument("--folds", type=int, default=5, help="cross-validation folds")
    s.add_argument(
        "--n-se",
        type=float,
        default=None,
        help="cv: a feature stays when its t exceeds this (default: Student's t quantile "
        "0.95 for folds - 1 degrees of freedom, 2.13 for 5 folds; 1: the one-SE rule)",
    )
    s.add_argument(
        "--min-gain",
        type=float,
        default=0.01,
        help="cv: a feature stays only when it lowers the held-out loss by more than this "
        "fraction (default 0.01)",
    )
    s.add_argument("--format", default="text", choices=["text", "markdown"], help=FMT_HELP)
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.add_argument("--json", metavar="OUT", help="write the path and both fits as JSON")
    s.set_defaults(func=cmd_simplify)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brdffit`` console command; returns the exit code."""
    args = build_parser().parse_args(argv)
    from brdffit.util.jax_config import enable_compilation_cache

    enable_compilation_cache()
    try:
        code = args.func(args)
    except (BrdffitError, OSError) as err:
        text = " ".join(str(err).split())
        sys.stderr.write(f"brdffit {args.command}: {text}\n")
        return 2
    return code or 0


if __name__ == "__main__":
    raise SystemExit(main())
