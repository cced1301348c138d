"""The ``brdffit`` console command: parse, keep freed memory for reuse
(:func:`brdffit.util.allocator.keep_freed_memory`), turn on the compilation cache, run
the subcommand; a :class:`~brdffit.errors.BrdffitError` or ``OSError`` becomes one line
on stderr and exit code 2.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from brdffit.cli.parser import build_parser
from brdffit.errors import BrdffitError
from brdffit.util.allocator import keep_freed_memory
from brdffit.util.jax_config import enable_compilation_cache


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brdffit`` console command; returns the exit code."""
    args = build_parser().parse_args(argv)
    keep_freed_memory()  # before JAX runs anything (its threads then share one heap)
    enable_compilation_cache()
    try:
        code = args.func(args)
    except (BrdffitError, OSError) as err:
        text = " ".join(str(err).split())
        sys.stderr.write(f"brdffit {args.command}: {text}\n")
        return 2
    return code or 0
