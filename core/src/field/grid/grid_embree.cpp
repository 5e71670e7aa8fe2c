// A grid block's Embree binding: its active bricks as user geometry, each ray walking the cells
// of its bricks (grid_cells.hpp).
#include "grid_cells.hpp"

namespace ldimesh::grid {
namespace {

template <class T>
class GridBinding final : public GeometryBinding {
 public:
  GridBinding(RTCDevice device, const GridView<T>& grid, double iso, std::vector<Brick> bricks,
              std::array<std::int64_t, 3> last, std::uint64_t nonfinite)
      : grid_(grid),
        iso_(iso),
        bricks_(std::move(bricks)),
        last_(last),
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
    // A ray in the plane of a face between two bricks belongs to the upper one (as a ray in a
    // cell face plane belongs to the upper cell below): each ray point lies in one cell.
    for (int a = 0; a < 3; ++a)
      if (q.dir[a] == 0.0 && q.org[a] == b.box_hi[a] && b.hi[a] != last_[a]) return;
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
        solve_cell<kSkipNonfinite>(g, iso_, q.org, q.dir, cell, step, t, t_exit, on_entry_face,
                                   on_exit_face, *q.hits);
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

  GridView<T> grid_;
  double iso_;
  std::vector<Brick> bricks_;
  std::array<std::int64_t, 3> last_;
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

}  // namespace

template <class T>
std::unique_ptr<GeometryBinding> bind_grid(RTCDevice device, const GridView<T>& grid, double iso,
                                           const std::array<std::int64_t, 3>& first,
                                           const std::array<std::int64_t, 3>& last,
                                           const std::array<std::int64_t, 3>& bricks,
                                           int brick_cells) {
  BrickCulling culled = cull_bricks(grid, iso, first, last, bricks, brick_cells);
  std::vector<Brick> kept;
  kept.reserve(culled.active_count);
  for (std::size_t n = 0; n < culled.bricks.size(); ++n)
    if (culled.active[n]) kept.push_back(culled.bricks[n]);
  return std::make_unique<GridBinding<T>>(device, grid, iso, std::move(kept), last,
                                          culled.nonfinite);
}

template std::unique_ptr<GeometryBinding> bind_grid<float>(RTCDevice, const GridView<float>&,
                                                           double,
                                                           const std::array<std::int64_t, 3>&,
                                                           const std::array<std::int64_t, 3>&,
                                                           const std::array<std::int64_t, 3>&, int);
template std::unique_ptr<GeometryBinding> bind_grid<double>(
    RTCDevice, const GridView<double>&, double, const std::array<std::int64_t, 3>&,
    const std::array<std::int64_t, 3>&, const std::array<std::int64_t, 3>&, int);

}  // namespace ldimesh::grid
