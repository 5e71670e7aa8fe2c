#include "axis_bins.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

namespace ldimesh {

AxisBins make_axis_bins(std::span<const AxisBox> boxes, int axis) {
  AxisBins bins;
  bins.b = axis == 0 ? 1 : 0;
  bins.c = axis == 2 ? 1 : 2;
  const std::size_t n = boxes.size();
  if (n > AxisBins::kIndex) throw std::length_error("more than 2^30 boxes to bin");
  if (n == 0) {
    bins.first.assign(2, 0);
    return bins;
  }
  double lo_b = INFINITY, hi_b = -INFINITY, lo_c = INFINITY, hi_c = -INFINITY;
  for (const AxisBox& box : boxes) {
    lo_b = std::min(lo_b, box.lo[bins.b]), hi_b = std::max(hi_b, box.hi[bins.b]);
    lo_c = std::min(lo_c, box.lo[bins.c]), hi_c = std::max(hi_c, box.hi[bins.c]);
  }
  // The median widths, of at most 4096 boxes evenly spread over the list.
  const std::size_t stride = std::max<std::size_t>(1, n / 4096);
  std::vector<double> wb, wc;
  for (std::size_t e = 0; e < n; e += stride) {
    wb.push_back(boxes[e].hi[bins.b] - boxes[e].lo[bins.b]);
    wc.push_back(boxes[e].hi[bins.c] - boxes[e].lo[bins.c]);
  }
  std::nth_element(wb.begin(), wb.begin() + wb.size() / 2, wb.end());
  std::nth_element(wc.begin(), wc.begin() + wc.size() / 2, wc.end());
  double median_b = wb[wb.size() / 2], median_c = wc[wc.size() / 2];
  // Each box's bin range (b0, b1, c0, c1) under the layout being tried; the entries in all.
  std::vector<std::array<int, 4>> range(n);
  const auto ranges = [&] {
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, n, 4096), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::size_t entries) {
          for (std::size_t e = r.begin(); e != r.end(); ++e) {
            const AxisBox& box = boxes[e];
            range[e] = {bins.bin_b(box.lo[bins.b]), bins.bin_b(box.hi[bins.b]),
                        bins.bin_c(box.lo[bins.c]), bins.bin_c(box.hi[bins.c])};
            entries += std::size_t(range[e][1] - range[e][0] + 1) *
                       std::size_t(range[e][3] - range[e][2] + 1);
          }
          return entries;
        },
        std::plus<>());
  };
  const auto layout = [](double lo, double hi, double median, double& size, int& count) {
    const double extent = std::max(hi - lo, 1e-300);
    count = int(std::clamp(std::ceil(extent / std::max(median, extent / 4096.0)), 1.0, 4096.0));
    size = extent / count;
  };
  bins.lo_b = lo_b, bins.lo_c = lo_c;
  for (;;) {
    layout(lo_b, hi_b, median_b, bins.size_b, bins.nb);
    layout(lo_c, hi_c, median_c, bins.size_c, bins.nc);
    if (ranges() <= 16 * n + 1024 || (bins.nb == 1 && bins.nc == 1)) break;
    median_b = 2.0 * std::max(median_b, bins.size_b);
    median_c = 2.0 * std::max(median_c, bins.size_c);
  }
  const std::size_t cells = std::size_t(bins.nb) * std::size_t(bins.nc);
  bins.first.assign(cells + 1, 0);
  for (std::size_t e = 0; e < n; ++e)
    for (int cc = range[e][2]; cc <= range[e][3]; ++cc)
      for (int bb = range[e][0]; bb <= range[e][1]; ++bb)
        ++bins.first[bins.bin(bb, cc) + 1];
  for (std::size_t k = 0; k < cells; ++k)
    bins.first[k + 1] += bins.first[k];
  bins.entries.resize(bins.first[cells]);
  std::vector<std::uint32_t> next(bins.first.begin(), bins.first.end() - 1);
  for (std::size_t e = 0; e < n; ++e)
    for (int cc = range[e][2]; cc <= range[e][3]; ++cc)
      for (int bb = range[e][0]; bb <= range[e][1]; ++bb)
        bins.entries[next[bins.bin(bb, cc)]++] = std::uint32_t(e) |
                                                 (bb == range[e][0] ? AxisBins::kFirstB : 0u) |
                                                 (cc == range[e][2] ? AxisBins::kFirstC : 0u);
  return bins;
}

}  // namespace ldimesh
