#!/usr/bin/env bash
# The checks too slow for the default suite (the identifiability fits of every model but
# Lambert and Lafortune, walter's reduction by simplify and the other tests marked
# `slow`), run on demand: bash benchmarks/slow_checks.sh
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pytest -m slow "$@"
