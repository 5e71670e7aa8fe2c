#include "ldimesh/core/mesh/trim.hpp"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace ldimesh {

std::size_t trim_by_view_quality(std::vector<std::uint32_t>& quads,
                                 std::span<const glm::vec3> positions, glm::dvec3 view_dir,
                                 std::span<const glm::dvec3> all_dirs, double r) {
  const std::size_t n = quads.size() / 4;
  std::vector<std::uint8_t> keep(n);
  std::vector<glm::vec3> dirs(all_dirs.begin(), all_dirs.end());
  const glm::vec3 dq(view_dir);
  const float rf = float(r);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 2048),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t q = range.begin(); q != range.end(); ++q) {
                        const std::uint32_t* c = &quads[4 * q];
                        bool valid = true;
                        for (int k = 0; k < 4 && valid; ++k) {
                          const glm::vec3 v = positions[c[k]];
                          const glm::vec3 prev = positions[c[(k + 3) & 3]];
                          const glm::vec3 next = positions[c[(k + 1) & 3]];
                          valid = view_quality_ok(glm::cross(v - prev, v - next), dq, dirs, rf);
                        }
                        keep[q] = valid;
                      }
                    });
  std::size_t kept = 0;
  for (std::size_t q = 0; q < n; ++q) {
    if (!keep[q]) continue;
    if (kept != q) std::copy_n(&quads[4 * q], 4, &quads[4 * kept]);
    ++kept;
  }
  quads.resize(4 * kept);
  return kept;
}

}  // namespace ldimesh
