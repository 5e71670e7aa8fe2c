#include "merge_state.hpp"

#include <algorithm>
#include <cmath>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh::merge_detail {

MergeState::MergeState(const Mesh& in, const InputRegion& region, const MergeOptions& options,
                       MergeStats& stats)
    : in_(in), region_(region), options_(options), stats_(stats) {
  mesh_.add_property(kind_);
  mesh_.add_property(view_);
  mesh_.add_property(scalar_);
  // Room for the region and the faces merging adds: growing OpenMesh's arrays one face at a
  // time copied them over and over. Deleted faces keep their slots (no garbage collection):
  // what merging adds is proportional to the open boundaries, which a region is built around,
  // so it takes three to six times the region's faces in all (Marschner–Lobb 512² 3.0, Barth
  // 128² 5.6), twice its edges and a third more vertices; the whole mesh, half as many faces
  // again. Reserved room costs address space only until it is used.
  const std::size_t nq = in.quad_count(), nf = nq + in.triangle_count();
  const std::size_t faces = region.faces, vertices = region.global.size();
  const std::size_t edges = 2 * faces + faces / 8;
  if (region.whole)
    mesh_.reserve(vertices + faces / 8, edges + edges / 2, faces + faces / 2);
  else
    mesh_.reserve(vertices + vertices / 2, 5 * edges / 2, 6 * faces);
  for (std::size_t i = 0; i < vertices; ++i) {
    const std::uint32_t v = region.global[i];
    const VH vh = mesh_.add_vertex({in.positions[v].x, in.positions[v].y, in.positions[v].z});
    mesh_.set_normal(vh, {in.normals[v].x, in.normals[v].y, in.normals[v].z});
    mesh_.property(scalar_, vh) = in.scalars.empty() ? 0.0f : in.scalars[v];
    mesh_.property(view_, vh) = region.vertex_view[v];
  }
  // The region's faces in input order.
  input_face_.assign(nf, FH());
  std::vector<VH> vs;
  for (std::size_t f = 0; f < nf; ++f) {
    if (!region.inside[f]) continue;
    vs.clear();
    for (std::uint32_t v : face_corners(in, f))
      vs.emplace_back(int(region.local[v]));
    input_face_[f] = insert(vs, Kind::kInput);
    if (!input_face_[f].is_valid()) ++stats_.dropped_faces;
  }
  built_faces_ = mesh_.n_faces();
  built_ = true;
  // The length scale for the limits: the LDI cell size when the caller knows it (refined
  // meshes have many short edges, their median would make every limit too tight), else the
  // median edge of the input.
  scale_ = options.cell_size;
  std::vector<double> lengths;
  if (!(scale_ > 0.0))
    for (const auto& e : mesh_.edges())
      lengths.push_back(length(e.halfedge(0)));
  scale_ = median_of(lengths, scale_);
}

bool MergeState::is_triangle(FH f) const {
  const HH h = mesh_.halfedge_handle(f);
  return mesh_.next_halfedge_handle(mesh_.next_halfedge_handle(mesh_.next_halfedge_handle(h))) == h;
}

double MergeState::length(HH h) const {
  return glm::distance(point(mesh_.from_vertex_handle(h)), point(mesh_.to_vertex_handle(h)));
}

FH MergeState::insert(const std::vector<VH>& vs, Kind kind) {
  const std::size_t n = vs.size();
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j)
      if (vs[i] == vs[j]) return FH();
  // After the build, a face at the region's edge would differ from the whole mesh's (there
  // its vertices are inside closed disks and take no face): refused, and merging runs again
  // on the whole mesh.
  if (built_)
    for (VH v : vs)
      if (is_pinned(v)) {
        ++cut_touched_;
        return FH();
      }
  const FH f = mesh_.add_face(vs);
  if (!f.is_valid()) return FH();
  mesh_.property(kind_, f) = kind;
  if (kind != Kind::kInput) region_faces_.push_back(f);
  return f;
}

std::uint32_t MergeState::global(VH v) const {
  const std::uint32_t i = std::uint32_t(v.idx());
  return i < region_.global.size()
             ? region_.global[i]
             : std::uint32_t(in_.positions.size() + (i - region_.global.size()));
}

void MergeState::erase(FH f, bool delete_isolated_vertices) {
  if (built_)
    for (const auto& v : mesh_.fv_range(f))
      if (is_pinned(v)) ++cut_touched_;
  mesh_.delete_face(f, delete_isolated_vertices);
}

bool MergeState::is_pinned(VH v) const {
  return std::size_t(v.idx()) < region_.pinned.size() && region_.pinned[v.idx()];
}

bool MergeState::is_cut(HH h) const {
  return mesh_.is_boundary(h) && is_pinned(mesh_.from_vertex_handle(h)) &&
         is_pinned(mesh_.to_vertex_handle(h));
}

bool MergeState::faces_its_normals(std::initializer_list<VH> vs) const {
  std::array<glm::dvec3, 4> p;  // triangles and quads
  std::size_t count = 0;
  glm::dvec3 n(0.0);
  for (VH v : vs) {
    p[count++] = point(v);
    n += to_glm(mesh_.normal(v));
  }
  const glm::dvec3 face = newell_normal(p.data(), count);
  const double a = glm::length(face), b = glm::length(n);
  return a > 0.0 && b > 0.0 && glm::dot(face, n) >= options_.min_facing * a * b;
}

bool MergeState::spans_surface(VH a, VH b) const {
  return glm::dot(to_glm(mesh_.normal(a)), to_glm(mesh_.normal(b))) >= options_.min_normal_dot;
}

bool MergeState::ear_is_convex(VH u, VH v, VH w, bool strict) const {
  const glm::dvec3 U = point(u), V = point(v), W = point(w);
  const glm::dvec3 n = glm::cross(V - U, W - V);
  const double scale = glm::distance(U, V) * glm::distance(V, W);
  if (!(glm::length(n) > (strict ? 0.05 : 0.01) * scale)) return false;  // not a straight run
  if (strict) return faces_its_normals({u, v, w});
  const glm::dvec3 normals =
      to_glm(mesh_.normal(u)) + to_glm(mesh_.normal(v)) + to_glm(mesh_.normal(w));
  return glm::dot(n, normals) > 0.0;
}

std::size_t MergeState::count_loops() const {
  std::vector<std::uint8_t> seen(mesh_.n_halfedges(), 0);
  std::size_t loops = 0;
  for (const auto& h : mesh_.halfedges()) {
    if (!is_open(h) || seen[h.idx()]) continue;
    ++loops;
    HH g = h;
    do {
      seen[g.idx()] = 1;
      g = mesh_.next_halfedge_handle(g);
    } while (g != HH(h) && !seen[g.idx()]);
  }
  return loops;
}

std::vector<HH> MergeState::region_edges() {
  std::erase_if(region_faces_, [&](FH f) { return mesh_.status(f).deleted(); });
  // Marks instead of sorting: a scan over the marks is ordered and far cheaper than sorting
  // the region's half-edges (docs/history/benchmarks-log.md, "Merging (§5)").
  edge_mark_.assign(mesh_.n_edges(), 0);
  for (FH f : region_faces_)
    mark_edges(f);
  return marked_edges();
}

void MergeState::mark_edges(FH f) {
  for (const auto& h : mesh_.fh_range(f))
    edge_mark_[mesh_.edge_handle(h).idx()] = 1;
}

std::vector<HH> MergeState::marked_edges() const {
  std::vector<HH> edges;
  for (std::size_t e = 0; e < edge_mark_.size(); ++e)
    if (edge_mark_[e]) edges.push_back(mesh_.halfedge_handle(OpenMesh::EdgeHandle(int(e)), 0));
  return edges;
}

VH MergeState::split(HH h) {
  const HH o = mesh_.opposite_halfedge_handle(h);
  const FH f = mesh_.face_handle(h), g = mesh_.face_handle(o);
  const VH a = mesh_.from_vertex_handle(h), b = mesh_.to_vertex_handle(h);
  const VH c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h));
  const VH d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(o));
  if (c == d) return VH();
  const Kind kf = mesh_.property(kind_, f), kg = mesh_.property(kind_, g);
  const glm::dvec3 n = to_glm(mesh_.normal(a)) + to_glm(mesh_.normal(b));
  const VH m = mesh_.add_vertex(mesh_.calc_edge_midpoint(mesh_.edge_handle(h)));
  mesh_.set_normal(m, glm::length(n) > 0.0 ? to_om(glm::normalize(n)) : mesh_.normal(a));
  mesh_.property(scalar_, m) = 0.5f * (mesh_.property(scalar_, a) + mesh_.property(scalar_, b));
  mesh_.property(view_, m) = mesh_.property(view_, a);
  erase(f, false);
  erase(g, false);
  if (add({a, m, c}, kf) && add({m, b, c}, kf) && add({b, m, d}, kg) && add({m, a, d}, kg))
    return m;
  // OpenMesh refused: take the new faces away (m stays isolated, output skips it) and put the
  // two triangles back.
  std::vector<FH> added;
  for (const auto& f2 : mesh_.vf_range(m))
    added.push_back(f2);
  for (FH f2 : added)
    erase(f2, false);
  if (!add({a, b, c}, kf) || !add({b, a, d}, kg)) ++stats_.lost_faces;
  return VH();
}

glm::dvec3 MergeState::face_normal(FH f) const {
  std::array<glm::dvec3, 4> p;
  std::size_t count = 0;
  for (const auto& v : mesh_.fv_range(f))
    if (count < p.size()) p[count++] = point(v);
  return newell_normal(p.data(), count);
}

void MergeState::set_point(VH v, glm::dvec3 p, glm::dvec3 n) {
  mesh_.set_point(v, to_om(p));
  mesh_.set_normal(v, to_om(n));
}

HH MergeState::try_flip(HH h) {
  const HH o = mesh_.opposite_halfedge_handle(h);
  const FH f = mesh_.face_handle(h), g = mesh_.face_handle(o);
  if (!in_region(f) || !in_region(g) || !is_triangle(f) || !is_triangle(g)) return HH();
  const VH a = mesh_.from_vertex_handle(h), b = mesh_.to_vertex_handle(h);
  const VH c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h));
  const VH d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(o));
  // At the region's edge the valences are not the whole mesh's (see insert).
  if (is_pinned(a) || is_pinned(b) || is_pinned(c) || is_pinned(d)) {
    ++cut_touched_;
    return HH();
  }
  // Cheapest tests first: most edges of the region are not longer than their other diagonal.
  if (c == d || glm::distance(point(c), point(d)) >= glm::distance(point(a), point(b))) return HH();
  if (mesh_.find_halfedge(c, d).is_valid()) return HH();
  if (mesh_.valence(a) <= 3 || mesh_.valence(b) <= 3) return HH();
  if (!faces_its_normals({a, d, c}) || !faces_its_normals({d, b, c})) return HH();
  // The flip must not fold the pair more sharply than it is: where two sheets meet (Barth's
  // double points) the other diagonal of a folded pair cuts through the other sheet (without
  // this, Barth 64² kept three crossing pairs; with it none, and the same forward mean).
  auto cosine = [&](VH p, VH q, VH r, VH s, VH t, VH u) {
    const glm::dvec3 n1 = glm::cross(point(q) - point(p), point(r) - point(p));
    const glm::dvec3 n2 = glm::cross(point(t) - point(s), point(u) - point(s));
    return glm::dot(n1, n2) / (glm::length(n1) * glm::length(n2));
  };
  if (!(cosine(a, d, c, d, b, c) >= cosine(a, b, c, b, a, d))) return HH();
  const Kind kf = mesh_.property(kind_, f), kg = mesh_.property(kind_, g);
  erase(f, false);
  erase(g, false);
  if (add({a, d, c}, kf)) {
    if (add({d, b, c}, kg)) return mesh_.find_halfedge(c, d);
    erase(mesh_.face_handle(mesh_.find_halfedge(a, d)), false);
  }
  // Put the two triangles back as they were (OpenMesh refused the flip).
  if (!add({a, b, c}, kf) || !add({b, a, d}, kg)) ++stats_.lost_faces;
  return HH();
}

bool MergeState::try_merge(VH v) {
  std::vector<HH> outer;
  std::vector<FH> fan;
  for (const auto& h : mesh_.voh_range(v)) {
    const FH f = mesh_.face_handle(h);
    if (!in_region(f) || !is_triangle(f)) return false;
    fan.push_back(f);
    outer.push_back(mesh_.next_halfedge_handle(h));  // the edge of f opposite v
  }
  if (fan.size() != 3) return false;
  const VH a = mesh_.from_vertex_handle(outer[0]), b = mesh_.to_vertex_handle(outer[0]);
  VH c = mesh_.to_vertex_handle(outer[1]);
  if (mesh_.from_vertex_handle(outer[1]) != b) c = mesh_.to_vertex_handle(outer[2]);
  const glm::dvec3 V = point(v), A = point(a) - V, B = point(b) - V, C = point(c) - V;
  const double mean = (glm::length(A) + glm::length(B) + glm::length(C)) / 3.0;
  if (std::abs(glm::dot(A, glm::cross(B, C))) >= options_.coplanar * mean * mean * mean)
    return false;
  if (!faces_its_normals({a, b, c})) return false;
  for (FH f : fan)
    erase(f, true);
  if (add({a, b, c}, Kind::kFill)) return true;
  ++stats_.lost_faces;  // the fan's vertex is gone: the hole stays and is counted
  return false;
}

}  // namespace ldimesh::merge_detail
