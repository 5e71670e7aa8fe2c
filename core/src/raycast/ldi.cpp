#include "ldimesh/core/raycast/ldi.hpp"

namespace ldimesh {

Ldi make_empty_ldi(const View& view) {
  Ldi ldi;
  ldi.view = view;
  ldi.offsets.assign(view.pixel_count() + 1, 0);
  return ldi;
}

std::vector<std::uint32_t> sample_pixels(const Ldi& ldi) {
  std::vector<std::uint32_t> pixel(ldi.sample_count());
  for (std::size_t p = 0; p < ldi.pixel_count(); ++p)
    for (std::uint32_t s = ldi.begin(p); s < ldi.end(p); ++s)
      pixel[s] = std::uint32_t(p);
  return pixel;
}

std::vector<glm::vec3> sample_positions(const Ldi& ldi) {
  std::vector<glm::vec3> pos(ldi.sample_count());
  const View& v = ldi.view;
  for (int j = 0; j < v.height; ++j)
    for (int i = 0; i < v.width; ++i) {
      const std::size_t p = std::size_t(j) * v.width + i;
      for (std::uint32_t s = ldi.begin(p); s < ldi.end(p); ++s)
        pos[s] = glm::vec3(v.pixel_point(i, j, ldi.depth[s]));
    }
  return pos;
}

}  // namespace ldimesh
