// A grid block's coherent caster of rays parallel to an axis (GridAxisCaster, below): object
// order for an axis view's lattice of pixel rays, column walks over straddle bits for the others.
#include "grid_cells.hpp"

namespace ldimesh::grid {
namespace {

// The coherent caster of a grid block for rays parallel to an axis. Along such a ray the
// trilinear interpolant is linear inside each cell: its value on a cell face the ray crosses
// is the bilinear interpolation of the face's four points, shared by the two cells, and the
// root in a cell is one division.
//
// Empty space is skipped with bits instead of a walk: at bind time one pass over the points
// gives each point's sign (v − iso ≥ 0, as solve_cell tests it) and each cell a bit "its
// corners have both signs" — only such cells can hold a root in either caster (solve_cell
// returns at once for the others). Per axis, each column of cells gets one bit per 4 cells
// along the axis (any such cell among them). A ray reads its column's words, and visits only
// the cells whose bit is set, in ray order. Each of them is solved exactly as the Embree
// binding's walk would solve it: the same segment ends and face flags (derived from the same
// brick clipping), the same face values (the same products summed in the same order), and
// solve_cell itself where the shortcut does not decide (a segment end inside a cell, a face
// value that is zero or not finite). The Embree binding solves a segment along one axis as a
// line too (trilinear_segment_roots), so both give the same roots, to the bit, at every
// degenerate spot as well.
//
// An axis view's pixel rays (a lattice query) are cast in object order instead (cast_lattice):
// the straddling cells of the rows' slab, visited once each in memory order, solve the rays
// through them with the same arithmetic; only rays whose segment ends inside the block walk
// their columns as above.
template <class T>
class GridAxisCaster final : public AxisCaster {
 public:
  // `held`: the source's (GridSource::held_), kept alive for primitive_count().
  GridAxisCaster(const GridView<T>& grid, double iso, std::array<std::int64_t, 3> first,
                 std::array<std::int64_t, 3> last, std::array<std::int64_t, 3> bricks,
                 int brick_cells, std::shared_ptr<const std::vector<std::uint8_t>> held)
      : g_(grid),
        held_(std::move(held)),
        iso_(iso),
        first_(first),
        last_(last),
        bricks_(bricks),
        brick_cells_(brick_cells) {
    g_.held = held_ ? held_->data() : nullptr;
    for (int a = 0; a < 3; ++a)
      cells_[a] = last_[a] - first_[a] + 1;
    classify_cells(g_, iso_, first_, cells_, bricks_, brick_cells_, straddle_, nonfinite_);
  }

  std::size_t primitive_count() const override {
    // The Embree binding's figure (its bricks after culling), computed when asked.
    std::call_once(count_once_, [this] {
      // Isolated: a thread waiting here inside a task must not pick up another of its caller's.
      tbb::this_task_arena::isolate([this] {
        active_bricks_ = cull_bricks(g_, iso_, first_, last_, bricks_, brick_cells_).active_count;
      });
    });
    return active_bricks_;
  }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

  bool prefers_column_tasks(const View& view) const override {
    const int ua = exact_axis(view.u), va = exact_axis(view.v);
    return ua >= 0 && va >= 0 && std::abs(g_.strides[va]) < std::abs(g_.strides[ua]);
  }

  void prepare(int a) const override {
    std::call_once(column_once_[a], [this, a] { build_columns(a); });
  }

  void cast(const AxisRays& rays, AxisHits& out) const override {
    const int a = rays.axis;
    prepare(a);
    if (rays.lattice && cast_lattice(rays, out)) return;
    std::vector<RayHit> hits;
    const auto cast_one = [&](std::size_t k) {
      const AxisRay& ray = rays.rays[k];
      if (!(ray.t0 <= ray.t1)) return;
      hits.clear();
      cast_ray(a, rays.dir, ray, hits);
      for (const RayHit& h : hits)
        out.push_back({std::uint32_t(k), h});
    };
    // Rays in the order that keeps the points they read in cache: along the image axis whose
    // world axis is the block's faster one in memory (neighbouring rays then read the same
    // cache lines).
    const View* view = rays.lattice;
    if (view && prefers_column_tasks(*view)) {
      const std::size_t width = std::size_t(rays.width()), rows = rays.rays.size() / width;
      for (std::size_t i = 0; i < width; ++i)
        for (std::size_t j = 0; j < rows; ++j)
          cast_one(j * width + i);
      return;
    }
    for (std::size_t k = 0; k < rays.rays.size(); ++k)
      cast_one(k);
  }

 private:
  static constexpr int kColumnBlock = 4;  // cells per bit of a column word

  // A brick's cells along the ray axis (lo … hi), the t of its entry face, and its stretch of
  // the ray [t0, t1] as clip_ray_to_box clips it.
  struct Stretch {
    std::int64_t lo, hi;
    double face_in, t0, t1;
  };

  std::size_t row_words() const { return std::size_t((cells_[0] + 63) / 64); }

  // Axis a's column words: bit q of column (b, c) (the transverse cell indices, relative) is set
  // iff one of its cells 4q … 4q + 3 along a straddles.
  std::size_t column_words(int a) const {
    return std::size_t(((cells_[a] + kColumnBlock - 1) / kColumnBlock + 63) / 64);
  }
  void build_columns(int a) const {
    // Isolated: should a thread get here inside one of the caster's tasks (prepare() not
    // called), it must not pick up another of them while it waits (they share its buffers).
    tbb::this_task_arena::isolate([this, a] { build_columns_isolated(a); });
  }
  void build_columns_isolated(int a) const {
    const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;
    const std::size_t wpc = column_words(a);
    std::vector<std::uint64_t>& col = columns_[a];
    col.assign(wpc * std::size_t(cells_[b] * cells_[c]), 0);
    const std::size_t cw = row_words();
    const auto set = [&](std::int64_t cb, std::int64_t cc, std::int64_t q) {
      col[std::size_t(cb + cells_[b] * cc) * wpc + std::size_t(q / 64)] |= std::uint64_t(1)
                                                                           << (q % 64);
    };
    if (a == 0) {
      tbb::parallel_for(std::int64_t(0), cells_[2], [&](std::int64_t z) {
        for (std::int64_t y = 0; y < cells_[1]; ++y) {
          const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
          for (std::size_t w = 0; w < cw; ++w)
            for (std::uint64_t bits = row[w]; bits; bits &= bits - 1)
              set(y, z, (std::int64_t(w) * 64 + std::countr_zero(bits)) / kColumnBlock);
        }
      });
      return;
    }
    // a = y: columns (x, z); a = z: columns (x, y). OR the rows of each block along a, then
    // set the bit of every x whose cells straddle.
    const std::int64_t outer = a == 1 ? cells_[2] : cells_[1];
    tbb::parallel_for(std::int64_t(0), outer, [&](std::int64_t o) {
      std::vector<std::uint64_t> merged(cw);
      for (std::int64_t q = 0; q * kColumnBlock < cells_[a]; ++q) {
        std::fill(merged.begin(), merged.end(), 0);
        for (std::int64_t k = q * kColumnBlock; k < std::min(cells_[a], (q + 1) * kColumnBlock);
             ++k) {
          const std::int64_t y = a == 1 ? k : o, z = a == 1 ? o : k;
          const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
          for (std::size_t w = 0; w < cw; ++w)
            merged[w] |= row[w];
        }
        for (std::size_t w = 0; w < cw; ++w)
          for (std::uint64_t bits = merged[w]; bits; bits &= bits - 1)
            set(std::int64_t(w) * 64 + std::countr_zero(bits), o, q);
      }
    });
  }

  // The pixel columns (or rows) of a lattice by the cell they lie in along one axis: pixels
  // pixels[first[q]] … pixels[first[q + 1] − 1] lie in cell first_ + q, at local coordinate p
  // (per pixel) across the rays, as cast_ray computes it; cells lo … hi (relative) hold some.
  struct PixelIndex {
    std::vector<std::uint32_t> first, pixels, next;
    std::vector<std::int64_t> cell;  // per pixel: its relative cell, −1 outside the block
    std::vector<double> p;
    std::int64_t lo = 0, hi = -1;
    // Pixels per cell that holds any.
    double density() const {
      std::size_t cells = 0;
      for (std::size_t q = 0; q + 1 < first.size(); ++q)
        cells += first[q + 1] > first[q];
      return cells == 0 ? 0.0 : double(pixels.size()) / double(cells);
    }
  };
  struct LatticeScratch {
    PixelIndex columns, rows;
    std::vector<std::uint8_t> whole;  // per ray: its segment covers the block along the axis
    std::vector<RayHit> hits;
  };
  static LatticeScratch& lattice_scratch() {
    thread_local LatticeScratch scratch;
    return scratch;
  }

  template <class Coordinate>
  void index_pixels(int axis, std::size_t count, Coordinate coordinate, PixelIndex& ix) const {
    ix.cell.assign(count, -1);
    ix.p.assign(count, 0.0);
    ix.first.assign(std::size_t(cells_[axis]) + 1, 0);
    ix.lo = cells_[axis];
    ix.hi = -1;
    const double lowest = g_.coord(axis, first_[axis]), highest = g_.coord(axis, last_[axis] + 1);
    for (std::size_t m = 0; m < count; ++m) {
      const double x = coordinate(m);
      if (x < lowest || x > highest) continue;
      const std::int64_t c = cell_index(axis, x);
      const double lo = g_.coord(axis, c);
      ix.p[m] = std::clamp((x - lo) / (g_.coord(axis, c + 1) - lo), 0.0, 1.0);
      const std::int64_t q = c - first_[axis];
      ix.cell[m] = q;
      ++ix.first[std::size_t(q) + 1];
      ix.lo = std::min(ix.lo, q);
      ix.hi = std::max(ix.hi, q);
    }
    for (std::size_t q = 1; q < ix.first.size(); ++q)
      ix.first[q] += ix.first[q - 1];
    ix.pixels.resize(ix.first.back());
    ix.next.assign(ix.first.begin(), ix.first.end() - 1);
    for (std::size_t m = 0; m < count; ++m)
      if (ix.cell[m] >= 0) ix.pixels[ix.next[std::size_t(ix.cell[m])]++] = std::uint32_t(m);
  }

  // Object order for the pixel rays of an axis view's rows (AxisRays::lattice): the straddling
  // cells of the rows' slab of the block are visited once each, in memory order, and each
  // solves the rays through it, instead of each ray walking its own column (at 512² of a 256³
  // block four rays share a column, and the column walks read the block out of order). The rays
  // whose segment covers the block's whole stretch along the axis — a view, or a rank's
  // fragment of its own block — are solved so; the others by cast_ray. Per ray and cell the
  // arithmetic is cast_ray's (its whole-segment case): the same cell across the ray, the same
  // face values (face_value), roots and gradients (axis_root), and solve_cell where a face value
  // is zero or not finite. Returns false where the rays do not form a lattice of this view
  // (cast() then casts them one by one).
  bool cast_lattice(const AxisRays& rays, AxisHits& out) const {
    const View& view = *rays.lattice;
    const int a = rays.axis;
    const int ua = exact_axis(view.u), va = exact_axis(view.v);
    if (ua < 0 || va < 0 || ua == a || va == a || rays.width() <= 0) return false;
    const std::span<const AxisRay> ray = rays.rays;
    const std::size_t width = std::size_t(rays.width()), n = ray.size();
    if (n == 0) return true;
    if (n % width != 0) return false;
    const double oa = ray[0].org[a];
    for (std::size_t row = 0; row < n; row += width)
      for (std::size_t i = 0; i < width; ++i) {
        const glm::dvec3 o = ray[row + i].org;
        if (o[ua] != ray[i].org[ua] || o[va] != ray[row].org[va] || o[a] != oa) return false;
      }

    const glm::dvec3 dir = rays.dir;
    const double inv = 1.0 / dir[a];
    const auto t_at = [&](std::int64_t node) { return (g_.coord(a, node) - oa) * inv; };
    const double t_lo = std::min(t_at(first_[a]), t_at(last_[a] + 1));
    const double t_hi = std::max(t_at(first_[a]), t_at(last_[a] + 1));
    LatticeScratch& x = lattice_scratch();
    index_pixels(
        ua, width, [&](std::size_t i) { return ray[i].org[ua]; }, x.columns);
    index_pixels(
        va, n / width, [&](std::size_t j) { return ray[j * width].org[va]; }, x.rows);
    // Object order pays where the rays are about as dense as the cells or denser: it streams the
    // block, while each ray's walk of its column misses the cache on most faces; below 0.75 rays
    // per column of cells on average the walks win (measured in alternating runs:
    // docs/history/benchmarks-log.md, "Ray casting beside Flying Edges").
    if (x.columns.density() * x.rows.density() < 0.75) return false;
    x.whole.assign(n, 0);
    for (std::size_t k = 0; k < n; ++k) {
      const AxisRay& r = ray[k];
      if (!(r.t0 <= r.t1)) continue;
      if (r.t0 <= t_lo && r.t1 >= t_hi) {
        x.whole[k] = 1;
        continue;
      }
      x.hits.clear();
      cast_ray(a, dir, r, x.hits);
      for (const RayHit& h : x.hits)
        out.push_back({std::uint32_t(k), h});
    }
    if (x.columns.hi < x.columns.lo || x.rows.hi < x.rows.lo) return true;

    // The slab: every cell along a, the cells that hold pixels across.
    std::array<std::int64_t, 3> lo{0, 0, 0}, hi{cells_[0] - 1, cells_[1] - 1, cells_[2] - 1};
    lo[ua] = x.columns.lo;
    hi[ua] = x.columns.hi;
    lo[va] = x.rows.lo;
    hi[va] = x.rows.hi;
    const Lattice lattice{ray, width, oa, dir, lo, hi};
    // The axes as template constants: the slab solver for (a, whether u is the lower transverse
    // axis).
    using Solver = void (GridAxisCaster::*)(const Lattice&, LatticeScratch&, AxisHits&) const;
    static constexpr Solver kSolvers[6] = {
        &GridAxisCaster::solve_slab<0, false>, &GridAxisCaster::solve_slab<0, true>,
        &GridAxisCaster::solve_slab<1, false>, &GridAxisCaster::solve_slab<1, true>,
        &GridAxisCaster::solve_slab<2, false>, &GridAxisCaster::solve_slab<2, true>};
    (this->*kSolvers[a * 2 + int(ua < va)])(lattice, x, out);
    return true;
  }

  // What solve_slab needs of a lattice query: its rays (ray k is pixel (k % width, k / width)),
  // their common origin along the ray axis, the direction, and the slab's cells (relative).
  struct Lattice {
    std::span<const AxisRay> ray;
    std::size_t width;
    double oa;
    glm::dvec3 dir;
    std::array<std::int64_t, 3> lo, hi;
  };

  // The straddling cells of the slab, by their bits (rows along x), each solving the rays
  // through it: along axis A, B < C the transverse axes; kUIsB: the image's u axis (pixel
  // columns) is B, else C. The axes as constants keep the coordinates in registers.
  template <int A, bool kUIsB>
  void solve_slab(const Lattice& l, LatticeScratch& x, AxisHits& out) const {
    constexpr int B = A == 0 ? 1 : 0, C = A == 2 ? 1 : 2;
    const PixelIndex& along_b = kUIsB ? x.columns : x.rows;
    const PixelIndex& along_c = kUIsB ? x.rows : x.columns;
    const std::size_t stride_b = kUIsB ? 1 : l.width, stride_c = kUIsB ? l.width : 1;
    const std::array<std::int64_t, 3> s = g_.strides;
    std::int64_t offsets[8];
    for (int m = 0; m < 8; ++m)
      offsets[m] = (m & 1) * s[0] + ((m >> 1) & 1) * s[1] + ((m >> 2) & 1) * s[2];
    // Corner index of face point m (β = m & 1 along B, γ = m >> 1 along C) on the entry and the
    // exit face.
    const int step = l.dir[A] > 0.0 ? 1 : -1;
    const double inv = 1.0 / l.dir[A];
    const int in = step > 0 ? 0 : 1;
    int face_in[4], face_out[4];
    for (int m = 0; m < 4; ++m) {
      face_in[m] = (in << A) | ((m & 1) << B) | ((m >> 1) << C);
      face_out[m] = ((1 - in) << A) | ((m & 1) << B) | ((m >> 1) << C);
    }
    const auto t_at = [&](std::int64_t node) { return (g_.coord(A, node) - l.oa) * inv; };

    // The rays of a cell whose face values differ in sign, solved after its loop (no branch on
    // the outcome, which is near random).
    struct Candidate {
      std::uint32_t k;
      double fa, fb, pb, pc;
    };
    constexpr int kCandidates = 64;
    Candidate candidates[kCandidates];
    int n_candidates = 0;
    double corner[8];
    std::array<std::int64_t, 3> cell;
    // The cell's stretch of the rays [t_in, t_out] and its inverse edges, computed when a ray
    // needs them (most straddling cells at one ray per cell have no hit); a cell without
    // thickness along the rays (t_out ≤ t_in) has none.
    double t_in = 0.0, t_out = 0.0;
    glm::dvec3 inv_size;
    bool extent_known = false, extent_ok = false;
    const auto extent = [&] {
      if (!extent_known) {
        const std::int64_t i = cell[A];
        t_in = t_at(step > 0 ? i : i + 1);
        t_out = t_at(step > 0 ? i + 1 : i);
        extent_ok = t_out > t_in;
        glm::dvec3 size;
        size[A] = g_.coord(A, i + 1) - g_.coord(A, i);
        size[B] = g_.coord(B, cell[B] + 1) - g_.coord(B, cell[B]);
        size[C] = g_.coord(C, cell[C] + 1) - g_.coord(C, cell[C]);
        inv_size = 1.0 / size;
        extent_known = true;
      }
      return extent_ok;
    };
    const auto flush = [&] {
      if (n_candidates == 0) return;
      if (!extent()) {
        n_candidates = 0;
        return;
      }
      const CellNormals<T> normals(g_, cell, corner, iso_);  // once for the cell's rays
      for (int m = 0; m < n_candidates; ++m) {
        const Candidate& h = candidates[m];
        glm::dvec3 local;
        local[B] = h.pb;
        local[C] = h.pc;
        out.push_back(
            {h.k, axis_root(normals, A, step, local, inv_size, h.fa, h.fb, t_in, t_out, l.dir)});
      }
      n_candidates = 0;
    };
    const auto solve_cell_rays = [&](std::int64_t rx, std::int64_t ry, std::int64_t rz) {
      const std::int64_t rel[3] = {rx, ry, rz};
      const std::size_t qb = std::size_t(rel[B]), qc = std::size_t(rel[C]);
      const std::uint32_t b0 = along_b.first[qb], b1 = along_b.first[qb + 1];
      const std::uint32_t c0 = along_c.first[qc], c1 = along_c.first[qc + 1];
      if (b0 == b1 || c0 == c1) return;
      for (int k = 0; k < 3; ++k)
        cell[k] = first_[k] + rel[k];
      extent_known = false;
      const T* lower = g_.values + cell[0] * s[0] + cell[1] * s[1] + cell[2] * s[2];
      for (int m = 0; m < 8; ++m)
        corner[m] = double(lower[offsets[m]]) - iso_;
      double f_in[4], f_out[4];
      for (int m = 0; m < 4; ++m) {
        f_in[m] = corner[face_in[m]];
        f_out[m] = corner[face_out[m]];
      }
      for (std::uint32_t mc = c0; mc < c1; ++mc) {
        const std::uint32_t pixel_c = along_c.pixels[mc];
        const double pc = along_c.p[pixel_c];
        for (std::uint32_t mb = b0; mb < b1; ++mb) {
          const std::uint32_t pixel_b = along_b.pixels[mb];
          const std::size_t k = pixel_b * stride_b + pixel_c * stride_c;
          if (!x.whole[k]) continue;
          const double pb = along_b.p[pixel_b];
          const double wb[2] = {1.0 - pb, pb}, wc[2] = {1.0 - pc, pc};
          const double w[4] = {wb[0] * wc[0], wb[1] * wc[0], wb[0] * wc[1], wb[1] * wc[1]};
          const double fa = face_value(w, f_in), fb = face_value(w, f_out);
          if (std::isfinite(fa) && std::isfinite(fb) && fa != 0.0 && fb != 0.0) [[likely]] {
            candidates[n_candidates] = {std::uint32_t(k), fa, fb, pb, pc};
            n_candidates += positive(fa) != positive(fb);
            if (n_candidates == kCandidates) flush();
            continue;
          }
          // A face value zero or not finite: solve_cell decides, as in cast_ray.
          if (!extent()) continue;
          std::array<int, 3> steps{0, 0, 0};
          steps[A] = step;
          std::array<bool, 3> entry_face{false, false, false}, exit_face{false, false, false};
          entry_face[A] = exit_face[A] = true;
          x.hits.clear();
          solve_cell<true>(g_, iso_, l.ray[k].org, l.dir, cell, steps, t_in, t_out, entry_face,
                           exit_face, x.hits);
          for (const RayHit& h : x.hits)
            out.push_back({std::uint32_t(k), h});
        }
      }
      flush();
    };

    const std::size_t cw = row_words();
    const std::size_t w0 = std::size_t(l.lo[0]) / 64, w1 = std::size_t(l.hi[0]) / 64;
    for (std::int64_t z = l.lo[2]; z <= l.hi[2]; ++z)
      for (std::int64_t y = l.lo[1]; y <= l.hi[1]; ++y) {
        const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
        for (std::size_t w = w0; w <= w1; ++w) {
          std::uint64_t bits = row[w];
          if (w == w0) bits &= ~std::uint64_t(0) << (l.lo[0] % 64);
          if (w == w1 && l.hi[0] % 64 != 63) bits &= (std::uint64_t(1) << (l.hi[0] % 64 + 1)) - 1;
          for (; bits; bits &= bits - 1)
            solve_cell_rays(std::int64_t(w) * 64 + std::countr_zero(bits), y, z);
        }
      }
  }

  // The cell along transverse axis b that holds coordinate x ∈ [coord(first), coord(last + 1)]:
  // the last cell whose lower face is at or below x (the upper cell on a shared face, as the
  // Embree binding's walk starts).
  std::int64_t cell_index(int b, double x) const {
    if (g_.rectilinear) {
      const double* c = g_.coords[b];
      return std::int64_t(std::upper_bound(c + first_[b] + 1, c + last_[b] + 1, x) - c) - 1;
    }
    const double guess = std::floor((x - g_.origin[b]) / g_.spacing[b]);
    std::int64_t i = std::clamp(std::int64_t(std::clamp(guess, -1e18, 1e18)), first_[b], last_[b]);
    while (i < last_[b] && g_.coord(b, i + 1) <= x)
      ++i;
    while (i > first_[b] && g_.coord(b, i) > x)
      --i;
    return i;
  }

  // One ray's cast along axis a through its column of cells (cast_ray's state, its steps as
  // always-inline methods): the column's transverse cell and the ray's local coordinates in it,
  // the face value last computed, the cells waiting to be solved, and where the column's
  // straddle bits lie.
  struct ColumnCast {
    // A cell whose face values differ in sign, waiting to be solved (emit_root) in ray order.
    struct Pending {
      std::int64_t i;
      double fa, fb, ta, tb;
    };
    static constexpr int kPending = 32;

    const GridAxisCaster& s;
    const GridView<T>& g;
    const double iso;
    const int a, b, c;  // the ray's axis, the transverse axes (b < c)
    const glm::dvec3 o, dir;
    const AxisRay& ray;
    std::vector<RayHit>& hits;
    std::array<std::int64_t, 3> cell;
    double p[3];                // local coordinates across the ray, as solve_cell has them
    glm::dvec3 inv_size{0.0};   // one over the cells' edges across the ray (the gradients')
    double w[4];                // the four face points' weights (trilinear_value's order)
    std::int64_t sa, sb, sc;    // the strides along a, b, c
    const T* points = nullptr;  // the column's lowest points
    std::int64_t offsets[8];    // corner n of a cell (x + 2y + 4z) from its lowest point
    int step = 1;
    double inv = 0.0;  // 1 / dir[a]
    std::array<int, 3> steps{0, 0, 0};
    std::int64_t cached_node = -1;  // the face value last computed (cells share faces)
    double cached_value = 0.0;
    Pending pending[kPending];
    int n_pending = 0;
    std::size_t base = 0, along = 0;  // straddle word of cell 0 along a, words between cells
    unsigned bit0 = 0;

    ColumnCast(const GridAxisCaster& caster, int axis, glm::dvec3 d, const AxisRay& r,
               std::vector<RayHit>& out)
        : s(caster),
          g(caster.g_),
          iso(caster.iso_),
          a(axis),
          b(axis == 0 ? 1 : 0),
          c(axis == 2 ? 1 : 2),
          o(r.org),
          dir(d),
          ray(r),
          hits(out) {}

    // The ray's column of straddle words, or null where the ray misses the block's cross-section
    // or no cell of its column straddles (solve_cell finds nothing elsewhere).
    [[gnu::always_inline]] const std::uint64_t* column() {
      if (o[b] < g.coord(b, s.first_[b]) || o[b] > g.coord(b, s.last_[b] + 1) ||
          o[c] < g.coord(c, s.first_[c]) || o[c] > g.coord(c, s.last_[c] + 1))
        return nullptr;
      cell[b] = s.cell_index(b, o[b]);
      cell[c] = s.cell_index(c, o[c]);
      const std::size_t words = s.column_words(a);
      const std::uint64_t* col = &s.columns_[a][std::size_t(cell[b] - s.first_[b] +
                                                            s.cells_[b] * (cell[c] - s.first_[c])) *
                                                words];
      if (std::all_of(col, col + words, [](std::uint64_t x) { return x == 0; })) return nullptr;
      return col;
    }

    // What every cell of the column shares: local coordinates and weights across the ray, the
    // corner offsets, the direction, where the straddle bits lie.
    [[gnu::always_inline]] void prepare() {
      for (int k : {b, c}) {
        const double lo = g.coord(k, cell[k]), size = g.coord(k, cell[k] + 1) - lo;
        p[k] = std::clamp((o[k] - lo) / size, 0.0, 1.0);
        inv_size[k] = 1.0 / size;
      }
      const double wb[2] = {1.0 - p[b], p[b]}, wc[2] = {1.0 - p[c], p[c]};
      w[0] = wb[0] * wc[0];
      w[1] = wb[1] * wc[0];
      w[2] = wb[0] * wc[1];
      w[3] = wb[1] * wc[1];
      sa = g.strides[a];
      sb = g.strides[b];
      sc = g.strides[c];
      points = g.values + cell[b] * sb + cell[c] * sc;
      for (int n = 0; n < 8; ++n)
        offsets[n] = ((n >> a) & 1) * sa + ((n >> b) & 1) * sb + ((n >> c) & 1) * sc;
      step = dir[a] > 0.0 ? 1 : -1;
      inv = 1.0 / dir[a];
      steps[a] = step;
      const std::size_t cw = s.row_words();
      const std::int64_t rb = cell[b] - s.first_[b], rc = cell[c] - s.first_[c];
      if (a == 0) {
        base = std::size_t(rb + s.cells_[1] * rc) * cw;
      } else {
        base = (a == 1 ? std::size_t(s.cells_[1]) * std::size_t(rc) : std::size_t(rc)) * cw +
               std::size_t(rb) / 64;
        along = a == 1 ? cw : std::size_t(s.cells_[1]) * cw;
        bit0 = unsigned(rb % 64);
      }
    }

    [[gnu::always_inline]] double t_at(std::int64_t node) const {
      return (g.coord(a, node) - o[a]) * inv;
    }
    // The value on the face at node `node` along a, at the ray (computed once per face).
    [[gnu::always_inline]] double face(std::int64_t node) {
      if (node != cached_node) {
        const T* q = points + node * sa;
        const double f[4] = {double(q[0]) - iso, double(q[sb]) - iso, double(q[sc]) - iso,
                             double(q[sb + sc]) - iso};
        cached_value = face_value(w, f);
        cached_node = node;
      }
      return cached_value;
    }
    // Whether the column's cell at relative index k along a straddles.
    [[gnu::always_inline]] bool straddling(std::int64_t k) const {
      if (a == 0) return bool((s.straddle_[base + std::size_t(k) / 64] >> (k % 64)) & 1u);
      return bool((s.straddle_[base + std::size_t(k) * along] >> bit0) & 1u);
    }

    // The hit in cell i on [ta, tb] whose face values fa, fb (finite, nonzero) differ in sign:
    // the one root of the linear function between the faces (as trilinear_segment_roots
    // computes it for a segment along one axis), and the gradient there, as solve_cell.
    void emit_root(std::int64_t i, double fa, double fb, double ta, double tb) {
      double corner[8];
      const T* lower = points + i * sa;
      for (int n = 0; n < 8; ++n)
        corner[n] = double(lower[offsets[n]]) - iso;
      glm::dvec3 local(0.0), inv_cell = inv_size;  // across the ray: the column's, once
      local[b] = p[b];
      local[c] = p[c];
      inv_cell[a] = 1.0 / (g.coord(a, i + 1) - g.coord(a, i));
      std::array<std::int64_t, 3> at = cell;
      at[a] = i;
      const CellNormals<T> normals(g, at, corner, iso);
      hits.push_back(axis_root(normals, a, step, local, inv_cell, fa, fb, ta, tb, dir));
    }
    // The waiting cells solved, in ray order.
    [[gnu::always_inline]] void flush() {
      for (int k = 0; k < n_pending; ++k)
        emit_root(pending[k].i, pending[k].fa, pending[k].fb, pending[k].ta, pending[k].tb);
      n_pending = 0;
    }

    // Cell i on [ta, tb], entered / left exactly on its faces or not: the shortcut where it
    // decides (the cell waits in `pending` when the buffer has room), solve_cell (the Embree
    // binding's) where it does not, after the waiting cells.
    [[gnu::always_inline]] void solve(std::int64_t i, double ta, double tb, bool on_entry,
                                      bool on_exit) {
      if (on_entry && on_exit) {
        const double fa = face(step > 0 ? i : i + 1);
        const double fb = face(step > 0 ? i + 1 : i);
        if (std::isfinite(fa) && std::isfinite(fb) && fa != 0.0 && fb != 0.0) {
          // A candidate whatever the signs, kept only where they differ: no branch on the
          // outcome, which is near random.
          pending[n_pending] = {i, fa, fb, ta, tb};
          n_pending += positive(fa) != positive(fb);
          if (n_pending == kPending) flush();
          return;
        }
      }
      flush();
      cell[a] = i;
      std::array<bool, 3> entry_face{false, false, false}, exit_face{false, false, false};
      entry_face[a] = on_entry;
      exit_face[a] = on_exit;
      // Checking corners for NaN and ±Inf changes nothing for a cell without them.
      solve_cell<true>(g, iso, o, dir, cell, steps, ta, tb, entry_face, exit_face, hits);
    }

    // The brick (the Embree binding's primitive) of cell i along a, and its stretch of the ray
    // clipped as clip_ray_to_box clips it.
    [[gnu::always_inline]] Stretch stretch_of(std::int64_t i) const {
      Stretch st;
      st.lo = s.first_[a] + (i - s.first_[a]) / s.brick_cells_ * s.brick_cells_;
      st.hi = std::min(s.last_[a], st.lo + s.brick_cells_ - 1);
      double ta = t_at(st.lo), tb = t_at(st.hi + 1);
      if (ta > tb) std::swap(ta, tb);
      st.face_in = ta;
      st.t0 = std::max(ray.t0, ta);
      st.t1 = std::min(ray.t1, tb);
      return st;
    }

    // The brick the ray's segment starts inside (not on its face), walked from the segment's
    // start point as the Embree binding walks it, cell by cell; its cells in [lo, hi] (none:
    // lo > hi).
    void start_brick(std::int64_t& lo, std::int64_t& hi) {
      lo = -1, hi = -2;
      const std::int64_t first = s.first_[a], last = s.last_[a];
      if (!(ray.t0 > std::min(t_at(first), t_at(last + 1)))) return;
      const double e = o[a] + ray.t0 * dir[a];
      std::int64_t guess = first;
      if (e >= g.coord(a, last + 1)) {
        guess = last;
      } else if (e > g.coord(a, first)) {
        guess = s.cell_index(a, e);
      }
      for (std::int64_t i : {guess, guess - step, guess + step}) {
        if (i < first || i > last) continue;
        const Stretch st = stretch_of(i);
        if (st.t0 > st.face_in && st.t0 < st.t1) {
          lo = st.lo;
          hi = st.hi;
          // solve_cell finds nothing in a cell that does not straddle: only those are solved.
          s.walk(a, st, o, dir, step, inv,
                 [&](std::int64_t k, double ta, double tb, bool on_entry, bool on_exit) {
                   if (straddling(k - first)) solve(k, ta, tb, on_entry, on_exit);
                 });
          return;
        }
      }
    }

    // The straddling cells of `col` in ray order, but those in [skip_lo, skip_hi] (walked by
    // start_brick).
    [[gnu::always_inline]] void straddling_cells(const std::uint64_t* col, std::int64_t skip_lo,
                                                 std::int64_t skip_hi) {
      const std::int64_t first = s.first_[a], last = s.last_[a];
      // Whether the segment covers the block's whole stretch along a: then every brick is
      // entered and left on its faces, and so is every cell (no clipping to compute).
      const bool whole = ray.t0 <= std::min(t_at(first), t_at(last + 1)) &&
                         ray.t1 >= std::max(t_at(first), t_at(last + 1));
      const std::int64_t n_blocks = (s.cells_[a] + kColumnBlock - 1) / kColumnBlock;
      const std::size_t wpc = s.column_words(a);
      for (std::size_t wi = 0; wi < wpc; ++wi) {
        const std::size_t wd = step > 0 ? wi : wpc - 1 - wi;
        std::uint64_t bits = col[wd];
        while (bits) {
          const int bit = step > 0 ? std::countr_zero(bits) : 63 - std::countl_zero(bits);
          bits &= ~(std::uint64_t(1) << bit);
          const std::int64_t q = std::int64_t(wd) * 64 + bit;
          if (q >= n_blocks) continue;
          const std::int64_t k0 = first + q * kColumnBlock;
          const std::int64_t k1 = std::min(last, k0 + kColumnBlock - 1);
          for (std::int64_t m = 0; m <= k1 - k0; ++m) {
            const std::int64_t i = step > 0 ? k0 + m : k1 - m;
            if (i >= skip_lo && i <= skip_hi) continue;
            if (!straddling(i - first)) continue;
            const double t_in = t_at(step > 0 ? i : i + 1), t_out = t_at(step > 0 ? i + 1 : i);
            if (whole) {
              if (t_out > t_in) solve(i, t_in, t_out, true, true);
              continue;
            }
            const Stretch st = stretch_of(i);
            if (!(st.t0 < st.t1)) continue;  // the Embree binding skips the brick
            const double ta = std::max(st.t0, t_in), tb = std::min(st.t1, t_out);
            if (tb > ta) solve(i, ta, tb, t_in == ta, t_out <= st.t1);
          }
        }
      }
    }
  };

  void cast_ray(int a, glm::dvec3 dir, const AxisRay& ray, std::vector<RayHit>& hits) const {
    ColumnCast cast(*this, a, dir, ray, hits);
    const std::uint64_t* column = cast.column();
    if (!column) return;
    cast.prepare();
    std::int64_t start_lo, start_hi;
    cast.start_brick(start_lo, start_hi);
    cast.straddling_cells(column, start_lo, start_hi);
    cast.flush();
  }

  // The Embree binding's walk through the cells of one brick's stretch of the ray, step by
  // step (GridBinding::intersect_brick, here along axis a only).
  template <class Solve>
  void walk(int a, const Stretch& st, glm::dvec3 o, glm::dvec3 dir, int step, double inv,
            const Solve& solve) const {
    const double entry = o[a] + st.t0 * dir[a];
    std::int64_t i = st.lo;
    if (g_.coord(a, st.hi) <= entry) {
      i = st.hi;
    } else {
      while (i < st.hi && g_.coord(a, i + 1) <= entry)
        ++i;
    }
    if (step < 0 && i > st.lo && g_.coord(a, i) == entry) --i;
    double t_next = (g_.coord(a, step > 0 ? i + 1 : i) - o[a]) * inv;
    bool on_entry = (g_.coord(a, step > 0 ? i : i + 1) - o[a]) * inv == st.t0;
    double t = st.t0;
    while (t < st.t1) {
      const double t_exit = std::min(t_next, st.t1);
      const bool on_exit = t_next == t_exit;
      if (t_exit > t) solve(i, t, t_exit, on_entry, on_exit);
      t = std::max(t, t_exit);
      on_entry = on_exit;
      if (!on_exit) break;
      i += step;
      if (i < st.lo || i > st.hi) break;
      t_next = (g_.coord(a, step > 0 ? i + 1 : i) - o[a]) * inv;
    }
  }

  GridView<T> g_;
  std::shared_ptr<const std::vector<std::uint8_t>> held_;
  double iso_;
  std::array<std::int64_t, 3> first_, last_, bricks_, cells_;
  int brick_cells_;
  std::uint64_t nonfinite_ = 0;
  std::vector<std::uint64_t> straddle_;  // per cell row along x, 64 cells per word
  mutable std::array<std::vector<std::uint64_t>, 3> columns_;
  mutable std::array<std::once_flag, 3> column_once_;
  mutable std::once_flag count_once_;
  mutable std::size_t active_bricks_ = 0;
};

}  // namespace

template <class T>
std::unique_ptr<AxisCaster> bind_grid_axis(const GridView<T>& grid, double iso,
                                           std::array<std::int64_t, 3> first,
                                           std::array<std::int64_t, 3> last,
                                           std::array<std::int64_t, 3> bricks, int brick_cells,
                                           std::shared_ptr<const std::vector<std::uint8_t>> held) {
  return std::make_unique<GridAxisCaster<T>>(grid, iso, first, last, bricks, brick_cells,
                                             std::move(held));
}

template std::unique_ptr<AxisCaster> bind_grid_axis<float>(
    const GridView<float>&, double, std::array<std::int64_t, 3>, std::array<std::int64_t, 3>,
    std::array<std::int64_t, 3>, int, std::shared_ptr<const std::vector<std::uint8_t>>);
template std::unique_ptr<AxisCaster> bind_grid_axis<double>(
    const GridView<double>&, double, std::array<std::int64_t, 3>, std::array<std::int64_t, 3>,
    std::array<std::int64_t, 3>, int, std::shared_ptr<const std::vector<std::uint8_t>>);

}  // namespace ldimesh::grid
