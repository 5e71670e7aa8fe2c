// The LDI fragment codec's quantizers (fragment_codec.cpp; docs/method.md, "LDI fragments on the
// wire"): depths on a uniform grid over the fragment's range, scalars likewise, normals on the
// octahedron. Per sample, so inline. Internal to the transport library.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>

#include <glm/glm.hpp>

#include "ldimesh/core/raycast/fragment.hpp"

namespace ldimesh::fragment_quantizers {

// The spacing of floats just above max(|lo|, |hi|): the resolution a float depth has there.
inline double float_spacing_at(double lo, double hi) {
  const double m = std::max(std::abs(lo), std::abs(hi));
  if (!(m < double(FLT_MAX))) return std::numeric_limits<double>::infinity();
  const float f = float(m);
  return double(std::nextafter(f, std::numeric_limits<float>::infinity())) - double(f);
}

// The depth bits the encoder really uses: a step of at least two float spacings keeps the
// float rounding of a decoded depth within a quarter step, so re-quantizing it gives the same
// integer (idempotence); finer steps would only store rounding noise.
inline int effective_depth_bits(int bits, double lo, double hi) {
  const double spacing = float_spacing_at(lo, hi);
  while (bits > 0 && (hi - lo) / double((std::uint32_t(1) << bits) - 1) < 2.0 * spacing)
    --bits;
  return bits;
}

// round(x) for x ≥ 0 (halves up): the conversion truncates, which is floor(x + 0.5) there, without
// the call that std::floor is on baseline x86-64.
inline std::uint32_t round_nonnegative(double x) {
  return std::uint32_t(x + 0.5);
}

// q = round((d − lo)/(hi − lo)·(2^b − 1)), decoded as lo + q·(hi − lo)/(2^b − 1) rounded to
// float. Monotone both ways, so depths sorted per pixel stay sorted.
struct DepthQuantizer {
  double lo = 0.0, hi = 0.0;
  std::uint32_t max_q = 0;  // 2^b − 1; 0 when b = 0 (every depth becomes lo)

  DepthQuantizer(int bits, double lo_, double hi_)
      : lo(lo_), hi(hi_), max_q((std::uint32_t(1) << bits) - 1) {}

  std::uint32_t quantize(float d) const {
    if (max_q == 0) return 0;
    const double t = (double(d) - lo) / (hi - lo) * double(max_q);
    return round_nonnegative(std::min(std::max(t, 0.0), double(max_q)));
  }
  float dequantize(std::uint32_t q) const {
    if (max_q == 0) return float(lo);
    return float(lo + double(q) * ((hi - lo) / double(max_q)));
  }
};

// The scalar bits the encoder really uses over [lo, hi] (at least 1): as for depths, a step of
// at least two float spacings, with 2^b − 2 steps (one code is kept for non-finite values).
inline int effective_scalar_bits(int bits, double lo, double hi) {
  const double spacing = float_spacing_at(lo, hi);
  while (bits > 1 && (hi - lo) / double((std::uint32_t(1) << bits) - 2) < 2.0 * spacing)
    --bits;
  return bits;
}

// Scalars (a colour field) of a lossy fragment: a finite value x is q = round((x − lo)/(hi −
// lo)·top), top = 2^b − 2, over the fragment's finite values [lo, hi], decoded as lo + q·(hi −
// lo)/top rounded to float (exactly lo at 0, hi at top); a non-finite one is q = top + 1,
// decoded as NaN. With b = 1 (top = 0) every finite value is lo.
struct ScalarQuantizer {
  double lo = 0.0, hi = 0.0;
  std::uint32_t top = 0;

  ScalarQuantizer(int bits, double lo_, double hi_)
      : lo(lo_), hi(hi_), top((std::uint32_t(1) << bits) - 2) {}

  std::uint32_t max_code() const { return top + 1; }
  std::uint32_t quantize(float x) const {
    if (!std::isfinite(x)) return top + 1;
    if (top == 0) return 0;
    const double t = (double(x) - lo) / (hi - lo) * double(top);
    return round_nonnegative(std::min(std::max(t, 0.0), double(top)));
  }
  float dequantize(std::uint32_t q) const {
    if (q > top) return std::numeric_limits<float>::quiet_NaN();
    if (q == top) return float(hi);
    return float(lo + double(q) * ((hi - lo) / double(top)));
  }
};

// The range and bits of a lossy fragment's scalars: its scalar range (the one the ranks agreed
// on) widened to hold its finite scalars, 0 and 0 without either; −0 as +0 (a decoded q = 0 is
// float(lo + 0), +0, which must give the same range again); collapsed to lo where one bit is
// left.
struct ScalarRange {
  int bits = 1;
  float lo = 0.0f, hi = 0.0f;
};
inline ScalarRange scalar_range(const LdiFragment& f, int bits) {
  float lo, hi;
  fragment_scalar_range(f, lo, hi);
  ScalarRange r;
  if (!std::isnan(lo)) {
    r.lo = lo + 0.0f;
    r.hi = hi + 0.0f;
  }
  r.bits = effective_scalar_bits(bits, r.lo, r.hi);
  if (r.bits == 1) r.hi = r.lo;
  return r;
}

// −0 counts as positive, so ±0 get one code.
inline double sign_not_zero(double v) {
  return v >= 0.0 ? 1.0 : -1.0;
}

// Octahedral normals (Meyer et al. 2010, "On floating-point normal vectors", CGF 29(4);
// Cigolle et al. 2014, "A survey of efficient representations for independent unit vectors",
// JCGT 3(2)): project onto the octahedron |x| + |y| + |z| = 1, unfold the lower half over the
// corners of the square [−1, 1]², and store each coordinate as an n-bit snorm, as Cigolle et
// al. do: round(p·(2^(n−1) − 1)), offset to be unsigned. This gives up one of the 2^n codes
// for a grid that holds −1, 0 and 1 exactly, so the six axis normals are exact.
struct NormalQuantizer {
  std::uint32_t half = 0;   // 2^(n−1) − 1: the code of p = 0
  std::uint32_t max_u = 0;  // 2·half: the code of p = 1; u ↔ max_u − u negates p exactly

  explicit NormalQuantizer(int bits)
      : half((std::uint32_t(1) << (bits - 1)) - 1), max_u(2 * half) {}

  std::uint32_t to_grid(double p) const {
    const double t = (p + 1.0) * double(half);
    return round_nonnegative(std::min(std::max(t, 0.0), double(max_u)));
  }
  double from_grid(std::uint32_t u) const { return (double(u) - double(half)) / double(half); }

  void quantize(glm::vec3 n, std::uint32_t& u, std::uint32_t& v) const {
    const double x = n.x, y = n.y, z = n.z;
    const double s = std::abs(x) + std::abs(y) + std::abs(z);
    const double px = x / s, py = y / s;
    // The lower half folded over the corners; both computed and one selected (z < 0 is a coin
    // toss over a surface's normals).
    const double fx = (1.0 - std::abs(py)) * sign_not_zero(px);
    const double fy = (1.0 - std::abs(px)) * sign_not_zero(py);
    const bool lower = z < 0.0;
    u = to_grid(lower ? fx : px);
    v = to_grid(lower ? fy : py);
    // The square's edges fold onto the lower half twice: (±1, p) and (±1, −p) are one normal,
    // as are (p, ±1) and (−p, ±1), and all four corners are −z. One code each, the one that
    // re-encoding the decoded normal gives (p ≥ 0 along the edge; sign_not_zero(±0) = +1).
    if (u == 0 || u == max_u) v = std::max(v, max_u - v);
    if (v == 0 || v == max_u) u = std::max(u, max_u - u);
  }

  glm::vec3 dequantize(std::uint32_t u, std::uint32_t v) const {
    const double px = from_grid(u), py = from_grid(v);
    const double z = 1.0 - std::abs(px) - std::abs(py);
    const double fx = (1.0 - std::abs(py)) * sign_not_zero(px);
    const double fy = (1.0 - std::abs(px)) * sign_not_zero(py);
    const bool lower = z < 0.0;  // folded as in quantize
    const double x = lower ? fx : px, y = lower ? fy : py;
    const double len = std::sqrt(x * x + y * y + z * z);  // ≥ 1/√3 on the octahedron
    return glm::vec3(float(x / len), float(y / len), float(z / len));
  }
};

}  // namespace ldimesh::fragment_quantizers
