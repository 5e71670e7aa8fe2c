#include "ldimesh/core/grid_source.hpp"

#include <algorithm>
#include <atomic>
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

// The trilinear interpolant at local point p: Σ w_n · corner[n] with w_n = wx·wy·wz, summed in
// corner order. Where p lies on a face (a coordinate exactly 0 or 1) the other side's weights
// are exact zeros, and the cell on the other side of that face computes the same sum of the
// same products: the value on a shared face does not depend on the cell.
double trilinear_value(const double corner[8], glm::dvec3 p) {
  double v = 0.0;
  for (int n = 0; n < 8; ++n) {
    const double wx = (n & 1) ? p.x : 1.0 - p.x, wy = (n & 2) ? p.y : 1.0 - p.y,
                 wz = (n & 4) ? p.z : 1.0 - p.z;
    v += wx * wy * wz * corner[n];
  }
  return v;
}

// The single root of the cubic in [a, b] where it changes sign: Newton steps kept inside the
// bracket, bisection when a step leaves it.
double converge_cubic(const double c[4], double a, double b, double fa, double fb) {
  if (fb == 0.0) return b;  // exactly at the end: keep it exact (the half-open rule needs it)
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
  // Some corner point of its cells is NaN or ±Inf: its cells check their corners.
  bool nonfinite = false;
};

template <class T>
class GridBinding final : public GeometryBinding {
 public:
  GridBinding(RTCDevice device, const GridView<T>& grid, double iso, std::vector<Brick> bricks,
              std::uint64_t nonfinite)
      : grid_(grid),
        iso_(iso),
        bricks_(std::move(bricks)),
        nonfinite_(nonfinite),
        geometry_(device, bricks_.size(), this, &GridBinding::bounds, &GridBinding::intersect) {}
  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return bricks_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    const Brick& b = self->bricks_[args->primID];
    write_padded_bounds(b.box_lo, b.box_hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    RayQuery& q = *reinterpret_cast<RayQuery*>(args->context);
    const Brick& b = self->bricks_[args->primID];
    if (b.nonfinite)
      self->template intersect_brick<true>(q, b);
    else
      self->template intersect_brick<false>(q, b);
  }

  // Walks the cells of the brick along the ray (3D DDA) and solves each cell's cubic. With
  // kSkipNonfinite, cells with a NaN or ±Inf corner produce no hits; bricks without such values
  // take the path without the check.
  template <bool kSkipNonfinite>
  void intersect_brick(RayQuery& q, const Brick& b) const {
    double t0 = q.t_min, t1 = q.t_max;
    if (!clip_ray_to_box(q.org, q.dir, b.box_lo, b.box_hi, t0, t1)) return;
    const GridView<T>& g = grid_;
    std::array<std::int64_t, 3> cell;
    std::array<int, 3> step;
    std::array<double, 3> t_next, inv;
    // Axes along which the current cell's entry point lies exactly on a face. A face point is
    // then evaluated by the same arithmetic in both cells that share the face (and in both
    // bricks or ranks), so the sign tests at segment ends agree and no root is lost or doubled.
    std::array<bool, 3> on_entry_face{false, false, false};
    const glm::dvec3 entry = q.org + t0 * q.dir;
    for (int a = 0; a < 3; ++a) {
      std::int64_t i = b.lo[a];
      while (i < b.hi[a] && g.coord(a, i + 1) <= entry[a])
        ++i;  // at most brick_cells steps
      // On a cell face, start in the cell the ray goes into.
      if (q.dir[a] < 0.0 && i > b.lo[a] && g.coord(a, i) == entry[a]) --i;
      cell[a] = i;
      step[a] = q.dir[a] > 0.0 ? 1 : (q.dir[a] < 0.0 ? -1 : 0);
      // t at a face as clip_ray_to_box computes it: (face − o) · (1 / d).
      inv[a] = step[a] == 0 ? 0.0 : 1.0 / q.dir[a];
      t_next[a] =
          step[a] == 0 ? INFINITY : (g.coord(a, step[a] > 0 ? i + 1 : i) - q.org[a]) * inv[a];
      on_entry_face[a] =
          step[a] != 0 && (g.coord(a, step[a] > 0 ? i : i + 1) - q.org[a]) * inv[a] == t0;
    }
    double t = t0;
    while (t < t1) {
      const double t_exit = std::min({t_next[0], t_next[1], t_next[2], t1});
      std::array<bool, 3> on_exit_face;
      for (int a = 0; a < 3; ++a)
        on_exit_face[a] = t_next[a] == t_exit;
      if (t_exit > t)
        solve_cell<kSkipNonfinite>(q, cell, step, t, t_exit, on_entry_face, on_exit_face);
      t = std::max(t, t_exit);  // a face behind t (rounding at the entry) moves nothing back
      // Advance along every axis whose face the ray leaves through (several at an edge).
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        on_entry_face[a] = on_exit_face[a];
        if (!on_exit_face[a]) continue;
        cell[a] += step[a];
        if (cell[a] < b.lo[a] || cell[a] > b.hi[a])
          inside = false;
        else
          t_next[a] = (g.coord(a, step[a] > 0 ? cell[a] + 1 : cell[a]) - q.org[a]) * inv[a];
      }
      if (!inside) break;
    }
  }

  template <bool kSkipNonfinite>
  void solve_cell(RayQuery& q, const std::array<std::int64_t, 3>& c, const std::array<int, 3>& step,
                  double ta, double tb, const std::array<bool, 3>& entry_face,
                  const std::array<bool, 3>& exit_face) const {
    const GridView<T>& g = grid_;
    double corner[8];
    bool any_positive = false, any_negative = false;
    for (int n = 0; n < 8; ++n) {
      const double v = g.value(c[0] + (n & 1), c[1] + ((n >> 1) & 1), c[2] + ((n >> 2) & 1));
      if constexpr (kSkipNonfinite) {
        if (!std::isfinite(v)) return;  // no interpolant in this cell
      }
      corner[n] = v - iso_;
      (positive(corner[n]) ? any_positive : any_negative) = true;
    }
    if (!any_positive || !any_negative) return;  // the interpolant lies between its corners
    glm::dvec3 lo, size, a, b;
    const glm::dvec3 pa = q.org + ta * q.dir, pb = q.org + tb * q.dir;
    for (int k = 0; k < 3; ++k) {
      lo[k] = g.coord(k, c[k]);
      size[k] = g.coord(k, c[k] + 1) - lo[k];
      // Exactly 0 or 1 on the face the ray enters or leaves through.
      a[k] = entry_face[k] ? (step[k] > 0 ? 0.0 : 1.0)
                           : std::clamp((pa[k] - lo[k]) / size[k], 0.0, 1.0);
      b[k] = exit_face[k] ? (step[k] > 0 ? 1.0 : 0.0)
                          : std::clamp((pb[k] - lo[k]) / size[k], 0.0, 1.0);
    }
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
      // A root at the very end of the segment keeps tb exactly (the half-open rule compares it).
      const double t = roots[r] == 1.0 ? tb : ta + roots[r] * (tb - ta);
      q.hits->push_back({t, len > 0.0 ? glm::vec3(grad / len) : glm::vec3(-q.dir), 0.0f});
    }
  }

  GridView<T> grid_;
  double iso_;
  std::vector<Brick> bricks_;
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

// Folds points i0 … i1 (at least two) of row (j, k) into the running minimum, maximum and sum.
// Two points per step into separate accumulators: a single chain of additions would bound the
// loop by their latency.
template <class T>
void scan_row(const GridView<T>& g, std::int64_t i0, std::int64_t i1, std::int64_t j,
              std::int64_t k, double& lo, double& hi, double& sum) {
  double lo1 = lo, hi1 = hi, sum0 = 0.0, sum1 = 0.0;
  std::int64_t i = i0;
  for (; i < i1; i += 2) {
    const double v0 = g.value(i, j, k), v1 = g.value(i + 1, j, k);
    lo = std::min(lo, v0);
    hi = std::max(hi, v0);
    sum0 += v0;
    lo1 = std::min(lo1, v1);
    hi1 = std::max(hi1, v1);
    sum1 += v1;
  }
  if (i == i1) {
    const double v = g.value(i, j, k);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    sum0 += v;
  }
  lo = std::min(lo, lo1);
  hi = std::max(hi, hi1);
  sum += sum0 + sum1;
}

template <class T>
std::unique_ptr<GeometryBinding> bind_grid(RTCDevice device, const GridView<T>& grid, double iso,
                                           const std::array<std::int64_t, 3>& first,
                                           const std::array<std::int64_t, 3>& last,
                                           const std::array<std::int64_t, 3>& bricks,
                                           int brick_cells) {
  const std::int64_t total = bricks[0] * bricks[1] * bricks[2];
  std::vector<std::uint8_t> active(total);
  std::vector<Brick> all(total);
  std::atomic<std::uint64_t> nonfinite{0};
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
    // Range of the trilinear interpolant over the brick = range of its points. The sum of the
    // values is finite unless one of them is NaN or ±Inf (or the sum overflows): a closer look
    // only then.
    double lo = INFINITY, hi = -INFINITY, sum = 0.0;
    for (std::int64_t k = b.lo[2]; k <= b.hi[2] + 1; ++k)
      for (std::int64_t j = b.lo[1]; j <= b.hi[1] + 1; ++j)
        scan_row(grid, b.lo[0], b.hi[0] + 1, j, k, lo, hi, sum);
    if (!std::isfinite(sum)) [[unlikely]] {
      // Non-finite points are left out of the range (their cells produce no hits, the others
      // keep theirs) and counted by the one brick that owns them: a brick owns the points below
      // its upper layer of points along each axis, which the next brick reads as its lower
      // layer, and the last brick along an axis owns that layer too. So every point read is
      // counted exactly once.
      std::array<std::int64_t, 3> owned_hi;
      for (int a = 0; a < 3; ++a)
        owned_hi[a] = b.hi[a] == last[a] ? b.hi[a] + 1 : b.hi[a];
      lo = INFINITY, hi = -INFINITY;
      std::uint64_t bad = 0;
      for (std::int64_t k = b.lo[2]; k <= b.hi[2] + 1; ++k)
        for (std::int64_t j = b.lo[1]; j <= b.hi[1] + 1; ++j)
          for (std::int64_t i = b.lo[0]; i <= b.hi[0] + 1; ++i) {
            const double v = grid.value(i, j, k);
            if (std::isfinite(v)) {
              lo = std::min(lo, v);
              hi = std::max(hi, v);
            } else {
              b.nonfinite = true;
              bad += i <= owned_hi[0] && j <= owned_hi[1] && k <= owned_hi[2];
            }
          }
      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
    }
    active[n] = lo <= iso && iso <= hi;
  });
  std::vector<Brick> kept;
  for (std::int64_t n = 0; n < total; ++n)
    if (active[n]) kept.push_back(all[n]);
  return std::make_unique<GridBinding<T>>(device, grid, iso, std::move(kept), nonfinite.load());
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
  // The end values by direct interpolation, not from the cubic: on a shared face both cells
  // compute them with the same arithmetic (see trilinear_value).
  double fa = trilinear_value(corner, a);
  if (fa == 0.0) {
    // A root exactly at the start belongs to this segment (the caster's half-open rule drops
    // one exactly at a shared end). Continue with the sign just after it, so that it is not
    // found again by the first piece.
    roots[n++] = 0.0;
    fa = c[1] != 0.0 ? c[1] : (c[2] != 0.0 ? c[2] : c[3]);
  }
  const double f_end = trilinear_value(corner, b);
  for (int k = 0; k + 1 < n_cuts; ++k) {
    const double fb = k + 2 == n_cuts ? f_end : eval_cubic(c, cuts[k + 1]);
    if (positive(fa) != positive(fb)) roots[n++] = converge_cubic(c, cuts[k], cuts[k + 1], fa, fb);
    fa = fb;
  }
  return n;
}

GridPart grid_part(const GridBlock& whole, std::array<int, 3> blocks, std::array<int, 3> index) {
  const GridSource source(whole);  // validates `whole`; its coordinates define the faces
  GridPart part{whole, {}};
  GridBlock& b = part.block;
  if (b.strides == std::array<std::int64_t, 3>{0, 0, 0})
    b.strides = {1, whole.dims[0], whole.dims[0] * whole.dims[1]};
  std::int64_t offset = 0;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t first = source.first_cell()[a];
    const std::int64_t cells = source.last_cell()[a] - first + 1;
    const std::int64_t c0 = first + cells * index[a] / blocks[a];
    const std::int64_t c1 = first + cells * (index[a] + 1) / blocks[a];  // one past the last cell
    if (c1 <= c0) throw std::invalid_argument("grid block: more parts than cells along an axis");
    const bool last_part = index[a] + 1 == blocks[a];
    // Points c0 … c1, where c1 belongs to the next part (a ghost here); the last part keeps
    // whatever `whole` has above.
    b.dims[a] = last_part ? whole.dims[a] - c0 : c1 - c0 + 1;
    b.ghost_lo[a] = 0;
    b.ghost_hi[a] = last_part ? whole.ghost_hi[a] : 1;
    offset += c0 * b.strides[a];
    if (whole.coords[0]) {
      b.coords[a] = whole.coords[a] + c0;
    } else {
      b.origin[a] = whole.origin[a] + double(c0) * whole.spacing[a];
    }
    part.owned.lo[a] = source.coordinate(a, c0);
    part.owned.hi[a] = source.coordinate(a, c1);
  }
  b.values =
      static_cast<const char*>(whole.values) + offset * std::int64_t(scalar_size(whole.type));
  return part;
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
