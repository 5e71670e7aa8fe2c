#include "ldimesh/core/field/grid_source.hpp"

#include "../colour_block.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "grid_cells.hpp"

namespace ldimesh {

using namespace grid;

int trilinear_segment_roots(const double corner[8], glm::dvec3 a, glm::dvec3 b, double roots[3]) {
  const glm::dvec3 d = b - a;
  if (int(d.x != 0.0) + int(d.y != 0.0) + int(d.z != 0.0) == 1) {
    // Along one axis the interpolant is linear: its root from the end values, evaluated as on a
    // face (see trilinear_value), with no rounding of cubic coefficients in between. This is
    // what the coherent caster of axis rays computes, to the bit.
    const double fa = trilinear_value(corner, a), fb = trilinear_value(corner, b);
    if (fa == 0.0) {
      roots[0] = 0.0;  // a root exactly at the start belongs to this segment (see below)
      return 1;
    }
    if (positive(fa) == positive(fb)) return 0;
    roots[0] = fa / (fa - fb);
    return 1;
  }
  // Each local coordinate is linear in s: x(s) = a + (b − a)s, and 1 − x(s) likewise; the
  // interpolant Σ corner · X·Y·Z is their product, a cubic in s (power basis, c[k] of s^k).
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
    // whatever `whole` has above. And one more point on each side where `whole` has it (ghosts),
    // for the central differences of the normals at the owned cells' corners: the parts' hits
    // then carry the normals the whole block gives.
    const std::int64_t below = c0 > 0 ? 1 : 0;
    const std::int64_t above = !last_part && c1 + 1 < whole.dims[a] ? 1 : 0;
    const std::int64_t p0 = c0 - below;
    b.dims[a] = (last_part ? whole.dims[a] - c0 : c1 - c0 + 1 + above) + below;
    b.ghost_lo[a] = int(below);
    b.ghost_hi[a] = last_part ? whole.ghost_hi[a] : int(1 + above);
    offset += p0 * b.strides[a];
    if (whole.coords[0]) {
      b.coords[a] = whole.coords[a] + p0;
    } else {
      b.origin[a] = whole.origin[a] + double(p0) * whole.spacing[a];
    }
    part.owned.lo[a] = source.coordinate(a, c0);
    part.owned.hi[a] = source.coordinate(a, c1);
  }
  b.values =
      static_cast<const char*>(whole.values) + offset * std::int64_t(scalar_size(whole.type));
  if (whole.colour)
    b.colour = static_cast<const char*>(whole.colour) +
               offset * std::int64_t(scalar_size(whole.colour_type));
  return part;
}

GridSource::GridSource(const GridBlock& block, int brick_cells, std::vector<std::uint8_t> held)
    : GridSource(block, brick_cells) {
  if (held.size() != brick_count())
    throw std::invalid_argument("grid block: " + std::to_string(held.size()) + " brick flags for " +
                                std::to_string(brick_count()) + " bricks");
  held_ = std::make_shared<const std::vector<std::uint8_t>>(std::move(held));
}

GridSource::GridSource(const GridBlock& block, int brick_cells)
    : block_(block), brick_cells_(brick_cells) {
  if (brick_cells < 1)
    throw std::invalid_argument("grid block: brick size must be at least one cell");
  if (!block_.values) throw std::invalid_argument("grid block: values pointer is null");
  for (const ScalarType t : {block_.type, block_.colour ? block_.colour_type : block_.type})
    if (t != ScalarType::float32 && t != ScalarType::float64)
      throw std::invalid_argument("grid block: unknown scalar type");
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

double GridSource::interpolate(glm::dvec3 p, double slack) const {
  std::array<std::int64_t, 3> cell{};
  glm::dvec3 f(0.0);
  for (int a = 0; a < 3; ++a) {
    const std::int64_t n = block_.dims[a];
    std::int64_t i = 0;
    if (block_.coords[0]) {
      const double* c = block_.coords[a];
      i = std::int64_t(std::upper_bound(c, c + n, p[a]) - c) - 1;
    } else {
      const double u = (p[a] - block_.origin[a]) / block_.spacing[a];
      if (!(u > -1.0 && u < double(n))) return std::numeric_limits<double>::quiet_NaN();
      i = std::int64_t(std::floor(u));
    }
    i = std::clamp<std::int64_t>(i, 0, n - 2);
    const double x0 = coordinate(a, i), x1 = coordinate(a, i + 1);
    const double t = (p[a] - x0) / (x1 - x0);
    if (!(t >= -slack && t <= 1.0 + slack)) return std::numeric_limits<double>::quiet_NaN();
    cell[a] = i;
    f[a] = std::clamp(t, 0.0, 1.0);
  }
  if (held_ && !cell_held(cell)) return std::numeric_limits<double>::quiet_NaN();
  const auto [i, j, k] = cell;
  const auto lerp = [](double u, double v, double t) { return u + t * (v - u); };
  const double c00 = lerp(value(i, j, k), value(i + 1, j, k), f.x);
  const double c10 = lerp(value(i, j + 1, k), value(i + 1, j + 1, k), f.x);
  const double c01 = lerp(value(i, j, k + 1), value(i + 1, j, k + 1), f.x);
  const double c11 = lerp(value(i, j + 1, k + 1), value(i + 1, j + 1, k + 1), f.x);
  const double v = lerp(lerp(c00, c10, f.y), lerp(c01, c11, f.y), f.z);
  return std::isfinite(v) ? v : std::numeric_limits<double>::quiet_NaN();
}

namespace {

// The colour field of a grid block: its interpolant, read in place (a source over the colour
// array with the block's held mask).
class GridScalarProbe final : public ScalarProbe {
 public:
  explicit GridScalarProbe(GridSource colour) : grid_(std::move(colour)) {}
  double at(glm::dvec3 p) const override { return grid_.interpolate(p, 0.0); }
  // Points rounded onto the wrong side of the block's faces.
  double near(glm::dvec3 p) const override { return grid_.interpolate(p, 1e-6); }

 private:
  GridSource grid_;
};

}  // namespace

std::unique_ptr<ScalarProbe> GridSource::bind_scalar() const {
  if (!block_.colour) return nullptr;
  GridSource colour = *this;
  colour.block_ = colour_as_values(block_);
  return std::make_unique<GridScalarProbe>(std::move(colour));
}

bool GridSource::cell_held(const std::array<std::int64_t, 3>& cell) const {
  // Per axis, the bricks whose copy holds both point layers of the cell: cells lo − 1 … hi + 1.
  std::array<std::array<std::int64_t, 3>, 3> bricks;
  std::array<int, 3> count{};
  for (int a = 0; a < 3; ++a) {
    const std::int64_t rel = cell[a] - first_cell_[a];
    const std::int64_t q =
        std::clamp<std::int64_t>(rel < 0 ? -1 : rel / brick_cells_, 0, bricks_[a] - 1);
    for (std::int64_t b = std::max<std::int64_t>(0, q - 1); b <= std::min(bricks_[a] - 1, q + 1);
         ++b) {
      const std::int64_t lo = first_cell_[a] + b * brick_cells_,
                         hi = std::min(last_cell_[a], lo + brick_cells_ - 1);
      if (cell[a] >= lo - 1 && cell[a] <= hi + 1) bricks[a][count[a]++] = b;
    }
  }
  for (int z = 0; z < count[2]; ++z)
    for (int y = 0; y < count[1]; ++y)
      for (int x = 0; x < count[0]; ++x)
        if ((*held_)[std::size_t(bricks[0][x] +
                                 bricks_[0] * (bricks[1][y] + bricks_[1] * bricks[2][z]))])
          return true;
  return false;
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

namespace {

// The casters' view of `block` (strides filled in) with `values` and the held mask.
template <class T>
GridView<T> make_view(const GridBlock& block, const T* values,
                      const std::shared_ptr<const std::vector<std::uint8_t>>& held) {
  return {values,        block.strides,       block.origin,
          block.spacing, block.coords,        block.coords[0] != nullptr,
          block.dims,    0.5 / block.spacing, held ? held->data() : nullptr};
}

}  // namespace

// Calls f(begin, end) over layers 0 … n − 1 of `layer_points` points each: on the calling thread
// where they hold at most 8 Mi points, else in tasks of a layer or more on all cores. The
// snapshot's scan and copies (needed_bricks, for_each_needed_run) run on the solver's thread;
// where ranks share cores (the Gray–Scott bench: 2 ranks on 2 cores), waiting there for TBB's
// workers, which another rank's threads can hold off a core, cost more than they saved
// (docs/history/benchmarks-log.md, "The solver waits 8 ms"). A larger block (a rank with many
// cores to itself) is still spread.
template <class F>
void for_layers(std::int64_t n, std::int64_t layer_points, F&& f) {
  if (n <= 0) return;
  if (layer_points <= (std::int64_t(8) << 20) / n) {
    f(std::int64_t(0), n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n),
                    [&](const tbb::blocked_range<std::int64_t>& r) { f(r.begin(), r.end()); });
}

std::vector<std::uint8_t> GridSource::needed_bricks(std::span<const double> isovalues) const {
  std::vector<std::uint8_t> needed = needed_bricks_by_isovalue(isovalues);
  for (std::uint8_t& n : needed)
    n = n != 0;
  return needed;
}

std::vector<std::uint8_t> GridSource::needed_bricks_by_isovalue(
    std::span<const double> isovalues) const {
  // The bricks' ranges from the rows of points in memory order (a brick at a time would jump
  // between rows and pages, much slower: docs/history/benchmarks-log.md, "The snapshot holds what
  // the step reads"), layers of bricks along
  // z (for_layers). A brick with a NaN or ±Inf is needed whatever its range: a superset of the
  // bricks a bind keeps or finds non-finite values in, which is all the snapshot needs.
  const std::size_t count = brick_count();
  std::vector<double> lo(count, INFINITY), hi(count, -INFINITY);
  std::vector<std::uint8_t> bad(count, 0);
  const auto scan = [&](const auto* values) {
    const auto g = make_view(block_, values, held_);
    const std::int64_t layer = block_.dims[0] * block_.dims[1] * (brick_cells_ + 1);
    for_layers(bricks_[2], layer, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t bz = begin; bz < end; ++bz) {
        const std::int64_t z0 = first_cell_[2] + bz * brick_cells_,
                           z1 = std::min(last_cell_[2], z0 + brick_cells_ - 1) + 1;
        for (std::int64_t k = z0; k <= z1; ++k)
          for (std::int64_t by = 0; by < bricks_[1]; ++by) {
            const std::int64_t y0 = first_cell_[1] + by * brick_cells_,
                               y1 = std::min(last_cell_[1], y0 + brick_cells_ - 1) + 1;
            const std::size_t row = std::size_t(bricks_[0] * (by + bricks_[1] * bz));
            for (std::int64_t j = y0; j <= y1; ++j)
              for (std::int64_t bx = 0; bx < bricks_[0]; ++bx) {
                const std::size_t n = row + std::size_t(bx);
                if (g.held && !g.held[n]) continue;
                const std::int64_t x0 = first_cell_[0] + bx * brick_cells_,
                                   x1 = std::min(last_cell_[0], x0 + brick_cells_ - 1) + 1;
                bool finite = true;
                scan_row(g, x0, x1, j, k, lo[n], hi[n], finite);
                if (!finite) bad[n] = 1;
              }
          }
      }
    });
  };
  if (block_.type == ScalarType::float32)
    scan(static_cast<const float*>(block_.values));
  else
    scan(static_cast<const double*>(block_.values));
  std::uint8_t every = 0;
  for (std::size_t i = 0; i < isovalues.size(); ++i)
    every |= std::uint8_t(1u << std::min<std::size_t>(i, 7));
  std::vector<std::uint8_t> needed(count, 0);
  for (std::size_t n = 0; n < count; ++n) {
    if (held_ && !(*held_)[n]) continue;
    std::uint8_t bits = bad[n] ? every : 0;
    for (std::size_t i = 0; i < isovalues.size(); ++i)
      if (lo[n] <= isovalues[i] && isovalues[i] <= hi[n])
        bits |= std::uint8_t(1u << std::min<std::size_t>(i, 7));
    needed[n] = bits;
  }
  return needed;
}

void GridSource::for_each_needed_run(
    std::span<const std::uint8_t> held,
    const std::function<void(std::int64_t, std::int64_t, std::int64_t, std::int64_t)>& f) const {
  if (held.size() != brick_count())
    throw std::invalid_argument("for_each_needed_run: " + std::to_string(held.size()) +
                                " brick flags for " + std::to_string(brick_count()) + " bricks");
  // Per axis and point index: the bricks of cells lo … hi whose points lo − 1 … hi + 2 include
  // it (a few consecutive ones).
  std::array<std::vector<std::pair<std::int64_t, std::int64_t>>, 3> near;
  for (int a = 0; a < 3; ++a) {
    near[a].assign(std::size_t(block_.dims[a]), {0, -1});
    for (std::int64_t b = 0; b < bricks_[a]; ++b) {
      const std::int64_t lo = first_cell_[a] + b * brick_cells_,
                         hi = std::min(last_cell_[a], lo + brick_cells_ - 1);
      for (std::int64_t i = std::max<std::int64_t>(0, lo - 1);
           i <= std::min(block_.dims[a] - 1, hi + 2); ++i) {
        auto& [b0, b1] = near[a][std::size_t(i)];
        if (b1 < b0) b0 = b;
        b1 = b;
      }
    }
  }
  for_layers(
      block_.dims[2], block_.dims[0] * block_.dims[1], [&](std::int64_t begin, std::int64_t end) {
        std::vector<std::uint8_t> row(static_cast<std::size_t>(bricks_[0]));
        for (std::int64_t k = begin; k < end; ++k) {
          const auto [z0, z1] = near[2][std::size_t(k)];
          if (z1 < z0) continue;
          for (std::int64_t j = 0; j < block_.dims[1]; ++j) {
            const auto [y0, y1] = near[1][std::size_t(j)];
            if (y1 < y0) continue;
            std::fill(row.begin(), row.end(), 0);
            for (std::int64_t bz = z0; bz <= z1; ++bz)
              for (std::int64_t by = y0; by <= y1; ++by) {
                const std::uint8_t* h = &held[std::size_t(bricks_[0] * (by + bricks_[1] * bz))];
                for (std::size_t bx = 0; bx < row.size(); ++bx)
                  row[bx] |= h[bx];
              }
            // The held bricks' points along x with their margins, joined where they touch.
            std::int64_t run_lo = 0, run_hi = -2;
            for (std::int64_t bx = 0; bx < bricks_[0]; ++bx) {
              if (!row[std::size_t(bx)]) continue;
              const std::int64_t lo = first_cell_[0] + bx * brick_cells_,
                                 hi = std::min(last_cell_[0], lo + brick_cells_ - 1);
              const std::int64_t i0 = std::max<std::int64_t>(0, lo - 1),
                                 i1 = std::min(block_.dims[0] - 1, hi + 2);
              if (i0 > run_hi + 1) {
                if (run_hi >= run_lo) f(j, k, run_lo, run_hi);
                run_lo = i0;
              }
              run_hi = i1;
            }
            if (run_hi >= run_lo) f(j, k, run_lo, run_hi);
          }
        }
      });
}

std::unique_ptr<AxisCaster> GridSource::bind_axis(double isovalue) const {
  auto bind_typed = [&](const auto* values) -> std::unique_ptr<AxisCaster> {
    return bind_grid_axis(make_view(block_, values, held_), isovalue, first_cell_, last_cell_,
                          bricks_, brick_cells_, held_);
  };
  if (block_.type == ScalarType::float32)
    return bind_typed(static_cast<const float*>(block_.values));
  return bind_typed(static_cast<const double*>(block_.values));
}

std::unique_ptr<GeometryBinding> GridSource::bind(RTCDevice device, double isovalue) const {
  auto bind_typed = [&](const auto* values) {
    return bind_grid(device, make_view(block_, values, held_), isovalue, first_cell_, last_cell_,
                     bricks_, brick_cells_);
  };
  if (block_.type == ScalarType::float32)
    return bind_typed(static_cast<const float*>(block_.values));
  return bind_typed(static_cast<const double*>(block_.values));
}

}  // namespace ldimesh
