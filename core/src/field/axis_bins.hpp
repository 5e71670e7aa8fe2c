// Boxes binned across one ray axis, for the element families' coherent casters (hexahedra,
// linear tetrahedra; internal): a uniform grid over the two world axes other than the ray's
// (b < c), each box listed in every bin it touches. A ray lies in one bin, so it meets each box
// listed there once; a rectangle of pixel rays visits each box once, from the first of its bins
// within the rectangle (first_in, from flags in the entry: the box itself is not read).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
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

// The bins of `boxes` across ray axis `axis` (0, 1, 2): as wide as the median box (of at most
// 4 096 spread over the list), at most 4 096 per axis, coarsened while the entries would exceed
// 16 per box (a graded mesh's large boxes would otherwise fill millions of bins each). Throws
// std::length_error for 2^30 boxes or more.
AxisBins make_axis_bins(std::span<const AxisBox> boxes, int axis);

}  // namespace ldimesh
