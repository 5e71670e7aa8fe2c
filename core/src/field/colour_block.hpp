// Internal to the sources: the block whose values are another block's colour field, what a
// source's ScalarProbe reads (GridBlock and HexBlock alike).
#pragma once

namespace ldimesh {

// `block` with its colour array (and type) in place of its values, and no colour of its own.
template <class Block>
Block colour_as_values(const Block& block) {
  Block colour = block;
  colour.values = block.colour;
  colour.type = block.colour_type;
  colour.colour = nullptr;
  return colour;
}

}  // namespace ldimesh
