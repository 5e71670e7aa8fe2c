#include "snapshot.hpp"

#include <algorithm>
#include <cstring>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {
namespace {

using BlockCopy = BlockSnapshot::BlockCopy;
using CopyPlan = BlockSnapshot::CopyPlan;

// Where point (i, j, k) of a grid block lies in its copy (x fastest, no gaps), in values.
std::size_t copy_index(const GridBlock& block, std::int64_t i, std::int64_t j, std::int64_t k) {
  return std::size_t((k * block.dims[1] + j) * block.dims[0] + i);
}

// The bricks of the grid block that `source` is over that a cast for `isovalues` reads, and the
// pages of their points (those a source holding them reads: for_each_needed_run) in its copies:
// the values' for every isovalue, each colour field's in `colours` for the isovalues whose bits
// (1 << i, 1 << 7 from the eighth on: GridSource::needed_bricks_by_isovalue) `field_bits` has.
CopyPlan plan_grid(const GridBlock& block, const GridSource& source,
                   std::span<const double> isovalues, std::span<const FieldArray> colours,
                   std::span<const std::uint8_t> field_bits) {
  CopyPlan plan;
  plan.held = source.needed_bricks_by_isovalue(isovalues);
  std::uint8_t every = 0;
  for (std::uint8_t bits : plan.held)
    every |= bits;
  const std::size_t points = std::size_t(block.dims[0] * block.dims[1] * block.dims[2]);
  const std::size_t size = scalar_bytes(block.type);
  plan.values_size = points * size;
  plan.values = PageSet(plan.values_size);
  std::vector<std::size_t> colour_size;
  for (std::size_t f = 0; f < colours.size(); ++f) {
    colour_size.push_back(colours[f].values ? scalar_bytes(colours[f].type) : 0);
    plan.colour_sizes.push_back(points * colour_size.back());
    plan.colours.emplace_back(plan.colour_sizes.back());
    // A field for some isovalues only: the bricks those need.
    std::vector<std::uint8_t>& held = plan.colour_held.emplace_back();
    if (colour_size.back() > 0 && (every & ~field_bits[f]) != 0)
      for (std::uint8_t bits : plan.held)
        held.push_back((bits & field_bits[f]) != 0);
  }
  for (std::uint8_t& bits : plan.held)
    bits = bits != 0;
  source.for_each_needed_run(
      plan.held, [&](std::int64_t j, std::int64_t k, std::int64_t i0, std::int64_t i1) {
        const std::size_t at = copy_index(block, i0, j, k), n = std::size_t(i1 - i0 + 1);
        plan.values.mark(at * size, n * size);
        for (std::size_t f = 0; f < colour_size.size(); ++f)
          if (plan.colour_held[f].empty())
            plan.colours[f].mark(at * colour_size[f], n * colour_size[f]);
      });
  for (std::size_t f = 0; f < colour_size.size(); ++f)
    if (!plan.colour_held[f].empty())
      source.for_each_needed_run(plan.colour_held[f], [&](std::int64_t j, std::int64_t k,
                                                          std::int64_t i0, std::int64_t i1) {
        const std::size_t at = copy_index(block, i0, j, k), n = std::size_t(i1 - i0 + 1);
        plan.colours[f].mark(at * colour_size[f], n * colour_size[f]);
      });
  for (int a = 0; a < 3; ++a)
    if (block.coords[a]) plan.coords_bytes += std::size_t(block.dims[a]) * sizeof(double);
  return plan;
}

// An element or cell block's colour fields in `plan`, each copied whole (`values` nodal values;
// a field the block lacks: none).
void plan_whole_colours(std::size_t values, std::span<const FieldArray> colours, CopyPlan& plan) {
  for (const FieldArray& c : colours) {
    plan.colour_sizes.push_back(c.values ? values * scalar_bytes(c.type) : 0);
    plan.colours.emplace_back(plan.colour_sizes.back());
    plan.colours.back().mark(0, plan.colour_sizes.back());
    plan.colour_held.emplace_back();
  }
}

// The elements of the high-order block that `source` is over that a cast for `isovalues` keeps,
// the pages of their nodal values in the copy (element after element, no gaps), and all of each
// colour field's in `colours` (a hit on a face a kept element shares with another may be
// coloured from that one).
CopyPlan plan_hex(const HexBlock& block, const HexElementSource& source,
                  std::span<const double> isovalues, std::span<const FieldArray> colours) {
  CopyPlan plan;
  plan.held = source.needed_elements(isovalues);
  const std::size_t n = std::size_t(block.order + 1) * (block.order + 1) * (block.order + 1);
  const std::size_t size = scalar_bytes(block.type);
  plan.values_size = block.element_count * n * size;
  plan.values = PageSet(plan.values_size);
  for (std::size_t e = 0; e < block.element_count; ++e)
    if (plan.held[e]) plan.values.mark(e * n * size, n * size);
  plan_whole_colours(block.element_count * n, colours, plan);
  return plan;
}

// Gives back the pages of block k's copies that `plan` does not write (all of a colour copy the
// block no longer has) before any is written.
void begin_copy(CopyPlan& plan, BlockCopy& copy) {
  copy.values.begin(plan.values_size, std::move(plan.values));
  copy.colours.resize(std::max(copy.colours.size(), plan.colours.size()));
  for (std::size_t f = 0; f < copy.colours.size(); ++f)
    if (f < plan.colours.size() && plan.colour_sizes[f] > 0)
      copy.colours[f].begin(plan.colour_sizes[f], std::move(plan.colours[f]));
    else
      copy.colours[f].clear();
}

// Of a grid block's array of `type` at `values` (its points, ghosts included), the points a
// source holding the bricks `held` reads into `dst`, at their places (copy_index). `pages` are
// the pages of `dst` they lie in (plan_grid): the copy holds those pages whole, so where the
// solver's rows are contiguous (x fastest) it fills them whole, a row's part at a time, from the
// solver's strides. A copy per needed stretch (11 points of a row for a lone brick of 8 cells)
// took twice as long on Gray–Scott (docs/history/benchmarks-log.md, "The copy in the solver's
// layout"). Where the surface is sparse a page holds few needed points, but the
// page is held (and zeroed by the system at its first write) anyway. As the pass that chose the
// bricks (GridSource::needed_bricks): on the calling thread up to 8 Mi points, else in tasks
// on all cores.
void copy_points(const GridBlock& block, const GridSource& source,
                 const std::vector<std::uint8_t>& held, const void* values, ScalarType type,
                 const PageSet& pages, unsigned char* dst) {
  const std::size_t size = scalar_bytes(type);
  std::array<std::int64_t, 3> stride = block.strides;
  if (stride == std::array<std::int64_t, 3>{0, 0, 0})
    stride = {1, block.dims[0], block.dims[0] * block.dims[1]};
  const auto* src = static_cast<const unsigned char*>(values);
  if (stride[0] == 1) {
    // Page sizes are multiples of 8 bytes: no point straddles two pages.
    const std::size_t page = PageSet::page(),
                      points = std::size_t(block.dims[0] * block.dims[1] * block.dims[2]),
                      nx = std::size_t(block.dims[0]), ny = std::size_t(block.dims[1]);
    const auto copy_runs = [&](std::size_t from, std::size_t to) {
      pages.for_each_run(from, to, [&](std::size_t first, std::size_t end) {
        const std::size_t last = std::min(end * page / size, points);
        for (std::size_t at = first * page / size; at < last;) {
          const std::size_t i = at % nx, j = at / nx % ny, k = at / nx / ny,
                            n = std::min(last - at, nx - i);
          std::memcpy(
              dst + at * size,
              src + (std::int64_t(i) + std::int64_t(j) * stride[1] + std::int64_t(k) * stride[2]) *
                        std::int64_t(size),
              n * size);
          at += n;
        }
      });
    };
    if (points <= (std::size_t(8) << 20))
      copy_runs(0, pages.pages());
    else
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, pages.pages()),
          [&](const tbb::blocked_range<std::size_t>& r) { copy_runs(r.begin(), r.end()); });
    return;
  }
  source.for_each_needed_run(
      held, [&](std::int64_t j, std::int64_t k, std::int64_t i0, std::int64_t i1) {
        unsigned char* to = dst + copy_index(block, i0, j, k) * size;
        const unsigned char* from =
            src + (i0 * stride[0] + j * stride[1] + k * stride[2]) * std::int64_t(size);
        for (std::int64_t i = 0; i <= i1 - i0; ++i)
          std::memcpy(to + std::size_t(i) * size, from + i * stride[0] * std::int64_t(size), size);
      });
}

// Of the grid block that `source` is over, the points a source holding the bricks `held` reads
// into the copy begun for them (begin_copy), and its coordinates. Not the colour fields
// (copy_points each).
GridBlock copy_grid(const GridBlock& block, const GridSource& source,
                    const std::vector<std::uint8_t>& held, BlockCopy& copy) {
  GridBlock out = block;
  copy_points(block, source, held, block.values, block.type, copy.values.held(),
              copy.values.data());
  out.values = copy.values.data();
  out.colour = nullptr;
  out.strides = {0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    if (!block.coords[a]) {
      copy.coords[a] = {};
      continue;
    }
    copy.coords[a].assign(block.coords[a], block.coords[a] + block.dims[a]);
    out.coords[a] = copy.coords[a].data();
  }
  return out;
}

// An element block's nodal array of `type` at `values` into `dst`, element after element without
// gaps: the elements `held` marks (all where it is empty).
void copy_nodal(std::size_t elements, std::size_t n, std::size_t element_stride, const void* values,
                ScalarType type, const std::vector<std::uint8_t>& held, unsigned char* dst) {
  const std::size_t size = scalar_bytes(type);
  const std::size_t stride = element_stride == 0 ? n : element_stride;
  const auto* src = static_cast<const unsigned char*>(values);
  if (stride == n && held.empty()) {
    std::memcpy(dst, src, elements * n * size);
    return;
  }
  for (std::size_t e = 0; e < elements; ++e)
    if (held.empty() || held[e]) std::memcpy(dst + e * n * size, src + e * stride * size, n * size);
}
void copy_nodal(const HexBlock& block, const void* values, ScalarType type,
                const std::vector<std::uint8_t>& held, unsigned char* dst) {
  const std::size_t n = std::size_t(block.order + 1) * (block.order + 1) * (block.order + 1);
  copy_nodal(block.element_count, n, block.element_stride, values, type, held, dst);
}
void copy_nodal(const CellBlock& block, const void* values, ScalarType type, unsigned char* dst) {
  copy_nodal(block.element_count, cell_nodes(block.type, block.order), block.element_stride, values,
             type, {}, dst);
}

// A cell block's copy: every cell's values (cell blocks are not culled before the copy), and
// all of each colour field's.
CopyPlan plan_cells(const CellBlock& block, std::span<const FieldArray> colours) {
  CopyPlan plan;
  const std::size_t n = cell_nodes(block.type, block.order);
  plan.values_size = block.element_count * n * scalar_bytes(block.value_type);
  plan.values = PageSet(plan.values_size);
  plan.values.mark(0, plan.values_size);
  plan_whole_colours(block.element_count * n, colours, plan);
  return plan;
}

// Of the cell block, every cell's values into the copy begun for them (begin_copy). Not the
// points: the source over the copy shares the sub-hexahedra prepared when the block was added.
CellBlock copy_cells(const CellBlock& block, BlockCopy& copy) {
  copy.coords = {};
  copy_nodal(block, block.values, block.value_type, copy.values.data());
  CellBlock out = block;
  out.points = nullptr;
  out.values = copy.values.data();
  out.colour = nullptr;
  out.element_stride = 0;
  return out;
}

// Of the high-order block, the nodal values of the elements `held` marks (plan_hex) into the
// copy begun for them (begin_copy). Not the geometry: the source over the copy shares the one
// prepared when the block was added. Not the colour fields (copy_nodal each, whole).
HexBlock copy_hex(const HexBlock& block, const std::vector<std::uint8_t>& held, BlockCopy& copy) {
  copy.coords = {};  // the block k of an earlier step may have been a grid
  copy_nodal(block, block.values, block.type, held, copy.values.data());
  HexBlock out = block;
  out.corners = nullptr;
  out.geometry = nullptr;
  out.values = copy.values.data();
  out.colour = nullptr;
  out.element_stride = 0;
  return out;
}

}  // namespace

std::size_t BlockSnapshot::BlockCopy::bytes() const {
  std::size_t total = values.bytes();
  for (const SparseCopy& c : colours)
    total += c.bytes();
  return total + (coords[0].size() + coords[1].size() + coords[2].size()) * sizeof(double);
}

std::size_t BlockSnapshot::CopyPlan::bytes() const {
  std::size_t total = values.bytes() + coords_bytes;
  for (const PageSet& c : colours)
    total += c.bytes();
  return total;
}

StatusOr<BlockSnapshot::Plan> BlockSnapshot::plan(const std::vector<Block>& blocks,
                                                  std::span<const double> isovalues,
                                                  std::span<const std::uint8_t> field_bits) {
  Plan plan;
  LDIMESH_RETURN_IF_ERROR(guard("snapshot: ", [&] {
    plan.blocks.resize(blocks.size());
    for (std::size_t k = 0; k < blocks.size(); ++k) {
      const Block& b = blocks[k];
      std::vector<FieldArray> colours;
      for (const Colour& c : b.colours)
        colours.push_back(c.array);
      CopyPlan& p = plan.blocks[k];
      p = b.grid ? plan_grid(*b.grid, static_cast<const GridSource&>(*b.source), isovalues, colours,
                             field_bits)
          : b.cells ? plan_cells(*b.cells, colours)
                    : plan_hex(*b.hex, static_cast<const HexElementSource&>(*b.source), isovalues,
                               colours);
      plan.bytes += p.bytes();
    }
    return Status::ok();
  }));
  return plan;
}

Status BlockSnapshot::take(const std::vector<Block>& blocks, Plan plan) {
  std::vector<CopyPlan>& plans = plan.blocks;
  const Status taken = guard("snapshot: ", [&] {
    // Every page the copies will not write is given back before any is written.
    copies_.resize(blocks.size());
    blocks_.clear();
    for (std::size_t k = 0; k < blocks.size(); ++k)
      begin_copy(plans[k], copies_[k]);
    for (std::size_t k = 0; k < blocks.size(); ++k) {
      const Block& b = blocks[k];
      BlockCopy& into = copies_[k];
      Block copy;
      copy.owned = b.owned;
      const std::vector<std::uint8_t>& held = plans[k].held;
      if (b.grid) {  // the bricks the step's isovalues need, with the points around them
        const auto& live = static_cast<const GridSource&>(*b.source);
        copy.grid = copy_grid(*b.grid, live, held, into);
        copy.source = std::make_shared<GridSource>(*copy.grid, live.brick_cells(), held);
      } else if (b.cells) {  // every cell's values; the sub-hexahedra prepared once
        copy.cells = copy_cells(*b.cells, into);
        copy.source = std::make_shared<CellElementSource>(
            static_cast<const CellElementSource&>(*b.source), *copy.cells);
      } else {  // the geometry as the block's source prepared it (converted and checked once)
        copy.hex = copy_hex(*b.hex, held, into);
        copy.source = std::make_shared<HexElementSource>(
            static_cast<const HexElementSource&>(*b.source), *copy.hex, held);
      }
      // Each colour field (a grid block's points the casts of the isovalues it colours read,
      // an element block's whole field), and a source over it and the copy's values.
      copy.colours.resize(b.colours.size());
      for (std::size_t f = 0; f < b.colours.size(); ++f) {
        const FieldArray live = b.colours[f].array;
        if (!live.values) continue;
        SparseCopy& colour = into.colours[f];
        const std::vector<std::uint8_t>& field_held =
            plans[k].colour_held[f].empty() ? held : plans[k].colour_held[f];
        if (b.grid)
          copy_points(*b.grid, static_cast<const GridSource&>(*b.source), field_held, live.values,
                      live.type, colour.held(), colour.data());
        else if (b.cells)
          copy_nodal(*b.cells, live.values, live.type, colour.data());
        else
          copy_nodal(*b.hex, live.values, live.type, {}, colour.data());
        const FieldArray copied{colour.data(), live.type};
        copy.colours[f] = {copied, coloured_source(copy, copied, field_held)};
      }
      blocks_.push_back(std::move(copy));
    }
    return Status::ok();
  });
  if (!taken) clear();
  return taken;
}

void BlockSnapshot::clear() {
  copies_.clear();
  blocks_.clear();
}

std::size_t BlockSnapshot::bytes() const {
  std::size_t total = 0;
  for (const BlockCopy& c : copies_)
    total += c.bytes();
  return total;
}

}  // namespace ldimesh
