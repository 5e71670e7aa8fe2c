#include "ldimesh/core/merge/quadrangulate.hpp"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "../base/in_place.hpp"
#include "../base/mesh_util.hpp"
#include "face_rings.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "quad_state.hpp"

namespace ldimesh {
namespace quad_detail {
namespace {

// The triangles and the quads within `rings` rings of them (sharing a vertex); the whole mesh
// for negative `rings` or when that is every quad.
QuadRegion select_region(const Mesh& m, int rings) {
  QuadRegion r;
  r.input = &m;
  if (rings < 0) return r;
  const std::size_t nv = m.positions.size(), nq = m.quad_count();
  // The triangles' corners seed the rings (the triangles themselves add no vertex).
  std::vector<std::uint8_t> in(nv, 0);
  std::vector<std::uint32_t> seeds;
  for (std::uint32_t v : m.triangles)
    if (!in[v]) in[v] = 1, seeds.push_back(v);
  r.inside.assign(m.face_count(), 0);
  grow_face_rings(m, VertexCorners(m), rings, std::move(seeds), in, r.inside);
  r.inside.resize(nq);  // per quad
  const std::size_t inside = std::size_t(std::count(r.inside.begin(), r.inside.end(), 1));
  if (inside == nq) {
    r.inside.clear();
    return r;
  }
  r.whole = false;
  r.local.assign(nv, kNone);
  for (std::uint32_t v = 0; v < nv; ++v)
    if (in[v]) {
      r.local[v] = std::uint32_t(r.global.size());
      r.global.push_back(v);
    }
  Mesh& sub = r.mesh;
  sub.view_dirs = m.view_dirs;
  sub.positions.reserve(r.global.size());
  sub.normals.reserve(r.global.size());
  for (std::uint32_t v : r.global) {
    sub.positions.push_back(m.positions[v]);
    sub.normals.push_back(m.normals[v]);
    if (!m.scalars.empty()) sub.scalars.push_back(m.scalars[v]);
  }
  sub.quads.reserve(4 * inside);
  if (!m.quad_view.empty()) sub.quad_view.reserve(inside);
  r.pinned.assign(r.global.size(), 0);
  for (std::uint32_t q = 0; q < nq; ++q) {
    const std::uint32_t* c = &m.quads[4 * std::size_t(q)];
    if (r.inside[q]) {
      for (int k = 0; k < 4; ++k)
        sub.quads.push_back(r.local[c[k]]);
      if (!m.quad_view.empty()) sub.quad_view.push_back(m.quad_view[q]);
      continue;
    }
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t a = r.local[c[k]], b = r.local[c[(k + 1) % 4]];
      if (a != kNone) r.pinned[a] = 1;
      if (a != kNone && b != kNone) r.cut.push_back(directed_edge_key(b, a));
    }
  }
  std::sort(r.cut.begin(), r.cut.end());
  sub.triangles.reserve(m.triangles.size());
  for (std::uint32_t v : m.triangles)
    sub.triangles.push_back(r.local[v]);
  sub.triangle_view = m.triangle_view;
  return r;
}

}  // namespace

void output(QuadState& qs, Mesh& m) {
  const std::size_t n_input = m.positions.size(), n_region = qs.region_.vertices();
  // Output order: input vertices (by input number), then the new ones.
  auto number = [&](std::uint32_t v) {
    return v < n_region ? qs.region_.to_input(v) : std::uint32_t(n_input + (v - n_region));
  };
  std::vector<std::uint32_t> index(n_input + (qs.pos_.size() - n_region), kNone);
  std::size_t outside = 0;  // input quads outside the region
  for (std::uint32_t q = 0; q < qs.region_.inside.size(); ++q)
    if (!qs.region_.inside[q]) {
      ++outside;
      for (int k = 0; k < 4; ++k)
        index[m.quads[4 * std::size_t(q) + k]] = 0;
    }
  for (std::uint32_t h = 0; h < qs.to_.size(); ++h)
    if (qs.face_[h] != kNone) index[number(qs.from_[h])] = 0;
  std::size_t used = 0, faces = outside;
  for (std::uint32_t x : index)
    used += x != kNone;
  for (std::uint32_t f = 0; f < qs.face_he_.size(); ++f)
    if (qs.face_he_[f] != kNone) ++faces;  // triangles left are few: room for all as quads
  const bool scalars = !m.scalars.empty();
  std::size_t w = 0;
  for (std::uint32_t g = 0; g < index.size(); ++g) {
    if (index[g] == kNone) continue;
    index[g] = std::uint32_t(w);
    const std::uint32_t v =
        g < n_input ? qs.region_.from_input(g) : std::uint32_t(n_region + (g - n_input));
    if (v == kNone) {  // outside the region: as it was (w <= g: a move down or none)
      m.positions[w] = m.positions[g];
      m.normals[w] = m.normals[g];
      if (scalars) m.scalars[w] = m.scalars[g];
    } else {
      put_at(m.positions, w, glm::vec3(qs.pos_[v]));
      put_at(m.normals, w, glm::vec3(qs.nrm_[v]));
      if (scalars) put_at(m.scalars, w, qs.scalar_[v]);
    }
    ++w;
  }
  m.positions.resize(used);
  m.normals.resize(used);
  if (scalars) m.scalars.resize(used);
  if (m.quad_view.empty()) m.quad_view.assign(m.quad_count(), 0);
  std::size_t kept = 0;  // outside quads written (kept <= q)
  for (std::uint32_t q = 0; q < qs.region_.inside.size(); ++q) {
    if (qs.region_.inside[q]) continue;
    for (int k = 0; k < 4; ++k)
      m.quads[4 * kept + k] = index[m.quads[4 * std::size_t(q) + k]];
    m.quad_view[kept++] = m.quad_view[q];
  }
  m.quads.resize(4 * kept);
  m.quad_view.resize(kept);
  m.quads.reserve(4 * faces);
  m.quad_view.reserve(faces);
  m.triangles.clear();
  m.triangle_view.clear();
  for (std::uint32_t f = 0; f < qs.face_he_.size(); ++f) {
    if (qs.face_he_[f] == kNone) continue;
    const std::size_t n = qs.face_size(f);
    std::vector<std::uint32_t>& target = n == 4 ? m.quads : m.triangles;
    std::uint32_t h = qs.face_he_[f];
    for (std::size_t k = 0; k < n; ++k, h = qs.next_[h])
      target.push_back(index[number(qs.from_[h])]);
    (n == 4 ? m.quad_view : m.triangle_view).push_back(qs.face_view_[f]);
  }
  qs.stats_.output_quads = m.quad_count();
  std::vector<std::uint32_t> renumber(qs.pos_.size());
  for (std::uint32_t v = 0; v < qs.pos_.size(); ++v)
    renumber[v] = index[number(v)];
  renumber_moves(qs.moved_, renumber);
}

}  // namespace quad_detail

using quad_detail::QuadRegion;
using quad_detail::QuadState;
using quad_detail::select_region;
Mesh quadrangulate(Mesh&& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project) {
  stats = {};
  const auto start = std::chrono::steady_clock::now();
  if (const Status s = check_mesh(mesh, {.distinct_corners = true}); !s)
    throw std::invalid_argument("quadrangulate: " + s.message());
  const std::size_t input_quads = mesh.quad_count(), input_triangles = mesh.triangle_count();
  // Converts the region; false (nothing written) when a part of a region that is not the whole
  // mesh keeps an odd number of triangles with no open edge to take the last one.
  auto convert = [&](const QuadRegion& region) {
    auto stage = std::chrono::steady_clock::now();
    auto lap = [&stage](double& seconds) {
      seconds += seconds_since(stage);
      stage = std::chrono::steady_clock::now();
    };
    QuadState qs(region, options, stats);
    lap(stats.setup_seconds);
    pair_triangles(qs);
    lap(stats.pair_seconds);
    connect_triangles(qs, project);
    lap(stats.path_seconds);
    if (!region.whole && stats.leftover_triangles > 0) return false;
    merge_quad_pairs(qs);
    flip_edges(qs);
    lap(stats.cleanup_seconds);
    smooth(qs, project);
    output(qs, mesh);
    // Moved vertices whose faces pass through other faces go back (crossings.hpp): near Barth's
    // double points a path vertex projected onto the surface can land on the other sheet.
    if (!qs.moved().empty() && qs.median_edge() > 0.0)
      stats.crossings_undone = undo_crossing_moves(mesh, qs.moved(), 2.0 * qs.median_edge(),
                                                   options.crossing_min_move * qs.median_edge());
    lap(stats.smooth_seconds);
    return true;
  };
  auto region_start = std::chrono::steady_clock::now();
  const QuadRegion region = select_region(mesh, options.region_rings);
  stats.setup_seconds = seconds_since(region_start);
  if (!convert(region)) {
    // Pair the triangles over the whole mesh instead (the times add up).
    stats = {};
    stats.setup_seconds = seconds_since(region_start);
    convert(select_region(mesh, -1));
  }
  stats.input_quads = input_quads;
  stats.input_triangles = input_triangles;
  stats.seconds = seconds_since(start);
  return std::move(mesh);
}

Mesh quadrangulate(const Mesh& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project) {
  return quadrangulate(Mesh(mesh), options, stats, project);
}

}  // namespace ldimesh
