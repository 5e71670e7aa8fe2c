#include "ldimesh/core/refine/refine.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <memory>
#include <stdexcept>
#include <string>

#include <tbb/parallel_for.h>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/mesh/trim.hpp"
#include "refine_state.hpp"

namespace ldimesh {
namespace refine_detail {
namespace {

// The six templates (up to rotation and inversion) for a leaf with hanging midpoints m[k] on
// its edges: none (two triangles), one, two adjacent, two opposite, three, four.
void triangle_templates(const RefineState& rs, const Cell& cell,
                        const std::vector<glm::vec3>& world, std::vector<std::uint32_t>& out) {
  std::array<std::uint32_t, 4> m;
  int hanging = 0;
  for (int k = 0; k < 4; ++k) {
    m[k] = rs.find_midpoint(cell.c[k], cell.c[(k + 1) & 3]);
    hanging += m[k] != kNone;
  }
  const auto c = [&](int k) { return cell.c[k & 3]; };
  const auto h = [&](int k) { return m[k & 3] != kNone; };
  const auto mid = [&](int k) { return m[k & 3]; };
  const auto quad = [&](std::uint32_t a, std::uint32_t b, std::uint32_t e, std::uint32_t d) {
    const std::uint32_t v[4] = {a, b, e, d};
    append_quad_triangles(world, v, out);
  };
  if (hanging == 0) {
    quad(c(0), c(1), c(2), c(3));
    return;
  }
  // Rotate: edge s is hanging, and so is s + 1 for two adjacent, s + 2 for two opposite, s + 1
  // and s + 2 for three.
  const auto fits = [&](int k) {
    if (!h(k)) return false;
    if (hanging == 2) return h(k + 1) || h(k + 2);
    if (hanging == 3) return h(k + 1) && h(k + 2);
    return true;
  };
  int s = 0;
  while (!fits(s))
    ++s;
  if (hanging == 1) {
    out.insert(out.end(),
               {mid(s), c(s + 1), c(s + 2), mid(s), c(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
  } else if (hanging == 2 && h(s + 2)) {
    quad(c(s), mid(s), mid(s + 2), c(s + 3));
    quad(mid(s), c(s + 1), c(s + 2), mid(s + 2));
  } else if (hanging == 2) {  // edges s and s + 1
    out.insert(out.end(), {mid(s), c(s + 1), mid(s + 1), mid(s), mid(s + 1), c(s + 2), mid(s),
                           c(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
  } else if (hanging == 3) {  // edges s, s + 1, s + 2
    out.insert(out.end(),
               {mid(s), c(s + 1), mid(s + 1), mid(s + 1), c(s + 2), mid(s + 2), mid(s), mid(s + 1),
                mid(s + 2), mid(s), mid(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
  } else {
    for (int k = 0; k < 4; ++k)
      out.insert(out.end(), {mid(k - 1), c(k), mid(k)});
    quad(mid(0), mid(1), mid(2), mid(3));
  }
}

}  // namespace

RefinedView output(const RefineState& rs, RefinementStats& stats) {
  const int arity = rs.faces_ == FaceType::quads ? 4 : 3;
  std::vector<glm::vec3> world(rs.vertices_.size());
  for (std::size_t v = 0; v < rs.vertices_.size(); ++v)
    world[v] = rs.position(rs.vertices_[v]);
  const glm::vec3 dq(rs.view_.dir);
  const float rf = float(rs.r_);
  RefinedView out;
  // The kept faces, in vertex numbers until the end: each leaf's faces are appended, then the
  // ones it keeps are moved down over those it drops.
  std::vector<std::uint32_t>& faces = out.faces;
  for (const Cell& cell : rs.cells_) {
    if (!cell.leaf) continue;
    std::size_t kept = faces.size();
    if (rs.faces_ == FaceType::quads)
      faces.insert(faces.end(), cell.c.begin(), cell.c.end());
    else
      triangle_templates(rs, cell, world, faces);
    for (std::size_t f = kept; f < faces.size(); f += arity) {
      std::uint32_t* c = &faces[f];
      if (cell.flip) std::reverse(c, c + arity);
      bool valid = true;
      for (int k = 0; k < arity; ++k)
        valid = valid && rs.vertices_[c[k]].valid;
      if (!valid) {
        ++stats.removed_faces;
        continue;
      }
      if (cell.grown) {
        for (int k = 0; k < arity && valid; ++k) {
          const glm::vec3 v = world[c[k]], prev = world[c[(k + arity - 1) % arity]],
                          next = world[c[(k + 1) % arity]];
          valid = view_quality_ok(glm::cross(v - prev, v - next), dq, rs.dirs_, rf);
        }
        if (!valid) {
          ++stats.trimmed_faces;
          continue;
        }
      }
      for (int k = 0; k < arity; ++k)  // kept ≤ f: no overlap ahead of the copy
        faces[kept + k] = c[k];
      kept += arity;
    }
    faces.resize(kept);
  }
  // Vertices used by a kept face, in the order they were made.
  std::vector<std::uint32_t> index(rs.vertices_.size(), kNone);
  std::uint32_t used = 0;
  for (std::uint32_t v : faces)
    if (index[v] == kNone) {
      index[v] = 0;
      ++used;
    }
  out.positions.reserve(used);
  out.normals.reserve(used);
  if (!rs.ldi_.scalar.empty()) out.scalars.reserve(used);
  for (std::size_t v = 0; v < rs.vertices_.size(); ++v) {
    if (index[v] == kNone) continue;
    index[v] = std::uint32_t(out.positions.size());
    out.positions.push_back(world[v]);
    out.normals.push_back(glm::vec3(rs.vertices_[v].normal));
    if (!rs.ldi_.scalar.empty()) out.scalars.push_back(rs.vertices_[v].scalar);
  }
  for (std::uint32_t& v : faces)
    v = index[v];
  stats.grown_cells += rs.grown_;
  stats.subdivided_cells += rs.subdivided_;
  stats.invalid_vertices += rs.invalid_;
  return out;
}

}  // namespace refine_detail

using refine_detail::RefineState;
std::vector<RefinedView> refine_views(std::span<const Ldi> ldis, std::span<const ViewQuads> quads,
                                      FaceType faces, const RefinementOptions& options,
                                      const MatchOptions& matching,
                                      std::span<const glm::dvec3> all_dirs, double r,
                                      SampleSource& samples, RefinementStats& stats) {
  if (options.levels < 0 || options.levels > 16)
    throw std::invalid_argument("refinement levels must lie in [0, 16]");
  if (quads.size() != ldis.size())
    throw std::invalid_argument("refine_views: one set of quads per LDI");
  stats = {};
  const auto start = std::chrono::steady_clock::now();
  const std::size_t n = ldis.size();
  std::vector<std::unique_ptr<RefineState>> views(n);
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) {
    views[k] =
        std::make_unique<RefineState>(ldis[k], quads[k], faces, options, matching, all_dirs, r);
    if (options.grow && options.levels > 0) grow(*views[k]);
  });

  for (int pass = 0; pass < options.levels; ++pass) {
    const auto pass_start = std::chrono::steady_clock::now();
    std::vector<std::uint8_t> marked(n, 0);
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) { marked[k] = split(*views[k]); });
    if (std::none_of(marked.begin(), marked.end(), [](std::uint8_t s) { return s != 0; })) break;
    // One round trip for the new vertices of all views.
    std::vector<SamplePoint> points;
    std::vector<std::size_t> first(n);
    std::size_t total = 0;
    for (std::size_t k = 0; k < n; ++k)
      total += views[k]->stretch_positions().size();
    points.reserve(total);
    for (std::size_t k = 0; k < n; ++k) {
      first[k] = points.size();
      const std::span<const glm::dvec2> positions = views[k]->stretch_positions(),
                                        ranges = views[k]->stretch_ranges();
      for (std::size_t i = 0; i < positions.size(); ++i)
        points.push_back({std::uint32_t(k), positions[i], ranges[i].x, ranges[i].y});
    }
    const auto sample_start = std::chrono::steady_clock::now();
    const RayHitList hits = samples.sample(points);
    stats.sample_seconds += seconds_since(sample_start);
    ++stats.round_trips;
    if (hits.offsets.size() != points.size() + 1)
      throw std::runtime_error("sample source answered " + std::to_string(hits.offsets.size() - 1) +
                               " rays for " + std::to_string(points.size()));
    tbb::parallel_for(std::size_t(0), n,
                      [&](std::size_t k) { resolve(*views[k], hits, first[k]); });
    ++stats.passes;
    stats.rays_per_pass.push_back(points.size());
    stats.seconds_per_pass.push_back(seconds_since(pass_start));
  }

  std::vector<RefinedView> out(n);
  std::vector<RefinementStats> per_view(n);
  tbb::parallel_for(std::size_t(0), n,
                    [&](std::size_t k) { out[k] = output(*views[k], per_view[k]); });
  for (const RefinementStats& s : per_view) {
    stats.grown_cells += s.grown_cells;
    stats.subdivided_cells += s.subdivided_cells;
    stats.invalid_vertices += s.invalid_vertices;
    stats.removed_faces += s.removed_faces;
    stats.trimmed_faces += s.trimmed_faces;
  }
  stats.seconds = seconds_since(start);
  return out;
}

}  // namespace ldimesh
