#include "ldimesh/core/merge/crossings.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh {
namespace {

// f(i) for i in [0, n), in parallel.
template <class F>
void parallel_each(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
    for (std::size_t i = r.begin(); i < r.end(); ++i)
      f(i);
  });
}

struct Bounds {
  glm::dvec3 lo, hi;
  Bounds(const glm::dvec3& l, const glm::dvec3& h) : lo(l), hi(h) {}
  explicit Bounds(const CrossingPolygon& g) : lo(g.p[0]), hi(g.p[0]) {
    for (std::size_t i = 1; i < g.n; ++i)
      lo = glm::min(lo, g.p[i]), hi = glm::max(hi, g.p[i]);
  }
};

// A face around a moved vertex as the test reads it: float corners (the mesh's own) and vertex
// ids in one cache line, half of a CrossingPolygon's two (the tests read stars at random).
struct alignas(64) Star {
  std::array<glm::vec3, 4> p;
  std::array<std::uint32_t, 4> v;  // v[3] = UINT32_MAX: a triangle
  std::size_t n() const { return v[3] == UINT32_MAX ? 3 : 4; }
  CrossingPolygon polygon() const {
    CrossingPolygon g;
    g.n = n();
    for (std::size_t k = 0; k < g.n; ++k)
      g.p[k] = glm::dvec3(p[k]), g.v[k] = v[k];
    return g;
  }
  Bounds bounds() const {
    glm::vec3 lo = p[0], hi = p[0];
    for (std::size_t k = 1; k < n(); ++k)
      lo = glm::min(lo, p[k]), hi = glm::max(hi, p[k]);
    return Bounds(glm::dvec3(lo), glm::dvec3(hi));
  }
};

// Cells of one size over a box, numbered x fastest, at most kMaxCells of them (the size given,
// doubled until they fit: any size finds the same pairs, a coarser one tests more). Dense
// numbers instead of hashed keys: a cell's bit and its entries are a few instructions away.
class CellGrid {
 public:
  CellGrid() = default;
  CellGrid(const glm::dvec3& lo, const glm::dvec3& hi, double size) : origin_(lo), size_(size) {
    auto cells = [&] { return glm::floor((hi - lo) / size_) + 1.0; };  // in double: no overflow
    while (cells().x * cells().y * cells().z > double(kMaxCells))
      size_ *= 2.0;
    dims_ = glm::ivec3(cells());
  }
  std::size_t size() const { return std::size_t(dims_.x) * dims_.y * dims_.z; }
  // The cell holding p, per axis clamped to [-1, dims] (before the conversion to int).
  glm::ivec3 cell(const glm::dvec3& p) const {
    return glm::ivec3(
        glm::clamp(glm::floor((p - origin_) / size_), glm::dvec3(-1.0), glm::dvec3(dims_)));
  }
  bool inside(const glm::ivec3& c) const {
    return glm::all(glm::greaterThanEqual(c, glm::ivec3(0))) && glm::all(glm::lessThan(c, dims_));
  }
  std::size_t index(const glm::ivec3& c) const {
    return (std::size_t(c.z) * dims_.y + c.y) * dims_.x + c.x;
  }
  // Calls f(index, cell) for the cells of the box (clipped to the grid) until f returns true.
  template <class F>
  bool visit(const Bounds& b, F&& f) const {
    const glm::ivec3 a = glm::max(cell(b.lo), glm::ivec3(0));
    const glm::ivec3 c = glm::min(cell(b.hi), dims_ - 1);
    for (int z = a.z; z <= c.z; ++z)
      for (int y = a.y; y <= c.y; ++y) {
        const std::size_t row = (std::size_t(z) * dims_.y + y) * dims_.x;
        for (int x = a.x; x <= c.x; ++x)
          if (f(row + x, glm::ivec3(x, y, z))) return true;
      }
    return false;
  }

 private:
  static constexpr std::uint64_t kMaxCells = std::uint64_t(1) << 26;  // 8 MB of bits
  glm::dvec3 origin_{0.0};
  double size_ = 1.0;
  glm::ivec3 dims_{0};
};

// A set of a grid's cells as bits; after rank(), each set cell's number among the set ones.
class CellSet {
 public:
  explicit CellSet(std::size_t cells) : bits_((cells + 63) / 64, 0) {}
  // Safe from several threads at once (the bits end up the same in any order).
  void insert(std::size_t i) {
    std::atomic_ref<std::uint64_t>(bits_[i / 64])
        .fetch_or(std::uint64_t(1) << (i % 64), std::memory_order_relaxed);
  }
  bool contains(std::size_t i) const { return (bits_[i / 64] >> (i % 64) & 1u) != 0; }
  // Numbers the set cells in index order; returns how many there are.
  std::uint32_t rank() {
    before_.resize(bits_.size());
    std::uint32_t n = 0;
    for (std::size_t w = 0; w < bits_.size(); ++w) {
      before_[w] = n;
      n += std::uint32_t(std::popcount(bits_[w]));
    }
    return n;
  }
  // A set cell's number (after rank()).
  std::uint32_t number(std::size_t i) const {
    const std::uint64_t below = (std::uint64_t(1) << (i % 64)) - 1;
    return before_[i / 64] + std::uint32_t(std::popcount(bits_[i / 64] & below));
  }

 private:
  std::vector<std::uint64_t> bits_;
  std::vector<std::uint32_t> before_;  // per word: set bits in the words before
};

// A cell → stars table over the stars' box: the cells star boxes touch as bits, and per touched
// cell its (star, star box) entries (counting sort: one pass to count, one to place, both in
// parallel; a cell's entries come in any order, which changes no result: the
// vertices found are sorted). The boxes sit in the entries (floats, rounded outward) so that a
// cell's candidates are read in one sweep instead of one cache miss each.
class StarGrid {
 public:
  StarGrid(const std::vector<Star>& stars, double cell) {
    if (stars.empty()) return;
    // Each star's box in floats, rounded outward: what the entries hold, and what the grid's
    // cells are found from (the cell where a pair is tested must be one both were entered in).
    std::vector<Entry> boxes(stars.size());
    parallel_each(stars.size(), [&](std::size_t s) {
      const Bounds b = stars[s].bounds();
      Entry& e = boxes[s];
      e.star = std::uint32_t(s);
      for (int k = 0; k < 3; ++k) {
        e.lo[k] = round_down(b.lo[k]);
        e.hi[k] = -round_down(-b.hi[k]);
      }
    });
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
    double extent = 0.0;  // of the boxes' longest sides
    for (const Entry& e : boxes) {
      const Bounds b = e.bounds();
      lo = glm::min(lo, b.lo), hi = glm::max(hi, b.hi);
      const glm::dvec3 d = b.hi - b.lo;
      extent += std::max({d.x, d.y, d.z});
    }
    // Cells no narrower than the mean box: a box spans a few cells, whatever `cell` is.
    grid_ = CellGrid(lo, hi, std::max(cell, extent / double(boxes.size())));
    touched_ = CellSet(grid_.size());
    parallel_each(boxes.size(), [&](std::size_t s) {
      grid_.visit(boxes[s].bounds(), [&](std::size_t i, const glm::ivec3&) {
        touched_.insert(i);
        return false;
      });
    });
    first_.assign(std::size_t(touched_.rank()) + 1, 0);
    parallel_each(boxes.size(), [&](std::size_t s) {
      grid_.visit(boxes[s].bounds(), [&](std::size_t i, const glm::ivec3&) {
        std::atomic_ref<std::uint32_t>(first_[touched_.number(i) + 1])
            .fetch_add(1, std::memory_order_relaxed);
        return false;
      });
    });
    for (std::size_t c = 1; c < first_.size(); ++c)
      first_[c] += first_[c - 1];
    entries_.resize(first_.back());
    std::vector<std::uint32_t> fill(first_.begin(), first_.end() - 1);
    parallel_each(boxes.size(), [&](std::size_t s) {
      grid_.visit(boxes[s].bounds(), [&](std::size_t i, const glm::ivec3&) {
        const std::uint32_t at = std::atomic_ref<std::uint32_t>(fill[touched_.number(i)])
                                     .fetch_add(1, std::memory_order_relaxed);
        entries_[at] = boxes[s];
        return false;
      });
    });
  }
  // Calls f(star) for each star whose box overlaps b, in the cell where both boxes' common part
  // starts (the cell of the larger low corner, per axis: cells grow with the coordinates), so
  // once per star.
  template <class F>
  void for_each_overlapping(const Bounds& b, F&& f) const {
    if (entries_.empty()) return;
    const glm::ivec3 lo_cell = grid_.cell(b.lo);
    grid_.visit(b, [&](std::size_t i, const glm::ivec3& at) {
      if (!touched_.contains(i)) return false;
      const std::uint32_t c = touched_.number(i);
      for (std::uint32_t k = first_[c]; k < first_[c + 1]; ++k) {
        const Entry& e = entries_[k];
        if (b.lo.x <= e.hi[0] && e.lo[0] <= b.hi.x && b.lo.y <= e.hi[1] && e.lo[1] <= b.hi.y &&
            b.lo.z <= e.hi[2] && e.lo[2] <= b.hi.z &&
            glm::max(lo_cell, grid_.cell(glm::dvec3(e.lo[0], e.lo[1], e.lo[2]))) == at)
          f(e.star);
      }
      return false;
    });
  }

 private:
  // The largest float not above x (nextafter only where the nearest float is above it).
  static float round_down(double x) {
    const float f = float(x);
    return double(f) <= x ? f : std::nextafter(f, -std::numeric_limits<float>::infinity());
  }
  struct Entry {
    std::uint32_t star;
    float lo[3], hi[3];
    Bounds bounds() const {
      return Bounds(glm::dvec3(lo[0], lo[1], lo[2]), glm::dvec3(hi[0], hi[1], hi[2]));
    }
  };
  CellGrid grid_;
  CellSet touched_{0};
  std::vector<std::uint32_t> first_;  // per touched cell (in index order): its first entry
  std::vector<Entry> entries_;
};

// The cells (of a grid `cell` wide or wider) that the stars' boxes grown by `reach` touch: a
// point outside them is farther than `reach` (along some axis) from every star's box.
class NearCells {
 public:
  NearCells(const std::vector<Star>& stars, double reach) {
    if (stars.empty()) return;
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
    for (const Star& g : stars) {
      const Bounds b = g.bounds();
      lo = glm::min(lo, b.lo - reach), hi = glm::max(hi, b.hi + reach);
    }
    grid_ = CellGrid(lo, hi, reach);
    cells_ = CellSet(grid_.size());
    parallel_each(stars.size(), [&](std::size_t s) {
      const Bounds b = stars[s].bounds();
      grid_.visit(Bounds(b.lo - reach, b.hi + reach), [&](std::size_t i, const glm::ivec3&) {
        cells_.insert(i);
        return false;
      });
    });
  }
  bool contains(const glm::dvec3& p) const {
    const glm::ivec3 c = grid_.cell(p);
    return grid_.inside(c) && cells_.contains(grid_.index(c));
  }

 private:
  CellGrid grid_;
  CellSet cells_{0};
};

}  // namespace

bool polygons_cross(const CrossingPolygon& a, const CrossingPolygon& b) {
  // Per corner of a, the bit of the b corner it is. Triangles that share a corner are not
  // tested (neighbours meet at a vertex or an edge); the other triangles of neighbouring faces
  // are (a face folded over its neighbour).
  std::array<unsigned, 4> same{};
  for (std::size_t i = 0; i < a.n; ++i)
    for (std::size_t j = 0; j < b.n; ++j)
      if (a.v[i] == b.v[j]) same[i] = 1u << j;
  // The triangle pairs to test: (i, j) with bit 4 i + j (no shared corner).
  static constexpr std::array<std::array<int, 3>, 4> kCorners{
      {{0, 1, 2}, {0, 2, 3}, {1, 2, 3}, {1, 3, 0}}};
  const std::size_t na = a.n == 3 ? 1 : 4, nb = b.n == 3 ? 1 : 4;
  unsigned pairs = 0;
  for (std::size_t i = 0; i < na; ++i) {
    const auto& c = kCorners[i];
    const unsigned touched = same[c[0]] | same[c[1]] | same[c[2]];
    for (std::size_t j = 0; j < nb; ++j) {
      const auto& d = kCorners[j];
      if (!(touched & ((1u << d[0]) | (1u << d[1]) | (1u << d[2])))) pairs |= 1u << (4 * i + j);
    }
  }
  if (pairs == 0) return false;  // the same face, or neighbouring triangles
  // Signed distances (unnormalised) of one face's corners to the planes of the other's
  // triangles: a triangle wholly on one side of the other's plane cannot meet it (the cheap
  // test that settles most pairs of nearby faces of a smooth surface).
  auto sides = [](const CrossingPolygon& f, std::size_t n, const CrossingPolygon& g,
                  std::array<std::array<double, 4>, 4>& d) {
    for (std::size_t i = 0; i < n; ++i) {
      const auto& c = kCorners[i];
      const glm::dvec3 normal = glm::cross(f.p[c[1]] - f.p[c[0]], f.p[c[2]] - f.p[c[0]]);
      for (std::size_t k = 0; k < g.n; ++k)
        d[i][k] = glm::dot(normal, g.p[k] - f.p[c[0]]);
    }
  };
  std::array<std::array<double, 4>, 4> to_a, to_b;  // b's corners to a's planes, a's to b's
  sides(a, na, b, to_a);
  sides(b, nb, a, to_b);
  auto apart = [](const std::array<double, 4>& d, const std::array<int, 3>& c) {
    return (d[c[0]] > 0.0 && d[c[1]] > 0.0 && d[c[2]] > 0.0) ||
           (d[c[0]] < 0.0 && d[c[1]] < 0.0 && d[c[2]] < 0.0);
  };
  for (std::size_t i = 0; i < na; ++i)
    for (std::size_t j = 0; j < nb; ++j) {
      if (!(pairs & (1u << (4 * i + j)))) continue;
      const auto &ci = kCorners[i], &cj = kCorners[j];
      if (apart(to_b[j], ci) || apart(to_a[i], cj)) continue;
      const std::array<glm::dvec3, 3> s{a.p[ci[0]], a.p[ci[1]], a.p[ci[2]]},
          t{b.p[cj[0]], b.p[cj[1]], b.p[cj[2]]};
      for (int k = 0; k < 3; ++k)
        if (segment_crosses_triangle(s[k], s[(k + 1) % 3], t[0], t[1], t[2]) ||
            segment_crosses_triangle(t[k], t[(k + 1) % 3], s[0], s[1], s[2]))
          return true;
    }
  return false;
}

void renumber_moves(std::vector<VertexMove>& moves, std::span<const std::uint32_t> index) {
  std::size_t kept = 0;
  for (const VertexMove& m : moves)
    if (m.vertex < index.size() && index[m.vertex] != UINT32_MAX)
      moves[kept++] = {index[m.vertex], m.position, m.normal};
  moves.resize(kept);
}

std::size_t undo_crossing_moves(Mesh& mesh, std::span<const VertexMove> moves, double cell,
                                double min_move, int max_rounds) {
  if (!(cell > 0.0) || !std::isfinite(cell))
    throw std::invalid_argument("undo_crossing_moves: the cell size must be positive");
  const std::size_t nv = mesh.positions.size();
  if (mesh.normals.size() != nv)
    throw std::invalid_argument("undo_crossing_moves: one normal per vertex needed");
  if (mesh.triangles.size() % 3 != 0 || mesh.quads.size() % 4 != 0)
    throw std::invalid_argument("undo_crossing_moves: incomplete face");
  const std::size_t nt = mesh.triangle_count(), nf = nt + mesh.quad_count();
  for (std::uint32_t v : mesh.triangles)
    if (v >= nv) throw std::invalid_argument("undo_crossing_moves: face vertex out of range");
  for (std::uint32_t v : mesh.quads)
    if (v >= nv) throw std::invalid_argument("undo_crossing_moves: face vertex out of range");
  for (const glm::vec3& p : mesh.positions)
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw std::invalid_argument("undo_crossing_moves: a position is not finite");
  std::vector<std::uint32_t> move_of(nv, UINT32_MAX);  // vertex → its (first) entry in moves
  std::vector<std::uint32_t> check;
  for (std::uint32_t i = 0; i < moves.size(); ++i) {
    const std::uint32_t v = moves[i].vertex;
    if (v >= nv) throw std::invalid_argument("undo_crossing_moves: moved vertex out of range");
    if (move_of[v] != UINT32_MAX) continue;
    move_of[v] = i;
    if (!(glm::distance(moves[i].position, mesh.positions[v]) >= min_move)) continue;
    check.push_back(v);
  }
  if (check.empty()) return 0;
  auto corners = [&](std::uint32_t f) {
    return f < nt ? std::span<const std::uint32_t>(&mesh.triangles[3 * f], 3)
                  : std::span<const std::uint32_t>(&mesh.quads[4 * (f - nt)], 4);
  };
  auto star_of = [&](std::uint32_t f) {  // face f as the test reads it
    Star g;
    const auto c = corners(f);
    g.v[3] = UINT32_MAX;
    for (std::size_t k = 0; k < c.size(); ++k)
      g.p[k] = mesh.positions[c[k]], g.v[k] = c[k];
    return g;
  };
  // The largest box diagonal of a face (a maximum: the same for any split among threads).
  const double widest = tbb::parallel_reduce(
      tbb::blocked_range<std::uint32_t>(0, std::uint32_t(nf), 8192), 0.0,
      [&](const auto& r, double widest) {
        for (std::uint32_t f = r.begin(); f < r.end(); ++f) {
          const Bounds b = star_of(f).bounds();
          widest = std::max(widest, glm::distance(b.lo, b.hi));
        }
        return widest;
      },
      [](double a, double b) { return std::max(a, b); });
  // A face that meets a star has every corner within its own box diagonal of the star's box:
  // the faces to test are found through their corners in `near` cells of that size around the
  // stars (in the first round that is most of the mesh near the moves; in later ones, few).
  const double near_cell = std::max(widest, cell);
  std::vector<std::uint8_t> still(nv, 0), is_near(nv, 0), checking(nv, 0);
  std::vector<std::uint32_t> star_index(nf, UINT32_MAX);  // a face's place among the stars
  for (std::uint32_t v : check)
    still[v] = 1;
  std::size_t put_back = 0;
  // The faces around the vertices to check: in the first round one scan over the faces (cheaper
  // than a vertex → faces table for the whole mesh); a later round checks vertices put back,
  // which were checked in the first, so its faces are among the first round's.
  std::vector<std::uint32_t> first_star;
  for (int round = 0; round < max_rounds && !check.empty(); ++round) {
    for (std::uint32_t v : check)
      checking[v] = 1;
    std::vector<std::uint32_t> star;
    auto around = [&](std::uint32_t f) {
      const auto c = corners(f);
      return std::any_of(c.begin(), c.end(), [&](std::uint32_t v) { return checking[v]; });
    };
    if (round == 0) {
      for (std::uint32_t f = 0; f < nf; ++f)
        if (around(f)) star.push_back(f);
      first_star = star;
    } else {
      std::copy_if(first_star.begin(), first_star.end(), std::back_inserter(star), around);
    }
    for (std::uint32_t v : check)
      checking[v] = 0;
    std::vector<Star> stars(star.size());
    parallel_each(star.size(), [&](std::size_t i) {
      star_index[star[i]] = std::uint32_t(i);
      stars[i] = star_of(star[i]);
    });
    const StarGrid grid(stars, cell);
    const NearCells near(stars, near_cell);
    // In parallel (the faces are independent; the vertices to put back are sorted after, so
    // the result is the same for any number of threads).
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, std::uint32_t(nv), 4096),
                      [&](const tbb::blocked_range<std::uint32_t>& r) {
                        for (std::uint32_t v = r.begin(); v < r.end(); ++v)
                          is_near[v] = near.contains(glm::dvec3(mesh.positions[v]));
                      });
    tbb::enumerable_thread_specific<std::vector<std::uint32_t>> found;
    tbb::parallel_for(
        tbb::blocked_range<std::uint32_t>(0, std::uint32_t(nf), 1024), [&](const auto& r) {
          std::vector<std::uint32_t>& back = found.local();
          auto note = [&](const auto& v, std::size_t n) {
            for (std::size_t i = 0; i < n; ++i)
              if (still[v[i]]) back.push_back(v[i]);
          };
          for (std::uint32_t f = r.begin(); f < r.end(); ++f) {
            const auto c = corners(f);
            if (std::none_of(c.begin(), c.end(), [&](std::uint32_t v) { return is_near[v]; }))
              continue;
            const CrossingPolygon g = star_of(f).polygon();
            // Two stars are tested once (from the one that comes first), a star not with itself.
            const std::uint32_t own = star_index[f];
            grid.for_each_overlapping(Bounds(g), [&](std::uint32_t s) {
              if (own != UINT32_MAX && own >= s) return;
              if (polygons_cross(g, stars[s].polygon())) {
                note(g.v, g.n);
                note(stars[s].v, stars[s].n());
              }
            });
          }
        });
    for (std::uint32_t f : star)
      star_index[f] = UINT32_MAX;
    std::vector<std::uint32_t> back;
    for (const std::vector<std::uint32_t>& part : found)
      back.insert(back.end(), part.begin(), part.end());
    std::sort(back.begin(), back.end());
    back.erase(std::unique(back.begin(), back.end()), back.end());
    for (std::uint32_t v : back) {
      const VertexMove& m = moves[move_of[v]];
      mesh.positions[v] = m.position;
      mesh.normals[v] = m.normal;
      still[v] = 0;
    }
    put_back += back.size();
    check = std::move(back);
  }
  return put_back;
}

}  // namespace ldimesh
