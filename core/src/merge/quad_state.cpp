// The half-edge state of §5 (iv) quad mesh generation and its edits (quad_state.hpp).
#include "quad_state.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh::quad_detail {
namespace {

// Shortest over longest edge of the quad p[0..3] if it is convex seen along its (Newell) normal
// and that normal points the way of `normals` (the sum of its vertex normals); 0 otherwise.
double quad_quality(const std::array<glm::dvec3, 4>& p, const glm::dvec3& normals) {
  const glm::dvec3 n = newell_normal(p.data(), p.size());
  if (!(glm::dot(n, normals) > 0.0)) return 0.0;
  double shortest = std::numeric_limits<double>::infinity(), longest = 0.0;
  for (int i = 0; i < 4; ++i) {
    const glm::dvec3 in = p[i] - p[(i + 3) % 4], out = p[(i + 1) % 4] - p[i];
    if (!(glm::dot(glm::cross(in, out), n) > 0.0)) return 0.0;
    shortest = std::min(shortest, glm::length(out));
    longest = std::max(longest, glm::length(out));
  }
  return longest > 0.0 ? shortest / longest : 0.0;
}

}  // namespace

QuadState::QuadState(const QuadRegion& region, const QuadOptions& options, QuadStats& stats)
    : region_(region), options_(options), stats_(stats) {
  const Mesh& in = region.faces();
  const std::size_t nv = in.positions.size();
  // Room for what the paths add (Marschner–Lobb 512²: a fifth more half-edges, half as many
  // faces and vertices again): growing these arrays copied them over in the middle of the
  // paths. Reserved room costs address space only until it is used.
  const std::size_t faces = in.face_count(), halfedges = in.quads.size() + in.triangles.size();
  for (auto* v : {&pos_, &nrm_})
    v->reserve(nv + nv / 2);
  if (!in.scalars.empty()) scalar_.reserve(nv + nv / 2);
  for (auto* v : {&from_, &to_, &next_, &face_, &opp_})
    v->reserve(halfedges + halfedges / 2);
  face_he_.reserve(faces + faces / 2);
  for (auto* v : {&face_view_, &face_new_})
    v->reserve(faces + faces / 2);
  pos_.resize(nv);
  nrm_.resize(nv);
  for (std::size_t v = 0; v < nv; ++v) {
    pos_[v] = glm::dvec3(in.positions[v]);
    nrm_[v] = glm::dvec3(in.normals[v]);
  }
  scalar_.assign(in.scalars.begin(), in.scalars.end());
  stats_.region_faces = faces;
  auto add_faces = [&](const std::vector<std::uint32_t>& faces,
                       const std::vector<std::uint8_t>& views, std::size_t arity) {
    for (std::size_t f = 0; f * arity < faces.size(); ++f) {
      const std::uint32_t face = std::uint32_t(face_he_.size());
      const std::uint32_t first = std::uint32_t(to_.size());
      for (std::size_t k = 0; k < arity; ++k) {
        const std::uint32_t h = first + std::uint32_t(k);
        from_.push_back(faces[f * arity + k]);
        to_.push_back(faces[f * arity + (k + 1) % arity]);
        next_.push_back(k + 1 < arity ? h + 1 : first);
        face_.push_back(face);
      }
      face_he_.push_back(first);
      face_view_.push_back(views.empty() ? 0 : views[f]);
      face_new_.push_back(0);
    }
  };
  add_faces(in.quads, in.quad_view, 4);
  add_faces(in.triangles, in.triangle_view, 3);
  link_opposites();
  if (!region_.cut.empty()) {  // the region's edge to the quads outside
    cut_.assign(to_.size(), 0);
    for (std::uint32_t h = 0; h < to_.size(); ++h)
      if (opp_[h] == kNone)
        cut_[h] = std::binary_search(region_.cut.begin(), region_.cut.end(),
                                     directed_edge_key(from_[h], to_[h]));
  }
  // The length unit of the limits: the median edge.
  std::vector<double> lengths;
  for (std::uint32_t h = 0; h < to_.size(); ++h)
    if (opp_[h] == kNone || h < opp_[h]) lengths.push_back(length(h));
  median_edge_ = median_of(lengths, median_edge_);
  stats_.median_edge = median_edge_;
}

void QuadState::link_opposites() {
  const std::size_t nv = pos_.size();
  std::vector<std::uint32_t> start(nv + 1, 0);
  for (std::uint32_t v : from_)
    ++start[v + 1];
  for (std::size_t v = 0; v < nv; ++v)
    start[v + 1] += start[v];
  std::vector<std::uint32_t> leaving(from_.size()), fill(start.begin(), start.end() - 1);
  for (std::uint32_t h = 0; h < from_.size(); ++h)
    leaving[fill[from_[h]]++] = h;
  opp_.assign(to_.size(), kNone);
  std::atomic<bool> twice{false};
  tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, std::uint32_t(to_.size()), 8192),
                    [&](const auto& r) {
                      for (std::uint32_t h = r.begin(); h < r.end(); ++h) {
                        const std::uint32_t u = from_[h], v = to_[h];
                        for (std::uint32_t k = start[u]; k < start[u + 1]; ++k)
                          if (leaving[k] != h && to_[leaving[k]] == v) twice = true;
                        for (std::uint32_t k = start[v]; k < start[v + 1]; ++k)
                          if (to_[leaving[k]] == u) opp_[h] = leaving[k];
                      }
                    });
  if (twice)
    throw std::invalid_argument(
        "quadrangulate: an edge is used twice in one direction (not an oriented manifold)");
}

std::size_t QuadState::face_size(std::uint32_t f) const {
  std::size_t n = 0;
  std::uint32_t h = face_he_[f];
  do {
    ++n;
    h = next_[h];
  } while (h != face_he_[f]);
  return n;
}

std::uint32_t QuadState::prev(std::uint32_t h) const {
  std::uint32_t p = h;
  while (next_[p] != h)
    p = next_[p];
  return p;
}

double QuadState::quality(const std::array<std::uint32_t, 4>& v) const {
  return quad_quality({pos_[v[0]], pos_[v[1]], pos_[v[2]], pos_[v[3]]},
                      nrm_[v[0]] + nrm_[v[1]] + nrm_[v[2]] + nrm_[v[3]]);
}

bool QuadState::faces_its_normals(const std::array<std::uint32_t, 4>& v) const {
  const std::array<glm::dvec3, 4> p{pos_[v[0]], pos_[v[1]], pos_[v[2]], pos_[v[3]]};
  return glm::dot(newell_normal(p.data(), p.size()),
                  nrm_[v[0]] + nrm_[v[1]] + nrm_[v[2]] + nrm_[v[3]]) > 0.0;
}

glm::dvec3 QuadState::centroid(std::uint32_t f) const {
  glm::dvec3 c(0.0);
  double n = 0.0;
  std::uint32_t h = face_he_[f];
  do {
    c += pos_[to_[h]];
    n += 1.0;
    h = next_[h];
  } while (h != face_he_[f]);
  return c / n;
}

std::uint32_t QuadState::add_vertex(std::initializer_list<std::uint32_t> vs) {
  glm::dvec3 p(0.0), n(0.0);
  double s = 0.0;
  for (std::uint32_t v : vs) {
    p += pos_[v];
    n += nrm_[v];
    if (!scalar_.empty()) s += scalar_[v];
  }
  const double count = double(vs.size());
  const double len = glm::length(n);
  pos_.push_back(p / count);
  nrm_.push_back(len > 0.0 ? n / len : nrm_[*vs.begin()]);
  if (!scalar_.empty()) scalar_.push_back(float(s / count));
  return std::uint32_t(pos_.size() - 1);
}

std::uint32_t QuadState::add_halfedge(std::uint32_t from, std::uint32_t to, std::uint32_t face) {
  from_.push_back(from);
  to_.push_back(to);
  next_.push_back(kNone);
  opp_.push_back(kNone);
  face_.push_back(face);
  return std::uint32_t(to_.size() - 1);
}

void QuadState::split_edge(std::uint32_t h, std::uint32_t m) {
  const std::uint32_t o = opp_[h];
  const std::uint32_t h2 = add_halfedge(m, to_[h], face_[h]);
  next_[h2] = next_[h];
  next_[h] = h2;
  to_[h] = m;
  if (o == kNone) return;
  const std::uint32_t o2 = add_halfedge(m, to_[o], face_[o]);
  next_[o2] = next_[o];
  next_[o] = o2;
  to_[o] = m;
  opp_[h] = o2, opp_[o2] = h;
  opp_[h2] = o, opp_[o] = h2;
}

std::uint32_t QuadState::split_face(std::uint32_t ha, std::uint32_t hb) {
  const std::uint32_t f = face_[ha];
  const std::uint32_t g = std::uint32_t(face_he_.size());
  face_he_.push_back(hb);
  face_view_.push_back(face_view_[f]);
  face_new_.push_back(1);
  const std::uint32_t an = next_[ha], bn = next_[hb];
  const std::uint32_t n = add_halfedge(to_[ha], to_[hb], f);
  const std::uint32_t n2 = add_halfedge(to_[hb], to_[ha], g);
  opp_[n] = n2, opp_[n2] = n;
  next_[ha] = n, next_[n] = bn;
  next_[hb] = n2, next_[n2] = an;
  for (std::uint32_t h = an; h != n2; h = next_[h])
    face_[h] = g;
  face_he_[f] = ha;
  return n2;
}

void QuadState::build_vertex_rings() {
  const std::size_t nv = pos_.size();
  out_he_.assign(nv, kNone);
  valence_.assign(nv, 0);
  boundary_.assign(nv, 0);
  for (std::uint32_t h = 0; h < to_.size(); ++h) {
    if (face_[h] == kNone) continue;
    if (out_he_[from_[h]] == kNone) out_he_[from_[h]] = h;
    ++valence_[from_[h]];
    if (opp_[h] == kNone) {
      ++valence_[to_[h]];
      boundary_[from_[h]] = boundary_[to_[h]] = 1;
    }
  }
}

bool QuadState::adjacent(std::uint32_t a, std::uint32_t b) const {
  const std::uint32_t start = out_he_[a];
  std::uint32_t h = start;
  do {
    if (to_[h] == b) return true;
    const std::uint32_t p = prev(h);
    if (opp_[p] == kNone) {
      if (from_[p] == b) return true;
      for (h = start; opp_[h] != kNone;) {
        h = next_[opp_[h]];
        if (to_[h] == b) return true;
      }
      return false;
    }
    h = opp_[p];
  } while (h != start);
  return false;
}

int QuadState::energy(std::uint32_t v, int change) const {
  const int d = int(valence_[v]) + change - ideal(v);
  return d * d;
}

}  // namespace ldimesh::quad_detail
