// A block the solver added for a step (add_grid_block, add_hex_block, add_cell_block,
// add_source), with its colour fields: what the adaptor casts, and what its snapshot copies.
// Internal to the adaptor library.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {

std::size_t scalar_bytes(ScalarType type);

// A colour field of a block as add_field gave it (values null: the block lacks it).
struct FieldArray {
  const void* values = nullptr;
  ScalarType type = ScalarType::float32;
};

// A colour field of a block and the source that reads it beside the block's values.
struct Colour {
  FieldArray array;
  std::shared_ptr<const FieldSource> source;  // null: the block lacks the field
};

struct Block {
  std::shared_ptr<const FieldSource> source;  // no colour (a FieldSource: its own bind_scalar)
  // Where the block's hits belong. None for element blocks: a solver's partition of its cells
  // is no box, and their bounding boxes overlap, so each block keeps every hit of its cells
  // (element_box) and a hit that cells of two blocks or ranks both find on their shared face
  // is collapsed by the duplicate rule (collapse_duplicate_hits), as one caster collapses its
  // own.
  std::optional<Box> owned;
  // What the block reads, for the background path's copy (neither: a FieldSource, which
  // cannot be copied); their colour pointers are null.
  std::optional<GridBlock> grid;
  std::optional<HexBlock> hex;
  std::optional<CellBlock> cells;
  std::vector<Colour> colours;  // grid and element blocks: per AdaptorOptions::colour_fields

  // Whether the snapshot can copy it (grid and element blocks; a FieldSource cannot).
  bool copyable() const { return grid || hex || cells; }
};

// An element block's subdomain: its cells' bounds grown by 10⁻⁹ of the domain's diagonal, so
// that the half-open box holds every hit of its cells (those on the bounds' upper faces, and
// on rays lying in them, included), clipped to the domain. Only rays that can meet its cells
// are cast.
Box element_box(const Box& bounds, const Box& domain);

// A source over the grid or element block `b` that reads `colour` as its colour field; over the
// block's copy holding only the bricks or elements `held` where given.
std::shared_ptr<const FieldSource> coloured_source(
    const Block& b, FieldArray colour, std::optional<std::vector<std::uint8_t>> held = {});

}  // namespace ldimesh
