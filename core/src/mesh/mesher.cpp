#include "ldimesh/core/mesh/mesher.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace ldimesh {
namespace {

constexpr std::int32_t kNoSample = -1;

// Depth change of a sample's tangent plane per pixel step along u and along v (world units).
std::vector<glm::vec2> depth_slopes(const Ldi& ldi, double min_facing) {
  const View& view = ldi.view;
  std::vector<glm::vec2> slope(ldi.sample_count());
  const glm::vec3 u(view.u), v(view.v), d(view.dir);
  const float h = float(view.spacing), floor_facing = float(min_facing);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slope.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t s = range.begin(); s != range.end(); ++s) {
                        const glm::vec3 n = ldi.normal[s];
                        float nd = glm::dot(n, d);
                        if (std::abs(nd) < floor_facing) nd = std::copysign(floor_facing, nd);
                        // Tangent plane n·Δp = 0 with Δp = h(a u + b v) + Δdepth d.
                        slope[s] = -h / nd * glm::vec2(glm::dot(n, u), glm::dot(n, v));
                      }
                    });
  return slope;
}

struct Match {
  std::int32_t sample;
  float cost;
};

// §3 best match of s0 (at image position (x, y)) among the samples of the pixel at
// (x + a, y + b): minimises |e(s, x, y) − d(s0)| + |e(s0, x+a, y+b) − d(s)|.
inline Match best_match(const Ldi& ldi, const glm::vec2* slope, std::uint32_t s0, std::size_t pixel,
                        float a, float b, float max_cost) {
  const float d0 = ldi.depth[s0];
  const float e0 = d0 + a * slope[s0].x + b * slope[s0].y;  // s0's prediction at the neighbour
  Match best{kNoSample, max_cost};
  for (std::uint32_t s = ldi.begin(pixel); s < ldi.end(pixel); ++s) {
    const float ds = ldi.depth[s];
    const float es = ds - a * slope[s].x - b * slope[s].y;  // s's prediction back at (x, y)
    const float cost = std::abs(es - d0) + std::abs(e0 - ds);
    if (cost < best.cost) best = {std::int32_t(s), cost};
  }
  return best;
}

// No two samples of one pixel keep the same match: the cheaper keeps it (ties: the nearer).
void keep_cheapest_per_target(std::span<Match> matches) {
  for (std::size_t k = 0; k < matches.size(); ++k) {
    if (matches[k].sample == kNoSample) continue;
    for (std::size_t m = k + 1; m < matches.size(); ++m) {
      if (matches[m].sample != matches[k].sample) continue;
      if (matches[m].cost < matches[k].cost) {
        matches[k].sample = kNoSample;
        break;
      }
      matches[m].sample = kNoSample;
    }
  }
}

}  // namespace

std::vector<std::uint32_t> build_quads(const Ldi& ldi, const MatchOptions& options) {
  const View& view = ldi.view;
  const int W = view.width, H = view.height;
  const std::size_t N = ldi.sample_count();
  if (N == 0 || W < 2 || H < 2) return {};

  const std::vector<glm::vec2> slope = depth_slopes(ldi, options.min_facing);
  const float max_cost = float(options.max_cost * view.spacing);
  // Best match of every sample to the right (x+1, y), top (x, y+1) and top-right (x+1, y+1).
  std::vector<std::int32_t> right(N, kNoSample), top(N, kNoSample), diag(N, kNoSample);

  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    std::vector<Match> r, t, g;
    for (int j = rows.begin(); j != rows.end(); ++j) {
      for (int i = 0; i < W; ++i) {
        const std::size_t p = std::size_t(j) * W + i;
        const std::uint32_t b = ldi.begin(p), e = ldi.end(p);
        if (b == e) continue;
        const bool has_right = i + 1 < W, has_top = j + 1 < H;
        r.assign(e - b, {kNoSample, 0.0f});
        t.assign(e - b, {kNoSample, 0.0f});
        g.assign(e - b, {kNoSample, 0.0f});
        for (std::uint32_t s = b; s < e; ++s) {
          if (has_right) r[s - b] = best_match(ldi, slope.data(), s, p + 1, 1, 0, max_cost);
          if (has_top) t[s - b] = best_match(ldi, slope.data(), s, p + W, 0, 1, max_cost);
          if (has_right && has_top)
            g[s - b] = best_match(ldi, slope.data(), s, p + W + 1, 1, 1, max_cost);
        }
        if (e - b > 1) {
          keep_cheapest_per_target(r);
          keep_cheapest_per_target(t);
          keep_cheapest_per_target(g);
        }
        for (std::uint32_t s = b; s < e; ++s) {
          right[s] = r[s - b].sample;
          top[s] = t[s - b].sample;
          diag[s] = g[s - b].sample;
        }
      }
    }
  });

  // Quads per row, concatenated in row order.
  std::vector<std::vector<std::uint32_t>> row_quads(H - 1);
  const glm::vec3 d(view.dir);
  tbb::parallel_for(tbb::blocked_range<int>(0, H - 1), [&](const tbb::blocked_range<int>& rows) {
    for (int j = rows.begin(); j != rows.end(); ++j) {
      std::vector<std::uint32_t>& out = row_quads[j];
      const std::uint32_t b = ldi.begin(std::size_t(j) * W),
                          e = ldi.end(std::size_t(j) * W + W - 2);
      for (std::uint32_t s0 = b; s0 < e; ++s0) {
        const std::int32_t sr = right[s0], st = top[s0], sg = diag[s0];
        if (sr == kNoSample || st == kNoSample || sg == kNoSample) continue;
        if (top[sr] != sg || right[st] != sg) continue;
        const float facing =
            glm::dot(ldi.normal[s0] + ldi.normal[sr] + ldi.normal[sg] + ldi.normal[st], d);
        // (s0, right, top-right, top) runs counter-clockwise around +dir.
        if (facing >= 0.0f) {
          out.insert(out.end(), {s0, std::uint32_t(sr), std::uint32_t(sg), std::uint32_t(st)});
        } else {
          out.insert(out.end(), {s0, std::uint32_t(st), std::uint32_t(sg), std::uint32_t(sr)});
        }
      }
    }
  });
  std::size_t total = 0;
  for (const auto& q : row_quads)
    total += q.size();
  std::vector<std::uint32_t> quads;
  quads.reserve(total);
  for (const auto& q : row_quads)
    quads.insert(quads.end(), q.begin(), q.end());
  return quads;
}

}  // namespace ldimesh
