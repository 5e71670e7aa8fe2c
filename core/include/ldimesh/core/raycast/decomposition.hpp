// Splitting the global domain into one block per rank.
#pragma once

#include <array>
#include <vector>

#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh {

// Blocks per axis for `parts` blocks of `box`: factors as close to each other as possible
// (like MPI_Dims_create), the largest along the longest side. Throws std::invalid_argument for
// parts < 1.
std::array<int, 3> block_grid(const Box& box, int parts);

// `parts` boxes tiling `box` along the block_grid, block k = i + nx·(j + ny·k'), x fastest.
// Neighbouring boxes share their faces exactly (both computed by one formula), so the
// half-open ownership rule of Subdomain assigns every point to exactly one box.
std::vector<Box> decompose_box(const Box& box, int parts);

}  // namespace ldimesh
