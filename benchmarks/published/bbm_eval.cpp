/*
 * bbm_eval: evaluate bsdfbenchmark (bbm) BSDFs on direction pairs read from stdin.
 *
 * An independent scorer for the published BRDF fits in bbm's fits/*.fit: the exact
 * right-hand side of a fit-file line (e.g. "Aggregate(Lambertian(albedo = [...]),
 * NganWard(albedo = [...], roughness = 0.0162))") is parsed by bbm's own string importer
 * (bbm::fromString<bsdf_ptr<Config>>, as BBM_STRING_BSDF_IMPORTER's bsdf_import does) and
 * evaluated by bbm's own C++ (https://github.com/bsdfbenchmark/bbm, BSD licence; built
 * against commit 9807fb3 by build_bbm_eval.sh, native backbone).
 *
 * Usage:
 *   bbm_eval [--threads K] '<bsdf string>' ['<bsdf string>' ...]  < pairs.f64 > values.f64
 *   bbm_eval --list                     (names of the registered BSDF models, to stderr)
 *   bbm_eval --print '<bsdf string>'    (bbm's toString of the parsed BSDF, to stdout)
 *
 * stdin:  N records of 6 little-endian float64: wi_x wi_y wi_z wo_x wo_y wo_z, unit
 *         vectors in the local shading frame (z = normal), read to EOF.
 * stdout: for each BSDF string in the order given, N records of 3 float64: the BSDF value
 *         f(wi, wo) for R, G, B in 1/sr, WITHOUT the cosine factor.
 * Exit status: 0 ok; 1 usage / input error; 2 a BSDF string bbm cannot parse.
 *
 * Precision: bbm::doubleRGB (Value = double, Spectrum = 3 doubles; the native backbone's
 * double-precision RGB configuration), so every step of bbm's formula runs in double.
 * (The He model uses the configuration's RGB wavelengths 0.645, 0.526, 0.444 micron.)
 *
 * Directions: each pair is passed as bsdf->eval(in = wi, out = wo) with bbm's default
 * component (bsdf_flag::All: diffuse + specular) and unit (unit_t::Radiance). bbm follows
 * Veach's convention (docs/source/use_bsdf.rst): transport flows from -in to out, and with
 * unit Radiance that is from the light to the camera, so `in` (wi) is the direction
 * towards the LIGHT and `out` (wo) the direction towards the VIEWER, both pointing away
 * from the surface. None of the 14 model classes used by the fit files reads `unit`, and
 * each one's formula is symmetric in (in, out) (Ward/Ward-Duer, Phong with reflect(in).out
 * = reflect(out).in, Lafortune, the microfacet models with F at h.in = h.out,
 * Ashikhmin-Shirley with max(cos_i, cos_o), He, Low smooth, Bagher's G1(in) G1(out)), so
 * swapping wi and wo gives the same value up to rounding (checked by the Python side's
 * checks at <= 2e-13 relative). Directions below the horizon give 0 (each model masks
 * z(in), z(out) > 0 or >= 0); input vectors are used as given (not renormalised).
 *
 * bbm's own numerics, passed through unchanged (this is bbm's scorer, not a fixed one):
 *  - NganLafortune multiplies albedo max(0, C.(in*out))^n by (n+2)/(2 pi) / max(Cz^2,
 *    Cxy^2)^(n/2) AFTER the power: where max(Cz^2, Cxy^2)^(n/2) underflows (Cz = 0.577,
 *    n > ~1350) both are 0 and the value is NaN at every pair above the horizon (33 of the
 *    86 lines of ngan_lafortune.fit); where only the numerator underflows it is 0.
 *  - NganHe is NaN / inf when one direction is within ~1e-8 rad of the normal and the
 *    other is not (1 - z^2 cancels in its geometry term G), and loses precision up to
 *    ~1e-4 rad from it.
 *  - Ward and Ward-Duer are NaN for an exact grazing mirror pair (z(in) = z(out) = 0).
 */

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

// bbm core (backbone, config, bsdf, bsdf_ptr) ...
#include "bbm/bbm_core.h"
// ... the BSDF models: a generated bbm_bsdfmodels.h that includes the headers of the
// models the fit files use (build_bbm_eval.sh writes it, like bbm's CMake does with all of
// bsdfmodel/*.h); each header's BBM_EXPORT_BSDFMODEL lines register its models for
// the string importer when bsdf_string_convert.h re-includes it ...
#include "bbm_bsdfmodels.h"
// ... the string -> bsdf_ptr conversion and bbm's default importer.
#include "bbm/bsdf_string_convert.h"
#include "bbm/bsdf_import.h"

#ifndef BBM_STRING_BSDF_IMPORTER
#error "bbm_eval needs BBM_STRING_BSDF_IMPORTER (bbm's string importer); see build_bbm_eval.sh"
#endif

static_assert(sizeof(double) == 8, "float64 I/O assumes 8-byte doubles");

namespace {

using Conf = bbm::doubleRGB;
using BsdfPtr = bbm::bsdf_ptr<Conf>;
using Vec3d = bbm::Vec3d_t<Conf>;
using Spectrum = bbm::Spectrum_t<Conf>;

bool little_endian()
{
  const std::uint16_t one = 1;
  unsigned char b;
  std::memcpy(&b, &one, 1);
  return b == 1;
}

void swap_bytes(double* v, std::size_t n)
{
  for (std::size_t i = 0; i < n; ++i) {
    unsigned char b[8];
    std::memcpy(b, v + i, 8);
    for (int k = 0; k < 4; ++k) std::swap(b[k], b[7 - k]);
    std::memcpy(v + i, b, 8);
  }
}

// Read all of stdin as float64; returns false (with a message) on a partial record.
bool read_pairs(std::vector<double>& data)
{
  std::vector<char> bytes;
  char buf[1 << 16];
  std::size_t got;
  while ((got = std::fread(buf, 1, sizeof(buf), stdin)) > 0) bytes.insert(bytes.end(), buf, buf + got);
  if (std::ferror(stdin)) {
    std::fprintf(stderr, "bbm_eval: error reading stdin: %s\n", std::strerror(errno));
    return false;
  }
  if (bytes.size() % (6 * sizeof(double)) != 0) {
    std::fprintf(stderr, "bbm_eval: stdin holds %zu bytes, not a whole number of 48-byte records (6 float64)\n",
                 bytes.size());
    return false;
  }
  data.resize(bytes.size() / sizeof(double));
  if (!bytes.empty()) std::memcpy(data.data(), bytes.data(), bytes.size());
  if (!little_endian()) swap_bytes(data.data(), data.size());
  return true;
}

// Evaluate records [begin, end) of `in` (6 doubles each) into `out` (3 doubles each).
void eval_range(const BsdfPtr& ptr, const double* in, double* out, std::size_t begin, std::size_t end)
{
  // Call through the raw pointer: bsdf_ptr's operator-> copies its shared_ptr (an atomic
  // reference count update) on every call, which costs more than a cheap model's eval.
  const bbm::bsdf_base<Conf>& bsdf = *ptr.ptr();
  for (std::size_t i = begin; i < end; ++i) {
    const double* p = in + 6 * i;
    const Vec3d wi(p[0], p[1], p[2]);
    const Vec3d wo(p[3], p[4], p[5]);
    const Spectrum f = bsdf.eval(wi, wo);  // component = bsdf_flag::All, unit = unit_t::Radiance
    out[3 * i + 0] = f[0];
    out[3 * i + 1] = f[1];
    out[3 * i + 2] = f[2];
  }
}

void list_models()
{
  std::vector<std::string> names;
#undef BBM_EXPORT_BSDFMODEL
#define BBM_EXPORT_BSDFMODEL(bsdfmodel) names.push_back(std::string(bsdfmodel<Conf>::name));
#include "bbm_bsdfmodels.h"
#include "export/clear_export.h"
  names.push_back("Aggregate");
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());  // headers re-export included models
  for (const auto& n : names) std::cerr << n << "\n";
}

int usage()
{
  std::fprintf(stderr,
               "usage: bbm_eval [--threads K] '<bsdf string>' ['<bsdf string>' ...] < pairs.f64 > values.f64\n"
               "       bbm_eval --list | --print '<bsdf string>'\n"
               "stdin: N x 6 little-endian float64 (wi, wo; local frame, z = normal, wi = light)\n"
               "stdout: per BSDF string, N x 3 float64 (f in 1/sr per R, G, B; no cosine)\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv)
{
  std::vector<std::string> specs;
  unsigned threads = 1;
  bool print = false;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--list") {
      list_models();
      return 0;
    } else if (arg == "--print") {
      print = true;
    } else if (arg == "--threads" || arg == "-j") {
      if (++a >= argc) return usage();
      threads = static_cast<unsigned>(std::max(1L, std::strtol(argv[a], nullptr, 10)));
    } else if (arg == "-h" || arg == "--help") {
      return usage();
    } else {
      specs.push_back(arg);
    }
  }
  if (specs.empty()) return usage();

  // Parse every string first, so a bad one fails before any output is written.
  std::vector<BsdfPtr> bsdfs;
  for (const auto& s : specs) {
    try {
      bsdfs.push_back(bbm::bsdf_import<Conf>(s));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bbm_eval: cannot parse BSDF string: %s\n  (%s)\n", s.c_str(), e.what());
      return 2;
    } catch (...) {
      std::fprintf(stderr, "bbm_eval: cannot parse BSDF string: %s\n", s.c_str());
      return 2;
    }
  }
  if (print) {
    for (const auto& b : bsdfs) std::cout << b.toString() << "\n";
    return 0;
  }

  std::vector<double> pairs;
  if (!read_pairs(pairs)) return 1;
  const std::size_t n = pairs.size() / 6;
  std::vector<double> values(3 * n);

  for (const auto& bsdf : bsdfs) {
    const unsigned k = static_cast<unsigned>(std::min<std::size_t>(threads, std::max<std::size_t>(n / 4096, 1)));
    if (k <= 1) {
      eval_range(bsdf, pairs.data(), values.data(), 0, n);
    } else {
      // bbm's eval is const and keeps no per-call state for these models.
      std::vector<std::thread> pool;
      for (unsigned t = 0; t < k; ++t)
        pool.emplace_back(eval_range, std::cref(bsdf), pairs.data(), values.data(), n * t / k, n * (t + 1) / k);
      for (auto& th : pool) th.join();
    }
    if (!little_endian()) swap_bytes(values.data(), values.size());
    if (n && std::fwrite(values.data(), sizeof(double), values.size(), stdout) != values.size()) {
      std::fprintf(stderr, "bbm_eval: error writing stdout: %s\n", std::strerror(errno));
      return 1;
    }
  }
  return std::fflush(stdout) == 0 ? 0 : 1;
}
