"""The ``brdffit`` command line's parser: subcommands, options, their checks and help.

:func:`build_parser` builds it; each subcommand's ``func`` default is its ``cmd_*``
function (:mod:`brdffit.cli.commands`). A bad option prints one line on stderr and exits
with code 2.
"""

from __future__ import annotations

import argparse
import sys

from brdffit.cli.commands import (
    cmd_check,
    cmd_demo,
    cmd_fit,
    cmd_info,
    cmd_material,
    cmd_models,
    cmd_rank,
    cmd_report,
    cmd_sample,
    cmd_simplify,
    cmd_sweep,
)
from brdffit.engine.metrics import METRICS
from brdffit.export.material import REFERENCE as MATERIAL_REFERENCE
from brdffit.util.version import __version__

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
        help="candidates over the ranges; of the 8 cheapest, one per valley starts (0: none)",
    )
    s.add_argument(
        "--robust", choices=["huber", "cauchy"], help="robust loss on the residuals (outliers)"
    )
    s.add_argument("--robust-scale", type=float, help="its scale, residual units (default: MAD)")
    s.add_argument(
        "--errors",
        default="auto",
        choices=["auto", "sandwich", "classic", "blocks"],
        help="standard errors; blocks: admits model error shared by neighbouring cells; "
        "auto (default): blocks for measured data, sandwich for synthetic",
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
        help="candidates over the ranges; of the 8 cheapest, one per valley starts (0: none)",
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
    s = sub.add_parser(
        "material", help="fit the forms a renderer holds, write the best for render-space error"
    )
    data_args(s)
    s.add_argument(
        "--target",
        required=True,
        choices=["mitsuba", "gltf", "materialx"],
        help="the renderer whose forms are fitted and written",
    )
    s.add_argument(
        "--out", required=True, metavar="PREFIX", help="write PREFIX.<target files> (atomically)"
    )
    s.add_argument(
        "--forms", metavar="SPECS", help="model specs to fit instead of the target's forms"
    )
    s.add_argument(
        "--reference",
        default=MATERIAL_REFERENCE,
        metavar="SPEC",
        help="a richer form fitted beside them, to measure what the target cannot hold "
        f"(default {MATERIAL_REFERENCE}; none: skip)",
    )
    s.add_argument("--cut", type=_cut, default=80.0, help="zenith cut, degrees")
    s.add_argument("--seed", type=_seed, default=0, help=SEED_HELP)
    s.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    s.set_defaults(func=cmd_material)
    return p
