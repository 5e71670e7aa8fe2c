// The background path's snapshot: what a due step reads of the solver's blocks, copied while
// the solver waits, so that the caster thread can cast it while the solver goes on. Internal to
// the adaptor library.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "block.hpp"
#include "ldimesh/core/base/status.hpp"
#include "sparse_copy.hpp"

namespace ldimesh {

// The copies of the blocks of the step last taken, kept from step to step so that later copies
// reuse their pages. The solver's thread takes it (plan, then take) while the caster thread is
// idle; the caster thread reads blocks() until it is idle again.
class BlockSnapshot {
 public:
  struct CopyPlan;
  // What a step copies of its blocks (plan), and the bytes the copy will hold.
  struct Plan {
    std::vector<CopyPlan> blocks;
    std::size_t bytes = 0;
  };
  // Chooses what a step for `isovalues` reads of `blocks`: a grid block's bricks (and, of each
  // colour field, those of the isovalues whose bits — 1 << i, 1 << 7 from the eighth on —
  // `field_bits` has), an element block's elements, a cell block's every cell. Errors: the
  // memory to plan it (out_of_memory).
  static StatusOr<Plan> plan(const std::vector<Block>& blocks, std::span<const double> isovalues,
                             std::span<const std::uint8_t> field_bits);
  // Copies what `plan` chose of `blocks` (those it was made for), the pages no longer needed
  // given back before any is written. Errors: the system refused the memory (no snapshot then).
  Status take(const std::vector<Block>& blocks, Plan plan);
  // Gives the memory back (no snapshot).
  void clear();
  // Sources over the copies, with their colour fields, as the step's blocks.
  const std::vector<Block>& blocks() const { return blocks_; }
  // The bytes the copies hold.
  std::size_t bytes() const;

  // A block's arrays as copied.
  struct BlockCopy {
    SparseCopy values;
    std::vector<SparseCopy> colours;  // per colour field ("colour_by"), where the block has it
    std::array<std::vector<double>, 3> coords;
    std::size_t bytes() const;
  };
  // What a step copies of one block: the bricks or elements a cast reads (`held`), and the
  // pages of its arrays they lie in (per colour field, those of the bricks the isovalues it
  // colours read, `colour_held`, empty where that is `held`; a field the block lacks: none).
  struct CopyPlan {
    std::vector<std::uint8_t> held;
    std::size_t values_size = 0;  // the arrays' bytes
    PageSet values;
    std::vector<std::size_t> colour_sizes;
    std::vector<PageSet> colours;
    std::vector<std::vector<std::uint8_t>> colour_held;
    std::size_t coords_bytes = 0;
    std::size_t bytes() const;
  };

 private:
  std::vector<BlockCopy> copies_;
  std::vector<Block> blocks_;
};

}  // namespace ldimesh
