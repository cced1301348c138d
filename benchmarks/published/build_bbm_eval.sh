#!/usr/bin/env bash
# Build bbm_eval (benchmarks/published/bbm_eval.cpp) against the bsdfbenchmark "bbm"
# headers: native backbone, doubleRGB, bbm's string BSDF importer. No CMake needed: bbm is
# header-only here, and this script does by hand the two things bbm's CMakeLists.txt does
# for a consumer:
#   * the compile definitions of its interface target: BBM_VERSION, BBM_NAME,
#     BBM_BSDF_ENABLE_FORWARD (BBM_BSDF_FORWARD=ON, the default), BBM_STRING_BSDF_IMPORTER
#     (BBM_DEFAULT_BSDF_IMPORTER="string", the default), BBM_BACKBONE=native; and its include
#     dirs include/ and backbone/native/include (backbone/native/backbone.cmake);
#   * the generated header bbm_bsdfmodels.h (cmake/bbm_helpers.cmake,
#     write_bsdfmodel_header), which CMake fills with every bsdfmodel/*.h; here it lists only
#     the headers of the models the 14 fit files use, so the string importer registers
#     (and compiles) only those. It is written to a build dir placed ahead of bbm's
#     include/ on the include path, so bbm's source tree is not modified.
#
# Environment:
#   BBM_DIR     a bbm source tree (a clone of https://github.com/bsdfbenchmark/bbm). If
#               unset, BBM_GIT is cloned (without checkout) into a temp dir and
#               include/ and backbone/native/ are checked out at BBM_COMMIT.
#   BBM_GIT     default /work/.mirror/bsdfbenchmark+bbm/repo if it exists, else
#               https://github.com/bsdfbenchmark/bbm
#   BBM_COMMIT  default 9807fb38d7ab51802f3a0fe0f65cf763cb01a0f4 (the commit of the fits)
#   BBM_EVAL    output binary, default $HOME/.cache/brdffit/bbm_eval
#   CXX         default g++ (g++ 12.2 tested; needs C++20)
#   CXXFLAGS    extra flags (default none; -O2 is always used)
#
# Usage: benchmarks/published/build_bbm_eval.sh   (about 50 s and 2.3 GB peak for g++ -O2)
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
SRC="$HERE/bbm_eval.cpp"
OUT="${BBM_EVAL:-$HOME/.cache/brdffit/bbm_eval}"
CXX="${CXX:-g++}"
BBM_COMMIT="${BBM_COMMIT:-9807fb38d7ab51802f3a0fe0f65cf763cb01a0f4}"
if [[ -z "${BBM_GIT:-}" ]]; then
  if [[ -d /work/.mirror/bsdfbenchmark+bbm/repo ]]; then
    BBM_GIT=/work/.mirror/bsdfbenchmark+bbm/repo
  else
    BBM_GIT=https://github.com/bsdfbenchmark/bbm
  fi
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/bbm_eval_build.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT

if [[ -n "${BBM_DIR:-}" ]]; then
  BBM="$(cd "$BBM_DIR" && pwd)"
  echo "bbm source: $BBM (BBM_DIR)" >&2
else
  BBM="$WORK/bbm"
  echo "bbm source: $BBM_GIT at $BBM_COMMIT (cloned into $BBM)" >&2
  # Check out only what the build reads: the headers (less the large precomputed tables
  # of the Holzschuch-Pacanowski model, which is not used) and the native backbone.
  git clone --quiet --no-checkout --filter=blob:none "$BBM_GIT" "$BBM" 2>/dev/null \
    || { rm -rf "$BBM"; git clone --quiet --no-checkout "$BBM_GIT" "$BBM"; }
  git -C "$BBM" checkout --quiet "$BBM_COMMIT" -- include backbone/native ':(exclude)include/precomputed'
fi
for f in include/bbm/bsdf_string_convert.h include/bsdfmodel/ngan.h backbone/native/include/backbone.h; do
  [[ -f "$BBM/$f" ]] || { echo "build_bbm_eval.sh: $BBM/$f not found; is BBM_DIR a bbm source tree?" >&2; exit 1; }
done

# The generated model list (cf. write_bsdfmodel_header), in the alphabetical order of
# CMake's glob (the headers rely on it; they do not all include what they use): bagher.h
# before the others that include microfacet.h, so that it is parsed before the bbm::ndf
# namespace exists (its concept check names the archetype ndf<>, which that namespace
# would make ambiguous); cooktorrance.h before low.h (LowCookTorrance) and he.h before
# ngan.h (NganHe), which use them without including them. The ngan/low headers' base
# models (Ward, Phong, CookTorrance, ...) get registered as well; no others are compiled.
GEN="$WORK/gen"
mkdir -p "$GEN"
cat > "$GEN/bbm_bsdfmodels.h" <<'EOF'
/* bbm_bsdfmodels.h for bbm_eval: written by build_bbm_eval.sh (bbm's CMake would list all
   bsdfmodel/*.h). Models: Aggregate, Lambertian, NganWard, NganWardDuer, NganBlinnPhong,
   NganLafortune, NganCookTorrance, NganAshikhminShirley, NganHe, LowAshikhminShirley,
   LowCookTorrance, LowMicrofacetFit, LowSmooth, Bagher. */
#include "bsdfmodel/aggregatemodel.h"
#include "bsdfmodel/ashikhminshirley.h"
#include "bsdfmodel/bagher.h"
#include "bsdfmodel/cooktorrance.h"
#include "bsdfmodel/he.h"
#include "bsdfmodel/lafortune.h"
#include "bsdfmodel/lambertian.h"
#include "bsdfmodel/low.h"
#include "bsdfmodel/lowmicrofacet.h"
#include "bsdfmodel/lowsmooth.h"
#include "bsdfmodel/ngan.h"
#include "bsdfmodel/phong.h"
#include "bsdfmodel/ward.h"
#include "bsdfmodel/wardduer.h"
EOF

mkdir -p "$(dirname "$OUT")"
CMD=("$CXX" -std=c++20 -O2 ${CXXFLAGS:-}
  -DBBM_VERSION=0.5.1 -DBBM_NAME=bbm -DBBM_BSDF_ENABLE_FORWARD -DBBM_STRING_BSDF_IMPORTER
  -DBBM_BACKBONE=native
  -I"$GEN" -I"$BBM/include" -I"$BBM/backbone/native/include"
  "$SRC" -o "$OUT.tmp$$" -pthread -ldl)
echo "${CMD[*]}" >&2
start=$(date +%s)
"${CMD[@]}"
mv -f "$OUT.tmp$$" "$OUT"
echo "built $OUT in $(( $(date +%s) - start )) s" >&2
