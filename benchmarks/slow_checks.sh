#!/usr/bin/env bash
# The checks too slow for the default suite (every option row's identifiability fit and
# other tests marked `slow`), run on demand: bash benchmarks/slow_checks.sh
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pytest -m slow "$@"
