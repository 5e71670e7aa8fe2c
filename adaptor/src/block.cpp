#include "block.hpp"

#include <utility>

#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {

std::size_t scalar_bytes(ScalarType type) {
  return type == ScalarType::float32 ? sizeof(float) : sizeof(double);
}

Box element_box(const Box& bounds, const Box& domain) {
  const double grow = 1e-9 * domain.diagonal();
  return {glm::max(bounds.lo - grow, domain.lo), glm::min(bounds.hi + grow, domain.hi)};
}

std::shared_ptr<const FieldSource> coloured_source(const Block& b, FieldArray colour,
                                                   std::optional<std::vector<std::uint8_t>> held) {
  if (b.grid) {
    GridBlock g = *b.grid;
    g.colour = colour.values;
    g.colour_type = colour.type;
    const auto& base = static_cast<const GridSource&>(*b.source);
    return held ? std::make_shared<GridSource>(g, base.brick_cells(), std::move(*held))
                : std::make_shared<GridSource>(g, base.brick_cells());
  }
  if (b.cells) {  // a cell block's values are copied whole: no `held`
    CellBlock c = *b.cells;
    c.colour = colour.values;
    c.colour_type = colour.type;
    return std::make_shared<CellElementSource>(static_cast<const CellElementSource&>(*b.source), c);
  }
  HexBlock h = *b.hex;
  h.colour = colour.values;
  h.colour_type = colour.type;
  const auto& prepared = static_cast<const HexElementSource&>(*b.source);
  return held ? std::make_shared<HexElementSource>(prepared, h, std::move(*held))
              : std::make_shared<HexElementSource>(prepared, h);
}

}  // namespace ldimesh
