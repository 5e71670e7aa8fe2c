// Straight tetrahedra of order p ≥ 2 (straight sides: an affine map from the reference
// tetrahedron) cast directly, without sub-hexahedra: along a ray the barycentric coordinates are
// linear in t, so the ray's segment in a tetrahedron is an interval of t found exactly, and the
// field on it is a polynomial of degree p in t — its Bernstein coefficients on the segment are
// the blossom of the field's Bernstein–Bézier form on the tetrahedron at the segment's ends —,
// its roots isolated by Bernstein subdivision (bernstein/roots.hpp). The Embree
// binding and the axis caster (object order over bins of the tetrahedra across the ray axis)
// take each hit from one function, so they give the same bits. Internal to CellElementSource.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <tbb/parallel_for.h>
#include <glm/glm.hpp>

#include "ldimesh/core/field/field_source.hpp"
#include "reference_cells.hpp"

namespace ldimesh::cells {

// One active tetrahedron: its map x − v0 → (λ₁, λ₂, λ₃), its vertices' box, and where the
// Bernstein–Bézier coefficients of its field minus the isovalue start in StraightTets::values.
struct StraightTet {
  glm::dvec3 v0{0.0};
  glm::dmat3 to_barycentric{1.0};
  glm::dvec3 lo{0.0}, hi{0.0};
  std::size_t values = 0;
};

struct StraightTets {
  const ReferenceCell* cell = nullptr;  // the tetrahedron of order p (VTK's nodes)
  std::vector<StraightTet> tets;
  // N per tetrahedron: the Bernstein–Bézier coefficients c_α of f − isovalue, in the order of
  // the cell's nodes (coefficient j has the multi-index α of node j's lattice position).
  std::vector<double> values;
  // Coefficient j's slot in a dense (p + 1)³ array, α₁ + (p + 1)(α₂ + (p + 1) α₃).
  std::vector<int> slots;
  std::uint64_t nonfinite = 0;
};

// The tetrahedra of order `cell.order` whose field may reach `isovalue` (its Bernstein
// coefficients on the tetrahedron, which bound it, straddle the isovalue; convex hull
// property), from their 4 vertices (12 doubles each) and nodal values `values(e, i)` (VTK's
// order); cells with a non-finite value are left out and those values counted.
template <class Values>
StraightTets active_straight_tets(const ReferenceCell& cell, std::span<const double> vertices,
                                  double isovalue, Values values);

std::unique_ptr<GeometryBinding> bind_straight_tets(RTCDevice device, StraightTets tets);
std::unique_ptr<AxisCaster> bind_axis_straight_tets(StraightTets tets);

// ---------------------------------------------------------------------------------------------

template <class Values>
StraightTets active_straight_tets(const ReferenceCell& cell, std::span<const double> vertices,
                                  double isovalue, Values values) {
  // In chunks on all cores, in two passes (the active cells per chunk, then each written in
  // place): the same list, in cell order, for any thread count.
  constexpr std::size_t kChunk = 4096;
  const std::size_t n = cell.nodes.size();
  const std::size_t cells = vertices.size() / 12, chunks = (cells + kChunk - 1) / kChunk;
  std::vector<std::vector<std::uint32_t>> active(chunks);
  std::vector<std::uint64_t> bad_values(chunks, 0);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t chunk) {
    std::vector<double> f(n), b(n);
    for (std::size_t e = chunk * kChunk; e < std::min(cells, (chunk + 1) * kChunk); ++e) {
      int bad = 0;
      for (std::size_t i = 0; i < n; ++i) {
        f[i] = values(e, int(i)) - isovalue;
        bad += !std::isfinite(f[i]);
      }
      if (bad > 0) {
        bad_values[chunk] += std::uint64_t(bad);
        continue;
      }
      double lo = INFINITY, hi = -INFINITY;
      for (std::size_t j = 0; j < n; ++j) {
        const double* row = cell.to_bernstein.data() + j * n;
        double s = 0.0;
        for (std::size_t i = 0; i < n; ++i)
          s += row[i] * f[i];
        lo = std::min(lo, s), hi = std::max(hi, s);
      }
      // The coefficients' rounding (n products and sums of the values' size): a margin.
      double size = 0.0;
      for (std::size_t i = 0; i < n; ++i)
        size = std::max(size, std::abs(f[i]));
      const double pad = 1e-12 * double(n) * size;
      if (lo - pad <= 0.0 && 0.0 <= hi + pad)
        active[chunk].push_back(std::uint32_t(e - chunk * kChunk));
    }
  });
  std::vector<std::size_t> offset(chunks + 1, 0);
  StraightTets out;
  out.cell = &cell;
  const int p = cell.order;
  for (const glm::dvec3& r : cell.nodes) {
    const glm::ivec3 alpha(glm::round(r * double(p)));
    out.slots.push_back(alpha.x + (p + 1) * (alpha.y + (p + 1) * alpha.z));
  }
  for (std::size_t chunk = 0; chunk < chunks; ++chunk) {
    offset[chunk + 1] = offset[chunk] + active[chunk].size();
    out.nonfinite += bad_values[chunk];
  }
  out.tets.resize(offset[chunks]);
  out.values.resize(offset[chunks] * n);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t chunk) {
    std::vector<double> f(n);
    std::size_t k = offset[chunk];
    for (const std::uint32_t local : active[chunk]) {
      const std::size_t e = chunk * kChunk + local;
      const double* v = vertices.data() + 12 * e;
      StraightTet& t = out.tets[k];
      t.v0 = glm::dvec3(v[0], v[1], v[2]);
      t.lo = t.hi = t.v0;
      glm::dmat3 edges;  // columns: v_i − v0
      for (int i = 1; i < 4; ++i) {
        const glm::dvec3 vi(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
        edges[i - 1] = vi - t.v0;
        t.lo = glm::min(t.lo, vi), t.hi = glm::max(t.hi, vi);
      }
      t.to_barycentric = glm::inverse(edges);
      t.values = k * n;
      for (std::size_t i = 0; i < n; ++i)
        f[i] = values(e, int(i)) - isovalue;
      for (std::size_t j = 0; j < n; ++j) {
        const double* row = cell.to_bernstein.data() + j * n;
        double s = 0.0;
        for (std::size_t i = 0; i < n; ++i)
          s += row[i] * f[i];
        out.values[k * n + j] = s;
      }
      ++k;
    }
  });
  return out;
}

}  // namespace ldimesh::cells
