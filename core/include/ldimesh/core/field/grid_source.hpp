// Structured-grid blocks as ray-caster sources (finite volume / finite difference codes): point
// data on a uniform or rectilinear grid, read in place from the solver's array, intersected
// exactly with the trilinear interpolant of each cell.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {

class GridSource final : public FieldSource {
 public:
  // Validates the block (at least 2 points and one owned cell per axis, non-null values,
  // non-zero strides, non-negative ghost layers, positive spacing or increasing coordinates) and
  // brick_cells ≥ 1; throws std::invalid_argument naming the problem. Bricks of brick_cells³
  // owned cells are the ray-caster primitives. The arrays are read in place: they must outlive
  // the source (threads: see field_source.hpp).
  explicit GridSource(const GridBlock& block, int brick_cells = 8);
  // A source over a block of which only some bricks' points are there (a snapshot that copied
  // what a cast reads, for_each_needed_run): `held` has a flag per brick (x fastest,
  // brick_count() of them) and must mark at least the bricks needed_bricks() names for every
  // isovalue bound; the points of the others may hold anything, they are not read. It casts
  // what a source over the whole block casts. Also throws std::invalid_argument for a mask of
  // the wrong size.
  GridSource(const GridBlock& block, int brick_cells, std::vector<std::uint8_t> held);

  // The owned region: the cells this block produces hits in.
  Box bounds() const override;
  // Computes every brick's value range from the current values (so a new time step in the same
  // arrays needs only a new bind) and puts the bricks whose range holds `isovalue` into an
  // Embree user geometry. Runs on all cores.
  //
  // Non-finite values (NaN, ±Inf): a cell with such a corner produces no hits; every other cell
  // produces the same hits as if the field had none. The binding's nonfinite_values() is the
  // number of points read whose value is non-finite, each point counted once: the corner
  // points of the owned cells, i.e. indices first_cell()[a] … last_cell()[a] + 1 per axis,
  // ghost points among them included (ghost points outside that range are not read).
  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override;
  // The same bricks, culled the same way, for rays parallel to an axis: each ray walks the cells
  // of its column of active bricks, where the interpolant is linear (the same roots as bind()).
  std::unique_ptr<AxisCaster> bind_axis(double isovalue) const override;
  // The block's colour field (GridBlock::colour), its trilinear interpolant read in place at
  // each hit; null without one.
  std::unique_ptr<ScalarProbe> bind_scalar() const override;

  // Bricks before culling, and their size in cells per axis.
  std::size_t brick_count() const;
  int brick_cells() const { return brick_cells_; }
  // Per brick (x fastest): whether the range of its points holds one of `isovalues` or one of
  // them is NaN or ±Inf: a superset of the bricks that bind() and
  // bind_axis() for these isovalues read, with the points around them that the hits' normals
  // read. Reads the values in place, on the calling thread up to 8 Mi points, else on all cores.
  std::vector<std::uint8_t> needed_bricks(std::span<const double> isovalues) const;
  // The same pass, per isovalue: bit i of a brick's byte is set where it is needed for
  // isovalue i alone (bit 7 for the eighth isovalue and every one after it), every isovalue's
  // bit where one of its points is NaN or ±Inf; needed_bricks is where the byte is not 0. (The
  // adaptor's snapshot copies a colour field only where the isovalues it colours need it.)
  std::vector<std::uint8_t> needed_bricks_by_isovalue(std::span<const double> isovalues) const;
  // Calls f(j, k, i0, i1) for each stretch of points i0 … i1 of point row (j, k) (indices of the
  // block's points, ghosts included) that a source holding the bricks `held` marks reads: for a
  // brick of cells lo … hi along an axis, points lo − 1 … hi + 2 where the block has them (its
  // cells' points and one layer more on each side: the normals' central differences, and the
  // colour probe in the cells beside its faces). The stretches do not overlap; f may run
  // concurrently for different k (rows of one k in order, on one thread; all on the calling
  // thread for a block of up to 8 Mi points). Throws
  // std::invalid_argument for a mask of the wrong size.
  void for_each_needed_run(
      std::span<const std::uint8_t> held,
      const std::function<void(std::int64_t, std::int64_t, std::int64_t, std::int64_t)>& f) const;
  // The value at point (i, j, k) (ghosts included), as a double. The indices must lie within the
  // block's points (0 … dims[a] − 1; not checked); with a held mask, within what it holds.
  double value(std::int64_t i, std::int64_t j, std::int64_t k) const;
  // The trilinear interpolant of the values at world point `p`, in the cell that holds it (ghost
  // cells included); NaN where p lies more than `slack` (a fraction of a cell) outside the
  // block's points, or where the interpolant there is not finite; with a held mask, also in a
  // cell whose points the mask's copy does not hold (for_each_needed_run).
  double interpolate(glm::dvec3 p, double slack = 0.0) const;
  // The coordinate of point index i along axis a (0 ≤ i < dims[a], 0 ≤ a < 3; not checked).
  double coordinate(int axis, std::int64_t i) const;
  // Owned cells along each axis: lower corner indices first_cell[a] … last_cell[a].
  std::array<std::int64_t, 3> first_cell() const { return first_cell_; }
  std::array<std::int64_t, 3> last_cell() const { return last_cell_; }

 private:
  GridBlock block_;
  int brick_cells_;
  std::array<std::int64_t, 3> first_cell_{}, last_cell_{}, bricks_{};
  std::shared_ptr<const std::vector<std::uint8_t>> held_;  // null: every brick's points
  // Whether some held brick's copy holds the points of `cell` (lower corner indices).
  bool cell_held(const std::array<std::int64_t, 3>& cell) const;
};

// Part `index` of `whole` split into blocks[0] × blocks[1] × blocks[2] blocks of cells (as
// evenly as possible): a block of the same arrays (nothing copied) with its owned points plus
// the ghost layer of point values above it that its last cells need, one more point layer on
// each side where `whole` has one (the normals' central differences read them), and the box
// its cells cover, computed from `whole`'s coordinates so that neighbouring parts share faces
// exactly (use it as the part's Subdomain box). The parts' owned cells tile `whole`'s. Throws
// std::invalid_argument if a part would have no cell.
struct GridPart {
  GridBlock block;
  Box owned;
};
GridPart grid_part(const GridBlock& whole, std::array<int, 3> blocks, std::array<int, 3> index);

// The roots of the trilinear interpolant minus `iso` along a segment of one cell, by the cubic
// it restricts to (Marmitt et al. 2004: split at the cubic's extrema, then one bracketed root
// per monotone piece); a segment along one axis is a line, solved from its end values. `corner`
// holds the 8 values minus iso, index = x + 2y + 4z; `a` and `b` are the segment's ends in the
// cell's local coordinates [0, 1]³. Writes the roots as segment parameters s ∈ [0, 1] in increasing
// order to `roots` and returns how many (at most 3).
int trilinear_segment_roots(const double corner[8], glm::dvec3 a, glm::dvec3 b, double roots[3]);

}  // namespace ldimesh
