// Layered Depth Images (Shade et al. 1998): every hit along every ray of a view.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/view.hpp"

namespace ldimesh {

// One view plus its samples in CSR form. The samples of pixel p = j * width + i are the indices
// [offsets[p], offsets[p + 1]) of depth, normal and (when present) scalar, sorted by increasing
// depth. Normals are unit vectors along the field gradient (pointing toward higher values).
// `scalar` is either empty or holds one value per sample.
struct Ldi {
  View view;
  std::vector<std::uint32_t> offsets;  // pixel_count() + 1 entries, offsets[0] == 0
  std::vector<float> depth;
  std::vector<glm::vec3> normal;
  std::vector<float> scalar;

  std::size_t pixel_count() const { return view.pixel_count(); }
  std::size_t sample_count() const { return depth.size(); }
  std::uint32_t begin(std::size_t pixel) const { return offsets[pixel]; }
  std::uint32_t end(std::size_t pixel) const { return offsets[pixel + 1]; }
  std::uint32_t count(std::size_t pixel) const { return offsets[pixel + 1] - offsets[pixel]; }
};

// An LDI of `view` with no samples.
Ldi make_empty_ldi(const View& view);

// World positions of all samples of `ldi`, in sample order.
std::vector<glm::vec3> sample_positions(const Ldi& ldi);

// The pixel index of every sample, in sample order.
std::vector<std::uint32_t> sample_pixels(const Ldi& ldi);

}  // namespace ldimesh
