#include "ldimesh/core/merge/merge.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <queue>
#include <span>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <OpenMesh/Core/System/omstream.hh>

#include "../base/in_place.hpp"
#include "../base/mesh_util.hpp"
#include "face_rings.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/merge/crossings.hpp"
#include "merge_state.hpp"

namespace ldimesh {
namespace merge_detail {

Mesh output(MergeState& ms, FaceType faces, Mesh* in_place) {
  Mesh fresh;
  Mesh& out = in_place ? *in_place : fresh;
  const std::size_t n_input = ms.in_.positions.size();
  const std::size_t outside_faces = ms.region_.inside.size() - ms.region_.faces;
  const std::size_t most_vertices = ms.mesh_.n_vertices() + (n_input - ms.region_.global.size());
  std::vector<std::uint32_t> index(ms.mesh_.n_vertices(), kNone);  // OpenMesh → output
  std::vector<std::uint32_t> outside(n_input, kNone);              // input → output
  const bool scalars = !ms.in_.scalars.empty();
  // Room for every face (deleted slots included: an upper bound that costs address space
  // only), so the arrays are not copied over while they grow.
  const std::size_t most = ms.mesh_.n_faces() + outside_faces;
  std::vector<std::uint32_t> triangles;
  std::vector<std::uint8_t> triangle_view;
  if (!in_place) {
    out.view_dirs = ms.in_.view_dirs;
    out.positions.reserve(most_vertices);
    out.normals.reserve(most_vertices);
    if (scalars) out.scalars.reserve(most_vertices);
    if (faces == FaceType::quads) {
      out.quads.reserve(4 * most);
      out.quad_view.reserve(most);
    } else {
      triangles.reserve(6 * most);
      triangle_view.reserve(2 * most);
    }
  }
  std::size_t vertices = 0;
  auto emit = [&](const glm::vec3& p, const glm::vec3& n, float scalar) {
    put_at(out.positions, vertices, p);
    put_at(out.normals, vertices, n);
    if (scalars) put_at(out.scalars, vertices, scalar);
    return std::uint32_t(vertices++);
  };
  auto emit_vertex = [&](VH v) {
    if (ms.alive(v))
      index[v.idx()] = emit(glm::vec3(ms.point(v)), glm::vec3(to_glm(ms.mesh_.normal(v))),
                            ms.mesh_.property(ms.scalar_, v));
  };
  for (std::uint32_t g = 0; g < n_input; ++g) {
    if (ms.region_.local[g] != kNone) {
      emit_vertex(VH(int(ms.region_.local[g])));
    } else if (ms.region_.used[g]) {
      outside[g] = emit(ms.in_.positions[g], ms.in_.normals[g], scalars ? ms.in_.scalars[g] : 0.0f);
    }
  }
  for (std::size_t v = ms.region_.global.size(); v < ms.mesh_.n_vertices(); ++v)
    emit_vertex(VH(int(v)));
  out.positions.resize(vertices);
  out.normals.resize(vertices);
  if (scalars) out.scalars.resize(vertices);
  UnionFind pieces(vertices);
  std::size_t quads = 0;
  // Corners one by one: a range insert of three or four numbers was a memmove call per face
  // (docs/history/benchmarks-log.md, "Less fresh memory, fewer passes").
  auto emit_face = [&](std::span<const std::uint32_t> c, std::uint8_t view) {
    for (std::size_t k = 1; k < c.size(); ++k)
      pieces.join(c[0], c[k]);
    if (c.size() == 3) {
      for (std::uint32_t v : c)
        triangles.push_back(v);
      triangle_view.push_back(view);
    } else if (faces == FaceType::quads) {
      for (std::size_t k = 0; k < 4; ++k)
        put_at(out.quads, 4 * quads + k, c[k]);
      put_at(out.quad_view, quads++, view);
    } else {
      append_quad_triangles(out.positions, c.data(), triangles);
      triangle_view.insert(triangle_view.end(), {view, view});
    }
  };
  std::vector<std::uint32_t> c;
  auto emit_mesh_face = [&](FH f) {
    if (ms.mesh_.status(f).deleted()) return;
    c.clear();
    for (const auto& v : ms.mesh_.fv_range(f))
      c.push_back(index[v.idx()]);
    emit_face(
        c, ms.mesh_.property(ms.view_, ms.mesh_.from_vertex_handle(ms.mesh_.halfedge_handle(f))));
  };
  // A face outside as OpenMesh keeps an added face: corners from the first on, its half-edge
  // from the last corner (whose view the face takes).
  for (std::size_t f = 0; f < ms.region_.inside.size(); ++f) {
    if (ms.region_.inside[f]) {
      if (ms.input_face_[f].is_valid()) emit_mesh_face(ms.input_face_[f]);
      continue;
    }
    const auto corners = face_corners(ms.in_, f);
    c.clear();
    for (std::uint32_t v : corners)  // pinned corners are the region's
      c.push_back(ms.region_.local[v] != kNone ? index[ms.region_.local[v]] : outside[v]);
    emit_face(c, ms.region_.vertex_view[corners.back()]);
  }
  for (std::size_t f = ms.built_faces_; f < ms.mesh_.n_faces(); ++f)
    emit_mesh_face(FH(int(f)));
  out.quads.resize(4 * quads);
  out.quad_view.resize(quads);
  out.triangles = std::move(triangles);
  out.triangle_view = std::move(triangle_view);
  for (std::uint32_t v = 0; v < out.positions.size(); ++v)
    if (pieces.find(v) == v) ++ms.stats_.components;
  ms.stats_.unfilled_holes = ms.count_loops();
  renumber_moves(ms.moves_, index);
  return in_place ? Mesh() : std::move(fresh);
}

}  // namespace merge_detail

namespace {

using namespace merge_detail;

// The boundary layer's faces touch the region's seeds, their neighbours one ring further out:
// with fewer rings, removing the layer would open edges the region's mesh does not have.
constexpr int kMinRegionRings = 2;

// OpenMesh reports refused faces on its error stream; merging tests before adding and treats a
// refusal as "not added", so the stream is quiet while merging runs.
class QuietOpenMesh {
 public:
  QuietOpenMesh() : was_enabled_(omerr().is_enabled()) { omerr().disable(); }
  ~QuietOpenMesh() {
    if (was_enabled_) omerr().enable();
  }

 private:
  bool was_enabled_;
};

// Every face and vertex, numbered as in the input (no vertex pinned).
void make_whole(InputRegion& r, std::size_t faces) {
  r.whole = true;
  r.faces = faces;
  r.inside.assign(faces, 1);
  r.global.resize(r.used.size());
  std::iota(r.global.begin(), r.global.end(), 0u);
  r.local = r.global;
  r.pinned.clear();
}

InputRegion select_input_region(const Mesh& m, int rings) {
  InputRegion r;
  const std::size_t nv = m.positions.size(), nq = m.quad_count(), nf = nq + m.triangle_count();
  // The view each vertex gets: that of the last face using it (as building the mesh sets it).
  r.vertex_view.assign(nv, 0);
  r.used.assign(nv, 0);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto views = f < nq ? std::span(m.quad_view) : std::span(m.triangle_view);
    const std::size_t i = f < nq ? f : f - nq;
    for (std::uint32_t v : face_corners(m, f)) {
      r.used[v] = 1;
      if (i < views.size()) r.vertex_view[v] = views[i];
    }
  }
  if (rings < 0) {
    make_whole(r, nf);
    return r;
  }
  const VertexCorners at(m);
  const std::uint32_t quad_corners = at.quad_corners;
  // The corners after and before corner c in its face.
  auto around = [&](std::uint32_t c) {
    if (c < quad_corners) {
      const std::uint32_t base = c - c % 4;
      return std::pair(m.quads[base + (c + 1) % 4], m.quads[base + (c + 3) % 4]);
    }
    const std::uint32_t t = c - quad_corners, base = t - t % 3;
    return std::pair(m.triangles[base + (t % 3 + 1) % 3], m.triangles[base + (t % 3 + 2) % 3]);
  };
  // A vertex is inside a closed disk when the faces around it form one cycle in which each face's
  // incoming edge is the next face's outgoing edge, every edge used once each way: OpenMesh
  // accepts all those faces in any order. Anything else (an open boundary, a repeated or
  // one-way edge, two fans meeting at the vertex, a face with a repeated vertex) seeds the region.
  std::vector<std::uint8_t> in_vertex(nv, 0);
  std::vector<std::uint32_t> frontier;
  for (std::uint32_t v = 0; v < nv; ++v) {
    const std::span<const std::uint32_t> corners = at.at(v);
    const std::uint32_t n = std::uint32_t(corners.size());
    if (n == 0) continue;
    bool disk = n >= 3 && n <= 32;
    for (std::uint32_t i = 0; disk && i < n; ++i) {
      const auto [out, in] = around(corners[i]);
      if (out == v || in == v || out == in) disk = false;
    }
    if (disk) {
      // Walk: from a face, the next is the one whose outgoing edge runs back along this face's
      // incoming edge; exactly one must, and the walk must visit all n faces.
      std::uint32_t i = 0, visited = 0, seen = 0;
      do {
        const std::uint32_t in = around(corners[i]).second;
        std::uint32_t next = kNone, matches = 0;
        for (std::uint32_t j = 0; j < n; ++j)
          if (around(corners[j]).first == in) next = j, ++matches;
        if (matches != 1 || (seen >> next & 1u)) break;
        seen |= 1u << next;
        ++visited;
        i = next;
      } while (i != 0);
      disk = visited == n && seen == (n == 32 ? ~0u : (1u << n) - 1u);
    }
    if (!disk) {
      in_vertex[v] = 1;
      frontier.push_back(v);
    }
  }
  r.inside.assign(nf, 0);
  r.faces = grow_face_rings(m, at, rings + 1, std::move(frontier), in_vertex, r.inside);
  if (r.faces == nf) {
    make_whole(r, nf);
    return r;
  }
  r.whole = false;
  r.local.assign(nv, kNone);
  for (std::uint32_t v = 0; v < nv; ++v)
    if (in_vertex[v]) {
      r.local[v] = std::uint32_t(r.global.size());
      r.global.push_back(v);
    }
  r.pinned.assign(r.global.size(), 0);
  for (std::size_t f = 0; f < nf; ++f)
    if (!r.inside[f])
      for (std::uint32_t v : face_corners(m, f))
        if (r.local[v] != kNone) r.pinned[r.local[v]] = 1;
  return r;
}

// merge_views; with `writable` (the input mesh itself) and quad output, the result is written
// over the input's arrays.
Mesh merge_mesh(const Mesh& mesh, Mesh* writable, FaceType faces, const MergeOptions& options,
                MergeStats& stats, const SurfaceProjection& project) {
  stats = {};
  if (const Status s = check_mesh(mesh); !s)  // bad input gets a clear error
    throw std::invalid_argument("merge_views: " + s.message());
  const QuietOpenMesh quiet;
  const SurfaceProjection none;
  const SurfaceProjection& onto_surface = options.project ? project : none;
  // Views, boundary layer, bridges, holes, enhancement and the crossing check on the faces of
  // `region`; sets reached_edge when a step was refused at the region's edge.
  auto merge = [&](const InputRegion& region, bool& reached_edge) {
    auto start = std::chrono::steady_clock::now();
    MergeState merger(mesh, region, options, stats);
    if (options.remove_boundary_layer) remove_boundary_layer(merger);
    bridge(merger);
    stats.bridge_seconds += seconds_since(start);
    start = std::chrono::steady_clock::now();
    fill_holes(merger);
    stats.sew_seconds = seconds_since(start);
    start = std::chrono::steady_clock::now();
    if (options.enhance) enhance(merger, onto_surface);
    reached_edge = merger.reached_region_edge();
    if (reached_edge) {  // merged again on the whole mesh
      stats.quality_seconds = seconds_since(start);
      return Mesh();
    }
    Mesh* in_place = faces == FaceType::quads ? writable : nullptr;
    Mesh out = output(merger, faces, in_place);
    if (in_place) out = std::move(*in_place);
    // Projected vertices whose faces pass through other faces go back to their edge midpoints
    // (crossings.hpp): without the moves no face crossed; with them, Barth's merged meshes had
    // crossing pairs near its double points, where the cone's two nappes are a cell or two
    // apart.
    if (!merger.moved().empty() && merger.scale() > 0.0) {
      stats.crossings_undone = undo_crossing_moves(
          out, merger.moved(), std::max(1.0, options.split_length) * merger.scale(),
          options.crossing_min_move * merger.scale());
      stats.projected -= stats.crossings_undone;
    }
    stats.quality_seconds = seconds_since(start);
    return out;
  };
  auto start = std::chrono::steady_clock::now();
  // The region needs the length scale up front (the median edge would need every edge).
  const bool by_region = options.region_rings >= 0 && options.cell_size > 0.0;
  InputRegion region =
      select_input_region(mesh, by_region ? std::max(options.region_rings, kMinRegionRings) : -1);
  stats.bridge_seconds = seconds_since(start);
  bool reached_edge = false;
  Mesh out = merge(region, reached_edge);
  stats.region_faces = region.faces;
  if (reached_edge) {
    // A step wanted a face at the region's edge: merge the whole mesh instead (the times add
    // up in the bridge column).
    const double first = stats.bridge_seconds + stats.sew_seconds + stats.quality_seconds;
    stats = {};
    start = std::chrono::steady_clock::now();
    region = select_input_region(mesh, -1);
    stats.bridge_seconds = first + seconds_since(start);
    out = merge(region, reached_edge);
    stats.region_faces = region.faces;
  }
  if (faces == FaceType::quads && options.all_quads) {
    start = std::chrono::steady_clock::now();
    out = quadrangulate(std::move(out), options.quads, stats.quads, onto_surface);
    stats.quality_seconds += seconds_since(start);
  }
  return out;
}

}  // namespace

Mesh merge_views(const Mesh& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project) {
  return merge_mesh(mesh, nullptr, faces, options, stats, project);
}

Mesh merge_views(Mesh&& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project) {
  return merge_mesh(mesh, &mesh, faces, options, stats, project);
}

}  // namespace ldimesh
