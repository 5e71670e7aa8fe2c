// Boxes binned across one ray axis, for the element families' coherent casters (hexahedra,
// linear tetrahedra; internal): a uniform grid over the two world axes other than the ray's
// (b < c), each box listed in every bin it touches. A ray lies in one bin, so it meets each box
// listed there once; a rectangle of pixel rays visits each box once, from the first of its bins
// within the rectangle (first_in, from flags in the entry: the box itself is not read).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh {

struct AxisBox {
  glm::dvec3 lo{0.0}, hi{0.0};
};

struct AxisBins {
  // An entry: the box's index, and whether this bin is the first of the box's along b, along c.
  static constexpr std::uint32_t kFirstB = 1u << 31, kFirstC = 1u << 30, kIndex = kFirstC - 1;
  int b = 0, c = 1, nb = 1, nc = 1;
  double lo_b = 0.0, lo_c = 0.0, size_b = 1.0, size_c = 1.0;
  std::vector<std::uint32_t> first, entries;  // CSR over the bins (b fastest)

  int bin_b(double x) const { return clamped_floor((x - lo_b) / size_b, 0, nb - 1); }
  int bin_c(double x) const { return clamped_floor((x - lo_c) / size_c, 0, nc - 1); }
  std::size_t bin(int bb, int cc) const {
    return std::size_t(bb) + std::size_t(nb) * std::size_t(cc);
  }
  // The bin of a point (its coordinates along b and c).
  std::size_t at(glm::dvec3 p) const { return bin(bin_b(p[b]), bin_c(p[c])); }
  // Whether `entry`, met in bin (bb, cc) of a rectangle whose first bins are (qb0, qc0), is met
  // there for the first time: its box's first bin within the rectangle.
  static bool first_in(std::uint32_t entry, int bb, int cc, int qb0, int qc0) {
    return ((entry & kFirstB) || bb == qb0) && ((entry & kFirstC) || cc == qc0);
  }
};

// Calls visit(index) once for each box listed in the bins that the rectangle [lo_b, hi_b] ×
// [lo_c, hi_c] (world coordinates along the bins' axes) meets, from the first of its bins there,
// bin by bin (b fastest). With `ahead`, ahead(index) is called for the box `distance` entries
// further on in the same bin before each visit (to prefetch what the visits read).
template <class Visit, class Ahead = std::nullptr_t>
void visit_rectangle(const AxisBins& bins, double lo_b, double hi_b, double lo_c, double hi_c,
                     Visit&& visit, Ahead&& ahead = nullptr, std::uint32_t distance = 8) {
  const int qb0 = bins.bin_b(lo_b), qb1 = bins.bin_b(hi_b);
  const int qc0 = bins.bin_c(lo_c), qc1 = bins.bin_c(hi_c);
  for (int cc = qc0; cc <= qc1; ++cc)
    for (int bb = qb0; bb <= qb1; ++bb) {
      const std::size_t bin = bins.bin(bb, cc);
      const std::uint32_t end = bins.first[bin + 1];
      for (std::uint32_t m = bins.first[bin]; m < end; ++m) {
        if constexpr (!std::is_null_pointer_v<std::decay_t<Ahead>>)
          if (m + distance < end) ahead(bins.entries[m + distance] & AxisBins::kIndex);
        const std::uint32_t entry = bins.entries[m];
        if (AxisBins::first_in(entry, bb, cc, qb0, qc0)) visit(entry & AxisBins::kIndex);
      }
    }
}

// The integers [first, last] in [a, b] within [lo, hi]; empty where first > last. Clamped as
// doubles before the conversion: a far-away box's pixel numbers would not fit an int.
inline std::pair<int, int> integer_range(double a, double b, int lo, int hi) {
  return {int(std::clamp(std::ceil(a), double(lo), double(hi + 1))),
          int(std::clamp(std::floor(b), double(lo - 1), double(hi)))};
}

// The pixel columns (or rows) of a view whose centres, at (n + ½)·spacing from the view's
// origin, lie in [x0, x1] (image coordinates along u or v) grown by `pad` pixel, within
// [lo, hi] (integer_range).
inline std::pair<int, int> pixel_range(double x0, double x1, double inv_spacing, double pad, int lo,
                                       int hi) {
  return integer_range(x0 * inv_spacing - 0.5 - pad, x1 * inv_spacing - 0.5 + pad, lo, hi);
}

// The bins of `boxes` across ray axis `axis` (0, 1, 2): as wide as the median box (of at most
// 4 096 spread over the list), at most 4 096 per axis, coarsened while the entries would exceed
// 16 per box (a graded mesh's large boxes would otherwise fill millions of bins each). Throws
// std::length_error for 2^30 boxes or more.
AxisBins make_axis_bins(std::span<const AxisBox> boxes, int axis);

}  // namespace ldimesh
