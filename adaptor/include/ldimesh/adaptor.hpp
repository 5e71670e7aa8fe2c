// The in situ adaptor a solver links (C++ API; ldimesh.h is the C API over it).
//
// Like Ascent (open / publish / execute / close) and Catalyst 2 (initialize / execute /
// finalize): create the adaptor with a communicator and options, describe the data each rank
// holds once (pointers into the solver's own arrays, read in place; the values may be updated
// between steps, the geometry not: clear_blocks() and add again to move a mesh), call
// execute(step, time) every step, and finalize (or destroy) at the end.
//
// On a due step (options "cadence") every rank ray casts the isosurfaces of its own blocks and
// hands its LDI fragments to the root; the root's decode, meshing, Draco encoding and
// publishing run on a worker thread while the solver continues. If the root is still busy with
// an earlier step the new one is skipped or replaces the waiting one ("busy": "skip" |
// "coalesce").
//
// What the solver waits for depends on MPI's thread level. With MPI_THREAD_MULTIPLE (and
// option "background", the default) execute() copies what the step reads of the grid and
// high-order blocks' arrays (a snapshot: of a grid block the bricks that hold the surface; the
// solver may overwrite its arrays as soon as execute() returns) and returns:
// the ray casting and the reduction run on a caster thread of every rank, over a duplicate of
// the communicator. With less (MPI_THREAD_FUNNELED at least), or when a block is a FieldSource
// (nothing to copy) or a rank's copy would exceed "memory_mb", the step runs synchronously: the
// solver waits for the ray casting and the reduction, and MPI is called from the thread that
// calls execute() only.
//
// Never harms the solver: no exception leaves the adaptor's functions, it never calls
// MPI_Abort or exit; an error is returned as a Status (also kept as last_error()) and the step
// is skipped. A step that fails in the background is reported by last_error(), the root's log
// and finalize().
//
// Threads: one thread (the solver's) calls an Adaptor's methods; the adaptor's own threads are
// described above and in docs/adaptor.md.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include <mpi.h>

#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/field/blocks.hpp"

namespace ldimesh {

class FieldSource;  // ldimesh/core/field/field_source.hpp (needs Embree's headers)

// What one step did, for logs and the snapshot metadata.
struct StepReport {
  std::uint64_t step = 0;
  bool executed = false;             // false: not due, or skipped because the root was busy
  bool skipped_busy = false;         // the root's worker was busy ("skip")
  bool replaced_pending = false;     // a waiting step was replaced by this one ("coalesce")
  double blocked_seconds = 0.0;      // this rank's time inside execute()
  double max_blocked_seconds = 0.0;  // the slowest rank's (root only)
  // NaN/±Inf values met in the fields of all ranks' blocks (root only). The cells and elements
  // they touch are left out of the surface; the step is still published.
  // (Synchronous path; in the background path the count comes with the published step.)
  std::uint64_t nonfinite_values = 0;
  bool background = false;  // the step was snapshotted and runs on the caster thread
  // What this rank's copy of its blocks holds (background path; a grid block's in whole pages).
  std::size_t snapshot_bytes = 0;
};

class Adaptor {
 public:
  // Collective over `comm`. `options_json` is a JSON document (docs/adaptor.md lists every
  // key); "" means all defaults. An unknown key or a bad value is an error naming the key, on
  // every rank. On the root the HTTP server starts here (unless disabled) and url() tells where.
  static Status create(MPI_Comm comm, std::string_view options_json, std::unique_ptr<Adaptor>& out);
  // The same with the options read from a file, or, when `path` is empty, from the file named
  // by the environment variable LDIMESH_OPTIONS (defaults when unset).
  static Status create_from_file(MPI_Comm comm, const std::string& path,
                                 std::unique_ptr<Adaptor>& out);

  virtual ~Adaptor() = default;

  // The global domain the views cover (the same on every rank). Required before execute().
  virtual Status set_domain(const Box& global) = 0;
  // This rank's data: blocks of point data, blocks of high-order elements, or any source (an
  // analytic field). Each call adds one block; `owned` is the part of the domain this block's
  // hits belong to (for grid blocks: the owned region, GridSource::bounds(); element blocks own
  // their cells, however the solver partitions them: a root on a face shared with another
  // block or rank is kept once, docs/method.md "Element blocks own their cells"). The values are
  // read in place at every due step and may change between steps; the geometry (a grid's
  // coordinates, an element block's corners or geometry nodes) is prepared when the block is
  // added and must not change while it is added — to move a mesh, clear_blocks() and add it
  // again.
  virtual Status add_grid_block(const GridBlock& block) = 0;
  virtual Status add_hex_block(const HexBlock& block) = 0;
  // A block of cells of one type and order — tetrahedra, wedges, pyramids, serendipity or
  // Lagrange hexahedra (CellBlock, core/field/cell_source.hpp), in VTK's node order; a mixed mesh
  // is one block per (type, order). A cell block's fields (add_field) have its values' layout.
  virtual Status add_cell_block(const CellBlock& block) = 0;
  virtual Status add_source(std::shared_ptr<const FieldSource> source, const Box& owned) = 0;
  // A further named field of the block added last (temperature beside density), read in place
  // like its values and in their layout: a grid block's points with the same dims and strides,
  // an element block's nodal values with the same nodes, order and element_stride; `type` may
  // differ from the block's. With option "colour_by": NAME every isosurface is coloured by the
  // field of that name ("colour_by": [NAME or null per isovalue]: each isosurface by its own
  // field, or by none), which every grid and element block must then have, and every
  // FieldSource must have a colour field of its own (bind_scalar; it has one, so two names
  // fail): a step without fails, naming the block. A GridBlock's or HexBlock's own `colour` member
  // is not read: fields come by name. Adding a name again replaces that field. Errors: no block
  // added yet, the last add_*_block refused (the field would belong to the block before), a
  // FieldSource block, an empty name, null values.
  virtual Status add_field(std::string_view name, const void* values, ScalarType type) = 0;
  // Forgets the blocks (to describe them anew, e.g. after a re-partition).
  virtual void clear_blocks() = 0;

  // Collective. Runs the in situ step if it is due. Never throws.
  virtual Status execute(std::uint64_t step, double time) = 0;
  // Collective. Waits for the root's pending work (published or failed) and stops the server.
  // Returns the last failure of that background work, if any. Called by the destructor if not
  // before.
  virtual Status finalize() = 0;

  // Root: the viewer's URL with the token ("" elsewhere or without a server).
  virtual std::string url() const = 0;
  // The report of this rank's last execute().
  virtual const StepReport& last_report() const = 0;
  // The last failure's message on this rank ("" if none), a copy: the caster and worker threads
  // may replace it at any time.
  virtual std::string last_error() const = 0;
  // Root: the number of steps published so far.
  virtual std::uint64_t published_steps() const = 0;
};

}  // namespace ldimesh
