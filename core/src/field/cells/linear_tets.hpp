// Linear tetrahedra (VTK_TETRA, P1) cast directly, without sub-hexahedra: the field is linear in
// a tetrahedron, so a ray meets its isosurface at most once, where the ray crosses the plane
// f = isovalue inside the tetrahedron. Both casters (Embree for any ray, the axis caster over bins
// of the tetrahedra across the ray axis) take each hit from one function, so they give the same
// bits. Internal to CellElementSource (cell_source.hpp).
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

namespace ldimesh::cells {

// One tetrahedron with its field minus the isovalue: f(x) = f0 + g·(x − v0), and the map from
// x − v0 to its barycentric coordinates λ₁, λ₂, λ₃ (λ₀ = 1 − Σ). Its crossing polygon (the plane
// f = 0 inside it: 3 or 4 corners, rounded to float) grown by `margin` holds every hit tet_hit
// accepts, rounding included (set_crossing); lo(), hi() bound that region. The culling data
// first, in one cache line, then what the hit reads: 3 lines in all.
struct alignas(64) LinearTet {
  float corner[4][3]{};
  float margin = 0.0f;
  int corners = 0;
  glm::dvec3 v0{0.0};
  glm::dmat3 to_barycentric{1.0};
  glm::dvec3 g{0.0};
  double f0 = 0.0;

  glm::dvec3 lo() const {
    glm::dvec3 out(INFINITY);
    for (int k = 0; k < corners; ++k)
      out = glm::min(out, glm::dvec3(corner[k][0], corner[k][1], corner[k][2]));
    return out - double(margin);
  }
  glm::dvec3 hi() const {
    glm::dvec3 out(-INFINITY);
    for (int k = 0; k < corners; ++k)
      out = glm::max(out, glm::dvec3(corner[k][0], corner[k][1], corner[k][2]));
    return out + double(margin);
  }
};

// The crossing polygon, its margin and box of `tet` (v0, g, f0 set) with vertices `v` (12
// doubles) and values minus the isovalue `f`, which straddle 0.
void set_crossing(LinearTet& tet, const double* v, const double* f);

// The tetrahedra whose values straddle `isovalue` (a value equal to it counts), from the cells'
// 4 vertices (12 doubles each, VTK's order) and their 4 values each (`values(e, i)`); the cells
// with a non-finite value are left out and their non-finite values counted in `nonfinite`.
template <class Values>
std::vector<LinearTet> active_linear_tets(std::span<const double> vertices, double isovalue,
                                          Values values, std::uint64_t& nonfinite);

// The Embree and axis casters over the active tetrahedra.
std::unique_ptr<GeometryBinding> bind_linear_tets(RTCDevice device, std::vector<LinearTet> tets,
                                                  std::uint64_t nonfinite);
std::unique_ptr<AxisCaster> bind_axis_linear_tets(std::vector<LinearTet> tets,
                                                  std::uint64_t nonfinite);

// Whether the 4 vertices (12 doubles) make a tetrahedron of non-zero volume (relative to its
// edges' lengths).
bool linear_tet_is_valid(const double* vertices);

// ---------------------------------------------------------------------------------------------

template <class Values>
std::vector<LinearTet> active_linear_tets(std::span<const double> vertices, double isovalue,
                                          Values values, std::uint64_t& nonfinite) {
  // In chunks of cells on all cores, in two passes: the active cells' indices per chunk, then
  // each active tetrahedron written in place at its chunk's offset — the same list, in cell
  // order, for any thread count, and no vector grown and copied on the way.
  constexpr std::size_t kChunk = 16384;
  const std::size_t cells = vertices.size() / 12, chunks = (cells + kChunk - 1) / kChunk;
  std::vector<std::vector<std::uint32_t>> active(chunks);
  std::vector<std::uint64_t> bad_values(chunks, 0);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t chunk) {
    std::vector<std::uint32_t>& out = active[chunk];
    for (std::size_t e = chunk * kChunk; e < std::min(cells, (chunk + 1) * kChunk); ++e) {
      double f[4];
      int bad = 0;
      for (int i = 0; i < 4; ++i) {
        f[i] = values(e, i);
        bad += !std::isfinite(f[i]);
      }
      if (bad > 0) {
        bad_values[chunk] += std::uint64_t(bad);
        continue;
      }
      const double lo = std::min(std::min(f[0], f[1]), std::min(f[2], f[3]));
      const double hi = std::max(std::max(f[0], f[1]), std::max(f[2], f[3]));
      if (!(lo <= isovalue && isovalue <= hi) || lo == hi) continue;
      out.push_back(std::uint32_t(e - chunk * kChunk));
    }
  });
  std::vector<std::size_t> offset(chunks + 1, 0);
  nonfinite = 0;
  for (std::size_t chunk = 0; chunk < chunks; ++chunk) {
    offset[chunk + 1] = offset[chunk] + active[chunk].size();
    nonfinite += bad_values[chunk];
  }
  std::vector<LinearTet> out(offset[chunks]);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t chunk) {
    LinearTet* to = out.data() + offset[chunk];
    for (const std::uint32_t local : active[chunk]) {
      const std::size_t e = chunk * kChunk + local;
      double f[4];
      for (int i = 0; i < 4; ++i)
        f[i] = values(e, i);
      const double* v = vertices.data() + 12 * e;
      LinearTet& t = *to++;
      t.v0 = glm::dvec3(v[0], v[1], v[2]);
      glm::dmat3 edges;  // columns: v_i − v0
      for (int i = 1; i < 4; ++i)
        edges[i - 1] = glm::dvec3(v[3 * i], v[3 * i + 1], v[3 * i + 2]) - t.v0;
      t.to_barycentric = glm::inverse(edges);
      // ∇f = (∂λ/∂x)ᵀ (f_i − f_0): the rows of to_barycentric are ∇λ_i.
      t.g = glm::transpose(t.to_barycentric) * glm::dvec3(f[1] - f[0], f[2] - f[0], f[3] - f[0]);
      t.f0 = f[0] - isovalue;
      const double shifted[4] = {f[0] - isovalue, f[1] - isovalue, f[2] - isovalue,
                                 f[3] - isovalue};
      set_crossing(t, v, shifted);
    }
  });
  return out;
}

}  // namespace ldimesh::cells
