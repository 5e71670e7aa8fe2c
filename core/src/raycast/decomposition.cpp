#include "ldimesh/core/raycast/decomposition.hpp"

#include <algorithm>
#include <stdexcept>

namespace ldimesh {

std::array<int, 3> block_grid(const Box& box, int parts) {
  if (parts < 1) throw std::invalid_argument("decomposition: need at least one block");
  // Prime factors, largest first, each given to the axis whose blocks are currently longest.
  std::vector<int> factors;
  for (int n = parts, f = 2; n > 1;) {
    if (f * f > n) {
      factors.push_back(n);
      break;
    }
    if (n % f == 0) {
      factors.push_back(f);
      n /= f;
    } else {
      ++f;
    }
  }
  std::sort(factors.rbegin(), factors.rend());
  std::array<int, 3> grid{1, 1, 1};
  const glm::dvec3 extent = box.extent();
  for (int f : factors) {
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (extent[a] / grid[a] > extent[axis] / grid[axis]) axis = a;
    grid[axis] *= f;
  }
  return grid;
}

std::vector<Box> decompose_box(const Box& box, int parts) {
  const std::array<int, 3> n = block_grid(box, parts);
  auto face = [&](int axis, int i) {
    return i == n[axis] ? box.hi[axis] : box.lo[axis] + (box.hi[axis] - box.lo[axis]) * i / n[axis];
  };
  std::vector<Box> blocks;
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i)
        blocks.push_back({{face(0, i), face(1, j), face(2, k)},
                          {face(0, i + 1), face(1, j + 1), face(2, k + 1)}});
  return blocks;
}

}  // namespace ldimesh
