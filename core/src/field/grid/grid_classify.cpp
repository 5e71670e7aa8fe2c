// The grid axis caster's bind-time pass (grid_axis.cpp): one pass over the block's points gives
// each point's sign against the isovalue and each cell a bit "its corners have both signs".
#include "grid_cells.hpp"

namespace ldimesh::grid {
namespace {

// Bits from … to (inclusive) of a row of words.
void set_bits(std::uint64_t* words, std::int64_t from, std::int64_t to) {
  for (std::int64_t i = from; i <= to; ++i)
    words[i / 64] |= std::uint64_t(1) << (i % 64);
}

// The bricks along axis a whose points include relative point index i: brick b holds points
// b·brick_cells … b·brick_cells + brick_cells (the last one up to the last point).
std::pair<std::int64_t, std::int64_t> bricks_of_point(const std::array<std::int64_t, 3>& bricks,
                                                      int brick_cells, int a, std::int64_t i) {
  const std::int64_t hi = std::min(i / brick_cells, bricks[a] - 1);
  return {i % brick_cells == 0 && i > 0 ? i / brick_cells - 1 : hi, hi};
}

}  // namespace

template <class T>
void classify_cells(const GridView<T>& g, double iso, const std::array<std::int64_t, 3>& first,
                    const std::array<std::int64_t, 3>& cells,
                    const std::array<std::int64_t, 3>& bricks, int brick_cells,
                    std::vector<std::uint64_t>& straddle, std::uint64_t& nonfinite_count) {
  const std::int64_t px = cells[0] + 1, py = cells[1] + 1, pz = cells[2] + 1;
  const std::size_t pw = std::size_t((px + 63) / 64), cw = std::size_t((cells[0] + 63) / 64);
  std::vector<std::uint64_t> sign(pw * std::size_t(py * pz), 0);
  std::atomic<std::uint64_t> nonfinite{0};
  // Per brick row (y fastest): the held bricks' cells and points along x.
  std::vector<std::uint64_t> held_cells, held_points;
  if (g.held) {
    const std::int64_t rows = bricks[1] * bricks[2];
    held_cells.assign(std::size_t(rows) * cw, 0);
    held_points.assign(std::size_t(rows) * pw, 0);
    for (std::int64_t r = 0; r < rows; ++r)
      for (std::int64_t b = 0; b < bricks[0]; ++b) {
        if (!g.held[b + bricks[0] * r]) continue;
        const std::int64_t lo = b * brick_cells, hi = std::min(lo + brick_cells, cells[0]);
        set_bits(&held_cells[std::size_t(r) * cw], lo, hi - 1);
        set_bits(&held_points[std::size_t(r) * pw], lo, hi);
      }
  }
  // The sign test in T: for a float v, v − iso ≥ 0 in double iff v ≥ the least float whose
  // double is ≥ iso (NaN fails both), so the rows compare in their own type, in bulk.
  T threshold = T(iso);
  if (double(threshold) < iso) threshold = std::nextafter(threshold, T(INFINITY));
  tbb::parallel_for(std::int64_t(0), pz, [&](std::int64_t z) {
    std::uint64_t bad = 0;
    T line[64];
    std::vector<std::uint64_t> held(g.held ? pw : 0);  // this row's held points
    for (std::int64_t y = 0; y < py; ++y) {
      std::uint64_t* row = &sign[std::size_t(y + py * z) * pw];
      if (g.held) {
        std::fill(held.begin(), held.end(), 0);
        const auto [y0, y1] = bricks_of_point(bricks, brick_cells, 1, y);
        const auto [z0, z1] = bricks_of_point(bricks, brick_cells, 2, z);
        for (std::int64_t bz = z0; bz <= z1; ++bz)
          for (std::int64_t by = y0; by <= y1; ++by)
            for (std::size_t w = 0; w < pw; ++w)
              held[w] |= held_points[std::size_t(by + bricks[1] * bz) * pw + w];
      }
      const T* v = g.values + (first[0]) * g.strides[0] + (first[1] + y) * g.strides[1] +
                   (first[2] + z) * g.strides[2];
      const std::int64_t sx = g.strides[0];
      for (std::int64_t x0 = 0; x0 < px; x0 += 64) {
        // No held point here: not read at all (a snapshot may have given these pages back to
        // the system; reading them would fault zero pages in).
        if (g.held && held[std::size_t(x0 / 64)] == 0) continue;
        const int n = int(std::min<std::int64_t>(64, px - x0));
        const T* src = v + x0 * sx;
        if (sx != 1 || n < 64) {  // into a padded line (the padding: clear, not counted)
          for (int i = 0; i < n; ++i)
            line[i] = src[i * sx];
          std::fill(line + n, line + 64, T(-INFINITY));
          src = line;
        }
        std::uint64_t finite = 0;
        row[x0 / 64] = sign_bits(src, threshold, finite);
        if (g.held)
          bad += std::uint64_t(std::popcount(~finite & held[x0 / 64]));
        else
          bad += std::uint64_t(64 - std::popcount(finite)) - std::uint64_t(64 - n);
      }
    }
    if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
  });
  nonfinite_count = nonfinite.load();
  // A cell straddles iff its 8 corner bits are neither all set nor all clear.
  straddle.assign(cw * std::size_t(cells[1] * cells[2]), 0);
  tbb::parallel_for(std::int64_t(0), cells[2], [&](std::int64_t z) {
    for (std::int64_t y = 0; y < cells[1]; ++y) {
      const std::uint64_t* r[4] = {
          &sign[std::size_t(y + py * z) * pw], &sign[std::size_t(y + 1 + py * z) * pw],
          &sign[std::size_t(y + py * (z + 1)) * pw], &sign[std::size_t(y + 1 + py * (z + 1)) * pw]};
      std::uint64_t* out = &straddle[std::size_t(y + cells[1] * z) * cw];
      for (std::size_t w = 0; w < cw; ++w) {
        std::uint64_t any = 0, all = ~std::uint64_t(0);
        for (const std::uint64_t* row : r) {
          const std::uint64_t here = row[w];
          const std::uint64_t next = (here >> 1) | (w + 1 < pw ? row[w + 1] << 63 : 0);
          any |= here | next;
          all &= here & next;
        }
        std::uint64_t bits = any & ~all;
        const std::int64_t valid = cells[0] - std::int64_t(w) * 64;
        if (valid < 64) bits &= (std::uint64_t(1) << valid) - 1;
        if (g.held)
          bits &= held_cells[std::size_t(y / brick_cells + bricks[1] * (z / brick_cells)) * cw + w];
        out[w] = bits;
      }
    }
  });
}

template void classify_cells<float>(const GridView<float>&, double,
                                    const std::array<std::int64_t, 3>&,
                                    const std::array<std::int64_t, 3>&,
                                    const std::array<std::int64_t, 3>&, int,
                                    std::vector<std::uint64_t>&, std::uint64_t&);
template void classify_cells<double>(const GridView<double>&, double,
                                     const std::array<std::int64_t, 3>&,
                                     const std::array<std::int64_t, 3>&,
                                     const std::array<std::int64_t, 3>&, int,
                                     std::vector<std::uint64_t>&, std::uint64_t&);

}  // namespace ldimesh::grid
