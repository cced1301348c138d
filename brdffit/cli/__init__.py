"""The ``brdffit`` command line: ``parser`` builds it, ``commands`` holds one function per
subcommand (a library call plus printing), ``entry`` runs it, ``demo`` is ``brdffit demo``."""

from brdffit.cli.entry import main
from brdffit.cli.parser import build_parser

__all__ = ["build_parser", "main"]
