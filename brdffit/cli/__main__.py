"""``python -m brdffit.cli``: the ``brdffit`` console command."""

from brdffit.cli.entry import main

if __name__ == "__main__":
    raise SystemExit(main())
