#include "ldimesh/core/grid_source.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <tbb/parallel_for.h>

namespace ldimesh {
namespace {

const char* kAxis[3] = {"x", "y", "z"};

double eval_cubic(const double c[4], double s) {
  return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

// The single root of the cubic in [a, b] where it changes sign: Newton steps kept inside the
// bracket, bisection when a step leaves it.
double converge_cubic(const double c[4], double a, double b, double fa) {
  double t = 0.5 * (a + b);
  for (int iter = 0; iter < 60 && b - a > 1e-15; ++iter) {
    const double ft = eval_cubic(c, t);
    if (ft == 0.0) return t;
    if (positive(ft) == positive(fa)) {
      a = t;
      fa = ft;
    } else {
      b = t;
    }
    const double slope = (3.0 * c[3] * t + 2.0 * c[2]) * t + c[1];
    double next = t - ft / slope;
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    if (std::abs(next - t) < 1e-15) return next;
    t = next;
  }
  return t;
}

// Grid geometry and values as the intersect callback reads them.
template <class T>
struct GridView {
  const T* values;
  std::array<std::int64_t, 3> strides;
  glm::dvec3 origin, spacing;
  std::array<const double*, 3> coords;  // all null: uniform
  bool rectilinear;

  double coord(int a, std::int64_t i) const {
    return rectilinear ? coords[a][i] : origin[a] + double(i) * spacing[a];
  }
  double value(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return double(values[i * strides[0] + j * strides[1] + k * strides[2]]);
  }
};

// A brick: owned cells lo[a] … hi[a] (lower corner indices) and the box they cover.
struct Brick {
  std::array<std::int64_t, 3> lo, hi;
  glm::dvec3 box_lo, box_hi;
};

template <class T>
class GridBinding final : public GeometryBinding {
 public:
  GridBinding(RTCDevice device, const GridView<T>& grid, double iso, std::vector<Brick> bricks)
      : grid_(grid),
        iso_(iso),
        bricks_(std::move(bricks)),
        geometry_(device, bricks_.size(), this, &GridBinding::bounds, &GridBinding::intersect) {}
  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return bricks_.size(); }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    const Brick& b = self->bricks_[args->primID];
    write_padded_bounds(b.box_lo, b.box_hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    self->intersect_brick(*reinterpret_cast<RayQuery*>(args->context), self->bricks_[args->primID]);
  }

  // Walks the cells of the brick along the ray (3D DDA) and solves each cell's cubic.
  void intersect_brick(RayQuery& q, const Brick& b) const {
    double t0 = q.t_min, t1 = q.t_max;
    if (!clip_ray_to_box(q.org, q.dir, b.box_lo, b.box_hi, t0, t1)) return;
    const GridView<T>& g = grid_;
    std::array<std::int64_t, 3> cell;
    std::array<int, 3> step;
    std::array<double, 3> t_next;
    const glm::dvec3 entry = q.org + t0 * q.dir;
    for (int a = 0; a < 3; ++a) {
      std::int64_t i = b.lo[a];
      while (i < b.hi[a] && g.coord(a, i + 1) <= entry[a])
        ++i;  // at most brick_cells steps
      // On a cell face, start in the cell the ray goes into.
      if (q.dir[a] < 0.0 && i > b.lo[a] && g.coord(a, i) == entry[a]) --i;
      cell[a] = i;
      step[a] = q.dir[a] > 0.0 ? 1 : (q.dir[a] < 0.0 ? -1 : 0);
      t_next[a] =
          step[a] == 0 ? INFINITY : (g.coord(a, step[a] > 0 ? i + 1 : i) - q.org[a]) / q.dir[a];
    }
    double t = t0;
    while (t < t1) {
      const double t_exit = std::min({t_next[0], t_next[1], t_next[2], t1});
      if (t_exit > t) solve_cell(q, cell, t, t_exit);
      t = std::max(t, t_exit);  // a face behind t (rounding at the entry) moves nothing back
      // Advance along every axis whose face the ray leaves through (several at an edge).
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        if (t_next[a] > t_exit) continue;
        cell[a] += step[a];
        if (cell[a] < b.lo[a] || cell[a] > b.hi[a])
          inside = false;
        else
          t_next[a] = (g.coord(a, step[a] > 0 ? cell[a] + 1 : cell[a]) - q.org[a]) / q.dir[a];
      }
      if (!inside) break;
    }
  }

  void solve_cell(RayQuery& q, const std::array<std::int64_t, 3>& c, double ta, double tb) const {
    const GridView<T>& g = grid_;
    double corner[8];
    bool any_positive = false, any_negative = false;
    for (int n = 0; n < 8; ++n) {
      corner[n] = g.value(c[0] + (n & 1), c[1] + ((n >> 1) & 1), c[2] + ((n >> 2) & 1)) - iso_;
      (positive(corner[n]) ? any_positive : any_negative) = true;
    }
    if (!any_positive || !any_negative) return;  // the interpolant lies between its corners
    glm::dvec3 lo, size, a, b;
    for (int k = 0; k < 3; ++k) {
      lo[k] = g.coord(k, c[k]);
      size[k] = g.coord(k, c[k] + 1) - lo[k];
    }
    a = glm::clamp((q.org + ta * q.dir - lo) / size, 0.0, 1.0);
    b = glm::clamp((q.org + tb * q.dir - lo) / size, 0.0, 1.0);
    double roots[3];
    const int n = trilinear_segment_roots(corner, a, b, roots);
    for (int r = 0; r < n; ++r) {
      const glm::dvec3 p = a + roots[r] * (b - a);
      // ∇ of the trilinear interpolant in local coordinates, then per unit length.
      glm::dvec3 grad;
      for (int axis = 0; axis < 3; ++axis) {
        const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
        double sum = 0.0;
        for (int m = 0; m < 4; ++m) {
          const int b1 = m & 1, b2 = m >> 1;
          const int i0 = (b1 << o1) | (b2 << o2), i1 = i0 | (1 << axis);
          const double w = (b1 ? p[o1] : 1.0 - p[o1]) * (b2 ? p[o2] : 1.0 - p[o2]);
          sum += w * (corner[i1] - corner[i0]);
        }
        grad[axis] = sum / size[axis];
      }
      const double len = glm::length(grad);
      q.hits->push_back(
          {ta + roots[r] * (tb - ta), len > 0.0 ? glm::vec3(grad / len) : glm::vec3(-q.dir), 0.0f});
    }
  }

  GridView<T> grid_;
  double iso_;
  std::vector<Brick> bricks_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

template <class T>
std::unique_ptr<GeometryBinding> bind_grid(RTCDevice device, const GridView<T>& grid, double iso,
                                           const std::array<std::int64_t, 3>& first,
                                           const std::array<std::int64_t, 3>& last,
                                           const std::array<std::int64_t, 3>& bricks,
                                           int brick_cells) {
  const std::int64_t total = bricks[0] * bricks[1] * bricks[2];
  std::vector<std::uint8_t> active(total);
  std::vector<Brick> all(total);
  tbb::parallel_for(std::int64_t(0), total, [&](std::int64_t n) {
    const std::array<std::int64_t, 3> idx{n % bricks[0], (n / bricks[0]) % bricks[1],
                                          n / (bricks[0] * bricks[1])};
    Brick& b = all[n];
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = first[a] + idx[a] * brick_cells;
      b.hi[a] = std::min(last[a], b.lo[a] + brick_cells - 1);
      b.box_lo[a] = grid.coord(a, b.lo[a]);
      b.box_hi[a] = grid.coord(a, b.hi[a] + 1);
    }
    // Range of the trilinear interpolant over the brick = range of its points.
    double lo = INFINITY, hi = -INFINITY;
    for (std::int64_t k = b.lo[2]; k <= b.hi[2] + 1; ++k)
      for (std::int64_t j = b.lo[1]; j <= b.hi[1] + 1; ++j)
        for (std::int64_t i = b.lo[0]; i <= b.hi[0] + 1; ++i) {
          const double v = grid.value(i, j, k);
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
    active[n] = lo <= iso && iso <= hi;
  });
  std::vector<Brick> kept;
  for (std::int64_t n = 0; n < total; ++n)
    if (active[n]) kept.push_back(all[n]);
  return std::make_unique<GridBinding<T>>(device, grid, iso, std::move(kept));
}

}  // namespace

int trilinear_segment_roots(const double corner[8], glm::dvec3 a, glm::dvec3 b, double roots[3]) {
  // Each local coordinate is linear in s: x(s) = a + (b − a)s, and 1 − x(s) likewise; the
  // interpolant Σ corner · X·Y·Z is their product, a cubic in s (power basis, c[k] of s^k).
  const glm::dvec3 d = b - a;
  const double L[3][2][2] = {{{1.0 - a.x, -d.x}, {a.x, d.x}},
                             {{1.0 - a.y, -d.y}, {a.y, d.y}},
                             {{1.0 - a.z, -d.z}, {a.z, d.z}}};
  double c[4] = {0.0, 0.0, 0.0, 0.0};
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y) {
      const double* Y = L[1][y];
      const double* Z = L[2][z];
      const double q0 = Y[0] * Z[0], q1 = Y[0] * Z[1] + Y[1] * Z[0], q2 = Y[1] * Z[1];
      for (int x = 0; x < 2; ++x) {
        const double v = corner[x + 2 * y + 4 * z];
        const double* X = L[0][x];
        c[0] += v * X[0] * q0;
        c[1] += v * (X[0] * q1 + X[1] * q0);
        c[2] += v * (X[0] * q2 + X[1] * q1);
        c[3] += v * X[1] * q2;
      }
    }
  // Split [0, 1] at the extrema (roots of 3c3 s² + 2c2 s + c1) into monotone pieces.
  double cuts[4] = {0.0, 0.0, 0.0, 0.0};
  int n_cuts = 0;
  cuts[n_cuts++] = 0.0;
  const double A = 3.0 * c[3], B = 2.0 * c[2], C = c[1];
  double ext[2];
  int n_ext = 0;
  if (A != 0.0) {
    const double disc = B * B - 4.0 * A * C;
    if (disc > 0.0) {
      // Stable quadratic roots.
      const double qd = -0.5 * (B + std::copysign(std::sqrt(disc), B));
      ext[n_ext++] = qd / A;
      if (qd != 0.0) ext[n_ext++] = C / qd;
    }
  } else if (B != 0.0) {
    ext[n_ext++] = -C / B;
  }
  if (n_ext == 2 && ext[0] > ext[1]) std::swap(ext[0], ext[1]);
  for (int e = 0; e < n_ext; ++e)
    if (ext[e] > 0.0 && ext[e] < 1.0) cuts[n_cuts++] = ext[e];
  cuts[n_cuts++] = 1.0;

  int n = 0;
  double fa = eval_cubic(c, 0.0);
  for (int k = 0; k + 1 < n_cuts; ++k) {
    const double fb = eval_cubic(c, cuts[k + 1]);
    if (positive(fa) != positive(fb)) roots[n++] = converge_cubic(c, cuts[k], cuts[k + 1], fa);
    fa = fb;
  }
  return n;
}

GridSource::GridSource(const GridBlock& block, int brick_cells)
    : block_(block), brick_cells_(brick_cells) {
  if (brick_cells < 1)
    throw std::invalid_argument("grid block: brick size must be at least one cell");
  if (!block_.values) throw std::invalid_argument("grid block: values pointer is null");
  if (block_.strides == std::array<std::int64_t, 3>{0, 0, 0})
    block_.strides = {1, block_.dims[0], block_.dims[0] * block_.dims[1]};
  const bool rectilinear = block_.coords[0] && block_.coords[1] && block_.coords[2];
  if (!rectilinear && (block_.coords[0] || block_.coords[1] || block_.coords[2]))
    throw std::invalid_argument(
        "grid block: rectilinear coordinates must be given for all three axes");
  for (int a = 0; a < 3; ++a) {
    const std::string axis = kAxis[a];
    const std::int64_t n = block_.dims[a];
    if (n < 2) throw std::invalid_argument("grid block: need at least 2 points along " + axis);
    if (block_.strides[a] == 0)
      throw std::invalid_argument("grid block: stride along " + axis + " is 0");
    if (block_.ghost_lo[a] < 0 || block_.ghost_hi[a] < 0)
      throw std::invalid_argument("grid block: negative ghost layer count along " + axis);
    first_cell_[a] = block_.ghost_lo[a];
    last_cell_[a] = std::min(n - 1 - block_.ghost_hi[a], n - 2);
    if (last_cell_[a] < first_cell_[a])
      throw std::invalid_argument("grid block: ghost layers leave no owned cell along " + axis);
    if (rectilinear) {
      for (std::int64_t i = 0; i + 1 < n; ++i)
        if (!(block_.coords[a][i] < block_.coords[a][i + 1]))
          throw std::invalid_argument("grid block: coordinates along " + axis +
                                      " are not increasing");
    } else if (!(block_.spacing[a] > 0.0) || !std::isfinite(block_.spacing[a])) {
      throw std::invalid_argument("grid block: spacing along " + axis + " must be positive");
    }
    const std::int64_t cells = last_cell_[a] - first_cell_[a] + 1;
    bricks_[a] = (cells + brick_cells - 1) / brick_cells;
  }
}

double GridSource::coordinate(int axis, std::int64_t i) const {
  if (block_.coords[0]) return block_.coords[axis][i];
  return block_.origin[axis] + double(i) * block_.spacing[axis];
}

double GridSource::value(std::int64_t i, std::int64_t j, std::int64_t k) const {
  const std::int64_t at = i * block_.strides[0] + j * block_.strides[1] + k * block_.strides[2];
  return block_.type == ScalarType::float32 ? double(static_cast<const float*>(block_.values)[at])
                                            : static_cast<const double*>(block_.values)[at];
}

Box GridSource::bounds() const {
  Box box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = coordinate(a, first_cell_[a]);
    box.hi[a] = coordinate(a, last_cell_[a] + 1);
  }
  return box;
}

std::size_t GridSource::brick_count() const {
  return std::size_t(bricks_[0] * bricks_[1] * bricks_[2]);
}

std::unique_ptr<GeometryBinding> GridSource::bind(RTCDevice device, double isovalue) const {
  auto bind_typed = [&](const auto* values) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(values)>>;
    const GridView<T> g{values,         block_.strides, block_.origin,
                        block_.spacing, block_.coords,  block_.coords[0] != nullptr};
    return bind_grid(device, g, isovalue, first_cell_, last_cell_, bricks_, brick_cells_);
  };
  if (block_.type == ScalarType::float32)
    return bind_typed(static_cast<const float*>(block_.values));
  return bind_typed(static_cast<const double*>(block_.values));
}

}  // namespace ldimesh
