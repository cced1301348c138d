#!/usr/bin/env bash
# CI: the wheel a user installs. Builds a wheel from the checkout's files (tracked and
# untracked-not-ignored, copied to a scratch folder, so no build/ or *.egg-info left in
# the checkout can hide a missing package), installs it (not editable, dependencies from
# PyPI) into a fresh virtual environment and, from a folder outside the checkout:
#   - imports every subpackage and module of the installed brdffit, checks that it is the
#     installed copy and that every name in brdffit.__all__ resolves;
#   - runs the console command end to end on a small synthetic MERL material (info, fit
#     with a JSON result, an HTML report and Mitsuba and glTF exports, a one-material
#     sweep and its report) and checks that every output file exists and is not empty.
# Usage: bash .ci/wheel_check.sh [REPO_ROOT]   (default: this script's repository)
set -euo pipefail

src="$(cd "${1:-$(dirname "$0")/..}" && pwd)"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/brdffit-wheel.XXXXXX")"
trap 'rm -rf "$tmp"' EXIT
say() { printf 'wheel check [%3ds]: %s\n' "$SECONDS" "$*" >&2; }
fail() { say "FAILED: $*"; exit 1; }

# 1. the checkout's files, without build outputs
mkdir "$tmp/src"
if git -C "$src" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    (cd "$src" && git ls-files -z --cached --others --exclude-standard) |
        (cd "$src" && python3 -c '
import os, shutil, sys
dest = sys.argv[1]
for rel in sys.stdin.buffer.read().decode().split("\0"):
    if rel and os.path.isfile(rel):  # a tracked file deleted in the work tree is left out
        os.makedirs(os.path.join(dest, os.path.dirname(rel)), exist_ok=True)
        shutil.copy2(rel, os.path.join(dest, rel))
' "$tmp/src")
else
    cp -a "$src/." "$tmp/src/"
    rm -rf "$tmp/src/build" "$tmp/src/dist" "$tmp/src"/*.egg-info
fi

# 2. a fresh venv; the wheel built there (pip's isolated build fetches setuptools)
say "building the wheel from $src"
python3 -m venv "$tmp/venv"
py="$tmp/venv/bin/python"
"$py" -m pip install --quiet --upgrade pip
"$py" -m pip wheel --quiet --no-deps -w "$tmp/dist" "$tmp/src" || fail "pip wheel"
shopt -s nullglob
wheels=("$tmp/dist"/brdffit-*.whl)
shopt -u nullglob
[ "${#wheels[@]}" -eq 1 ] || fail "expected one brdffit wheel in $tmp/dist, found ${#wheels[*]}"
wheel="${wheels[0]}"
say "built $(basename "$wheel"); installing it with its dependencies"
"$py" -m pip install --quiet "$wheel" || fail "pip install $(basename "$wheel")"

# 3. everything below runs outside the checkout, on the installed copy
work="$tmp/work"
mkdir "$work"
cd "$work"
export MPLBACKEND=Agg BRDFFIT_JAX_CACHE="$tmp/jax-cache"
unset PYTHONPATH

say "importing every module of the installed brdffit"
"$py" - "$wheel" "$src" <<'EOF' || fail "imports from the installed wheel"
import importlib
import pkgutil
import sys
import sysconfig
import zipfile
from pathlib import Path

wheel, checkout = sys.argv[1], Path(sys.argv[2]).resolve()
top = {n.split("/", 1)[0] for n in zipfile.ZipFile(wheel).namelist()}
extra = sorted(t for t in top if t != "brdffit" and not t.endswith(".dist-info"))
assert not extra, f"the wheel installs more than brdffit: {extra}"

import brdffit

site = Path(sysconfig.get_paths()["purelib"]).resolve()
where = Path(brdffit.__file__).resolve()
assert where.is_relative_to(site), f"brdffit imported from {where}, not from {site}"
assert not where.is_relative_to(checkout), f"brdffit imported from the checkout: {where}"


def onerror(name):
    raise ImportError(f"walking {name} failed") from sys.exc_info()[1]


names = [m.name for m in pkgutil.walk_packages(brdffit.__path__, "brdffit.", onerror=onerror)]
for name in names:
    mod = importlib.import_module(name)  # raises ModuleNotFoundError with the missing name
    f = Path(mod.__file__).resolve()
    assert f.is_relative_to(site), f"{name} imported from {f}, not from {site}"
missing = [n for n in brdffit.__all__ if not hasattr(brdffit, n)]
assert not missing, f"brdffit.__all__ names what brdffit lacks: {missing}"
print(f"imported brdffit and {len(names)} modules from {site}; {len(brdffit.__all__)} public names")
EOF

say "making a synthetic MERL material"
"$py" - <<'EOF' || fail "synthetic material"
import brdffit

truth = {"kd": [0.12, 0.30, 0.55], "ks": [0.8] * 3, "f0": [0.045] * 3, "alpha": 0.09}
data = brdffit.synthesize(brdffit.models.get("walter"), truth, noise_mult=0.05, seed=0)
brdffit.write_merl("material.binary", data)
EOF

bf="$tmp/venv/bin/brdffit"
[ -x "$bf" ] || fail "the wheel installs no brdffit console command"
say "running the brdffit command"
"$bf" --version
"$bf" info material.binary >info.txt || fail "brdffit info"
"$bf" fit material.binary --model walter --stride 9 9 15 --metric ngan \
    --json fit.json --report fit.html --export mitsuba,gltf >fit.txt || fail "brdffit fit"
"$bf" sweep sweep --synthetic 1 --models lambert --metrics ngan --stride 9 9 15 \
    --jobs 1 --no-progress >sweep.txt || fail "brdffit sweep"
"$bf" report sweep >report.txt || fail "brdffit report"
for f in info.txt fit.txt fit.json fit.html fit.mitsuba.xml fit.mitsuba.json fit.gltf \
    sweep/report.html sweep/report/report.md; do
    [ -s "$f" ] || fail "$f is missing or empty"
done
"$py" -c 'import json; json.load(open("fit.json")); json.load(open("fit.gltf"))' ||
    fail "fit.json or fit.gltf is not JSON"
cat fit.txt
say "passed: $(basename "$wheel") imports and runs outside the checkout"
