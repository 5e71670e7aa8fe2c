#include "ldimesh/adaptor.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <new>
#include <optional>
#include <span>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <type_traits>
#include <vector>

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/mpi_reduce.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "ldimesh/transport/step_package.hpp"
#include "options.hpp"

namespace ldimesh {
namespace {

using Clock = std::chrono::steady_clock;

// One due step's work for the root's worker.
struct Job {
  std::uint64_t step = 0;
  double time = 0.0;
  std::vector<View> views;
  CastStep cast;  // the collective half's fragments (isovalue-major) and the others' pending merge
  // Meshed already, one per isovalue (refinement, or merging that projects: on the thread that made
  // the step's MPI calls, while every rank served samples); otherwise the worker meshes.
  std::optional<std::vector<MeshingResult>> meshed;
  std::map<std::string, double> seconds;
  std::uint64_t skipped_steps = 0;  // due steps dropped since the previous job was handed over
  std::uint64_t nonfinite_values = 0;
  bool merge = false;  // §5 merging (the same on every rank: the ranks serve its samples)
};

// Puts the calling thread in Linux's SCHED_BATCH class while it waits for work (`waiting`), back
// in the normal class while it works. The caster's and the root's worker threads wait so: waking
// a batch thread does not take the core from the thread that wakes it. The solver's thread,
// handing a step to its caster thread at the end of execute(), otherwise lost its core to it for
// up to 4.6 ms there (Gray–Scott, 2 ranks on 2 cores; median blocked time 12.9 → 9.0 ms per
// step). Working in the normal class, neither leaves the batch class to threads they start
// (TBB's workers, which the solver's own TBB work may share). Nothing where the system refuses
// it.
void wait_as_batch_thread([[maybe_unused]] bool waiting) {
#ifdef SCHED_BATCH
  sched_param param{};
  param.sched_priority = 0;
  pthread_setschedparam(pthread_self(), waiting ? SCHED_BATCH : SCHED_OTHER, &param);
#endif
}

std::size_t scalar_bytes(ScalarType type) {
  return type == ScalarType::float32 ? sizeof(float) : sizeof(double);
}

// The pages of an array of `bytes` bytes that some of its stretches touch.
class PageSet {
 public:
  static std::size_t page() {
    static const std::size_t size = std::size_t(sysconf(_SC_PAGESIZE));
    return size;
  }
  explicit PageSet(std::size_t bytes = 0) : bytes_(bytes), marked_((bytes + page() - 1) / page()) {}
  // Bytes offset … offset + length − 1 are touched (any thread).
  void mark(std::size_t offset, std::size_t length) {
    if (length == 0) return;
    for (std::size_t p = offset / page(); p <= (offset + length - 1) / page(); ++p)
      std::atomic_ref<std::uint8_t>(marked_[p]).store(1, std::memory_order_relaxed);
  }
  bool marked(std::size_t p) const { return marked_[p] != 0; }
  std::size_t pages() const { return marked_.size(); }
  // f(first, end) for each run of touched pages first … end − 1 among pages from … to − 1.
  template <class F>
  void for_each_run(std::size_t from, std::size_t to, F&& f) const {
    for (std::size_t p = from; p < to;) {
      if (!marked_[p]) {
        ++p;
        continue;
      }
      const std::size_t first = p;
      while (p < to && marked_[p])
        ++p;
      f(first, p);
    }
  }
  // The bytes of the touched pages (the last one as far as the array goes).
  std::size_t bytes() const {
    std::size_t total = 0;
    for (std::size_t p = 0; p < marked_.size(); ++p)
      total += marked_[p] ? std::min(page(), bytes_ - p * page()) : 0;
    return total;
  }

 private:
  std::size_t bytes_;
  std::vector<std::uint8_t> marked_;
};

// One array of a block as copied at a due step (background path), of which a step may copy
// only some stretches (a grid block's needed bricks, an element block's needed elements):
// anonymous memory, kept from step to step so that later copies reuse its pages. Before a step
// writes, the pages it will not write are given back to the system, so the memory the array
// holds, during the copy as after it, is the pages the step copies into, not the whole array.
class SparseCopy {
 public:
  SparseCopy() = default;
  SparseCopy(SparseCopy&& other) noexcept { *this = std::move(other); }
  SparseCopy& operator=(SparseCopy&& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(size_, other.size_);
    std::swap(held_, other.held_);
    return *this;
  }
  ~SparseCopy() { unmap(); }

  // Prepares the array of `bytes` bytes for a step that writes into the pages `planned` (of an
  // array of `bytes`): gives back the other pages it holds (a new mapping where the size
  // changed). Throws std::bad_alloc where the system refuses the memory.
  unsigned char* begin(std::size_t bytes, PageSet planned) {
    if (bytes != size_) {
      unmap();
      if (bytes > 0) {
        void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (p == MAP_FAILED) throw std::bad_alloc();
        // Small pages: a huge page would make one written stretch hold 2 MiB.
        advise_small_pages(p, bytes);
        data_ = static_cast<unsigned char*>(p);
      }
      size_ = bytes;
    } else {
      const std::size_t page = PageSet::page();
      for (std::size_t p = 0; p < held_.pages();) {
        if (!held_.marked(p) || planned.marked(p)) {
          ++p;
          continue;
        }
        const std::size_t first = p;
        while (p < held_.pages() && !planned.marked(p))
          ++p;
        madvise(data_ + first * page, std::min(p * page, size_) - first * page, MADV_DONTNEED);
      }
    }
    held_ = std::move(planned);
    return data_;
  }
  // What it holds: the pages of the last step's copy.
  std::size_t bytes() const { return held_.bytes(); }
  const PageSet& held() const { return held_; }
  // No copy: gives the memory back.
  void clear() { unmap(); }
  unsigned char* data() { return data_; }

 private:
  static void advise_small_pages([[maybe_unused]] void* p, [[maybe_unused]] std::size_t bytes) {
#ifdef MADV_NOHUGEPAGE
    madvise(p, bytes, MADV_NOHUGEPAGE);
#endif
  }
  void unmap() {
    if (data_) munmap(data_, size_);
    data_ = nullptr;
    size_ = 0;
    held_ = PageSet();
  }
  unsigned char* data_ = nullptr;
  std::size_t size_ = 0;
  PageSet held_;
};

// A colour field of a block as add_field gave it (values null: the block lacks it).
struct FieldArray {
  const void* values = nullptr;
  ScalarType type = ScalarType::float32;
};

// A block's arrays as copied at a due step (background path).
struct BlockCopy {
  SparseCopy values;
  std::vector<SparseCopy> colours;  // per colour field (option "colour_by"), where the block has it
  std::array<std::vector<double>, 3> coords;
  std::size_t bytes() const {
    std::size_t total = values.bytes();
    for (const SparseCopy& c : colours)
      total += c.bytes();
    return total + (coords[0].size() + coords[1].size() + coords[2].size()) * sizeof(double);
  }
};

// What a due step copies of one block: the bricks or elements a cast reads (`held`), and the
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
  std::size_t bytes() const {
    std::size_t total = values.bytes() + coords_bytes;
    for (const PageSet& c : colours)
      total += c.bytes();
    return total;
  }
};

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
// took twice as long on Gray–Scott: 4.3 against 2.2 ms per rank and step, medians
// (docs/benchmarks.md). Where the surface is sparse a page holds few needed points, but the
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

class AdaptorImpl final : public Adaptor {
 public:
  AdaptorImpl(MPI_Comm comm, AdaptorOptions options) : comm_(comm), options_(std::move(options)) {
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
    // Each colour field's isovalues, as GridSource::needed_bricks_by_isovalue marks them.
    field_bits_.assign(options_.colour_fields.size(), 0);
    for (std::size_t i = 0; i < options_.surface_field.size(); ++i)
      if (options_.surface_field[i] >= 0)
        field_bits_[std::size_t(options_.surface_field[i])] |=
            std::uint8_t(1u << std::min<std::size_t>(i, 7));
  }
  ~AdaptorImpl() override { finalize(); }

  // Root: store, server and worker.
  Status start_root() {
    if (rank_ != 0) return Status::ok();
    int level = MPI_THREAD_SINGLE;
    MPI_Query_thread(&level);
    if (level < MPI_THREAD_FUNNELED && options_.log)
      std::fprintf(stderr,
                   "ldimesh: warning: MPI runs with MPI_THREAD_SINGLE; the root's worker thread "
                   "never calls MPI, but the standard asks for MPI_THREAD_FUNNELED "
                   "(MPI_Init_thread)\n");
    store_ = std::make_unique<SnapshotStore>(
        SnapshotStoreLimits{options_.keep, options_.memory_mb << 20});
    if (options_.server) {
      HttpServerOptions o;
      o.bind_address = options_.bind;
      o.allow_remote = options_.allow_remote;
      o.port = options_.port;
      o.token = options_.token;
      // The viewer's files: the checkout the library was built in, or where it is installed.
      const ViewerFiles files = find_viewer_files();
      o.static_dir = files.static_dir;
      o.vendor_three_dir = files.vendor_three_dir;
      server_ = std::make_unique<HttpServer>(*store_, o);
      if (Status s = server_->start(); !s) return s;
      if (!is_loopback_address(o.bind_address) && options_.log)
        std::fprintf(stderr, "ldimesh: %s", remote_server_warning(o.bind_address).c_str());
    }
    if (!options_.output_dir.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(options_.output_dir, ec);
      if (ec) return Status::io("options: 'output_dir' cannot be created: " + ec.message());
    }
    worker_ = std::thread([this] { work(); });
    return Status::ok();
  }

  // Collective, every rank: the background path where MPI allows it (every rank agrees).
  void start_background() {
    int level = MPI_THREAD_SINGLE;
    MPI_Query_thread(&level);
    int ok = options_.background && level >= MPI_THREAD_MULTIPLE ? 1 : 0;
    MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, comm_);
    if (!ok) {
      if (!options_.background && rank_ == 0 && options_.log &&
          options_.merging == AdaptorOptions::Merging::automatic)
        std::fprintf(stderr,
                     "ldimesh: \"background\": false: in situ steps run synchronously; the views "
                     "are published trimmed, not merged (\"merging\": \"auto\"; true merges "
                     "anyway, the solver then waits for the merge too)\n");
      if (options_.background && rank_ == 0 && options_.log)
        std::fprintf(stderr,
                     "ldimesh: MPI runs without MPI_THREAD_MULTIPLE (MPI_Init_thread gave level "
                     "%d): in situ steps run synchronously, the solver waits for the ray cast and "
                     "the reduction%s\n",
                     level,
                     options_.merging == AdaptorOptions::Merging::automatic
                         ? "; the views are published trimmed, not merged (\"merging\": \"auto\"; "
                           "true merges anyway, the solver then waits for the merge too)"
                         : "");
      return;
    }
    MPI_Comm_dup(comm_, &background_comm_);
    background_ = true;
    caster_ = std::thread([this] { cast_in_background(); });
  }

  Status set_domain(const Box& global) override {
    if (!global.is_valid()) return fail(Status::invalid_argument("set_domain: the box is empty"));
    domain_ = global;
    has_domain_ = true;
    return Status::ok();
  }
  Status add_grid_block(const GridBlock& block) override {
    return add_block<GridSource>(block, "add_grid_block");
  }
  Status add_hex_block(const HexBlock& block) override {
    return add_block<HexElementSource>(block, "add_hex_block");
  }
  Status add_cell_block(const CellBlock& block) override {
    return add_block<CellElementSource>(block, "add_cell_block");
  }
  Status add_source(std::shared_ptr<const FieldSource> source, const Box& owned) override {
    last_add_failed_ = !source;
    if (!source) return fail(Status::invalid_argument("add_source: no source"));
    blocks_.push_back({std::move(source), owned, std::nullopt, std::nullopt, std::nullopt, {}});
    return Status::ok();
  }
  Status add_field(std::string_view name, const void* values, ScalarType type) override {
    return fail_if(guard("add_field: ", [&] {
      if (last_add_failed_)
        return Status::invalid_argument(
            "the block added last was refused (the field would belong to the one before)");
      if (blocks_.empty() || (!blocks_.back().grid && !blocks_.back().hex && !blocks_.back().cells))
        return Status::invalid_argument(
            blocks_.empty() ? "no block added yet (the field belongs to the block added last)"
                            : "the block added last is a FieldSource (it colours by its own "
                              "bind_scalar)");
      if (name.empty()) return Status::invalid_argument("the field's name is empty");
      if (!values)
        return Status::invalid_argument("field '" + std::string(name) + "': null values");
      if (type != ScalarType::float32 && type != ScalarType::float64)
        return Status::invalid_argument("field '" + std::string(name) + "': unknown scalar type");
      // Only the fields "colour_by" names are read; the others are accepted and left alone.
      const auto& fields = options_.colour_fields;
      const std::size_t f =
          std::size_t(std::find(fields.begin(), fields.end(), name) - fields.begin());
      if (f == fields.size()) return Status::ok();
      Block& b = blocks_.back();
      // The colour field: a source that reads it beside the block's values (an element block's
      // geometry as prepared).
      b.colours[f] = {{values, type}, coloured_source(b, {values, type})};
      return Status::ok();
    }));
  }
  void clear_blocks() override {
    blocks_.clear();
    last_add_failed_ = false;
  }

  Status execute(std::uint64_t step, double time) override {
    const auto start = Clock::now();
    report_ = {};
    report_.step = step;
    // The root decides whether the step runs (cadence, busy worker); everyone follows. Each rank
    // says whether it can take a snapshot (background path): all must, or the step runs
    // synchronously everywhere. One collective for both.
    const bool can_snapshot = background_ && snapshot_copyable();
    // The root's decision, whether a rank cannot snapshot, whether "auto" merging has stopped.
    int flags[3] = {0, background_ && !can_snapshot ? 1 : 0, 0};
    if (rank_ == 0) {
      const bool due =
          step % options_.every_steps == 0 && (options_.every_seconds <= 0.0 || !ran_before_ ||
                                               seconds_since(last_run_) >= options_.every_seconds);
      if (due) {
        std::lock_guard lock(mutex_);
        const bool busy = working_ || pending_.has_value();
        // A step still being cast or reduced in the background holds the snapshot buffers: the
        // new one is skipped, or with "coalesce" it waits for them (hand_to_background), so
        // that the newest due step is always published.
        flags[0] = (casting_ || busy) && !options_.coalesce ? 2 : 1;  // 0 not due, 1 run, 2 busy
        // The solver's time between due steps, run or skipped.
        const double interval = due_before_ ? seconds_since(last_due_) : 0.0;
        last_due_ = Clock::now();
        due_before_ = true;
        if (flags[0] == 1) flags[2] = auto_merge_stopped(step, interval) ? 1 : 0;
      }
    }
    MPI_Allreduce(MPI_IN_PLACE, flags, 3, MPI_INT, MPI_MAX, comm_);
    const int decision = flags[0];
    if (decision != 1) {
      report_.skipped_busy = decision == 2;
      if (decision == 2 && rank_ == 0) ++skipped_since_handoff_;
      if (decision == 2 && rank_ == 0 && options_.log)
        std::printf("ldimesh: step %llu skipped: still processing an earlier step\n",
                    (unsigned long long)step);
      finish_report(start);
      return Status::ok();
    }
    if (rank_ == 0) {
      last_run_ = Clock::now();
      ran_before_ = true;
    }
    Job job;
    job.step = step;
    job.time = time;
    if (rank_ == 0) {
      job.skipped_steps = skipped_since_handoff_;
      skipped_since_handoff_ = 0;
    }
    // "auto" merges the background steps within its budget (auto_merge_stopped); "true" every
    // step.
    job.merge = options_.merging == AdaptorOptions::Merging::on ||
                (options_.merging == AdaptorOptions::Merging::automatic && background_ &&
                 flags[1] == 0 && flags[2] == 0);
    std::string why = "a rank's blocks cannot be copied (a FieldSource)";
    SyncReason reason = SyncReason::field_source;
    if (background_ && flags[1] == 0) {
      long long largest = 0;
      if (hand_to_background(job, start, largest)) {
        log_path(step, SyncReason::none, "");
        return Status::ok();
      }
      char text[160];
      std::snprintf(text, sizeof text,
                    "a rank's copy of what it reads (%.1f MiB) would exceed memory_mb (%zu)",
                    double(largest) / (1 << 20), options_.memory_mb);
      why = text;
      reason = SyncReason::memory;
      job.merge = options_.merging == AdaptorOptions::Merging::on;
    }
    if (background_) log_path(step, reason, why);

    // The synchronous path: the solver waits for the cast and the reduction (and for the
    // meshing, where it needs every rank's samples).
    StepCasters casters;
    Status s = collective_step(comm_, blocks_, domain(), Status::ok(), job, casters);
    if (s && meshing_samples(meshing_options(job.merge)))
      s = mesh_with_samples(comm_, casters, job);
    if (rank_ == 0) report_.nonfinite_values = job.cast.nonfinite_values;
    finish_report(start);
    if (!s) return fail(s.prefixed("step " + std::to_string(step) + " skipped: "));
    if (rank_ == 0) {
      job.seconds["blocked"] = report_.max_blocked_seconds;
      report_.replaced_pending = hand_to_worker(std::move(job));
    }
    return Status::ok();
  }

  Status finalize() override {
    if (finalized_) return Status::ok();
    finalized_ = true;
    if (caster_.joinable()) {
      {
        std::unique_lock lock(mutex_);
        caster_idle_.wait(lock, [&] { return !caster_job_ && !casting_; });
        caster_stopping_ = true;
        caster_wake_.notify_all();
      }
      caster_.join();
      MPI_Comm_free(&background_comm_);
    }
    if (rank_ == 0 && worker_.joinable()) {
      {
        std::unique_lock lock(mutex_);
        idle_.wait(lock, [&] { return !pending_ && !working_; });
        stopping_ = true;
        wake_.notify_all();
      }
      worker_.join();
      if (server_) server_->stop();
    }
    std::lock_guard lock(mutex_);
    return worker_status_;
  }

  std::string url() const override { return server_ ? server_->url() : std::string(); }
  const StepReport& last_report() const override { return report_; }
  std::string last_error() const override {
    std::lock_guard lock(mutex_);
    return last_error_;
  }
  std::uint64_t published_steps() const override {
    std::lock_guard lock(mutex_);
    return published_;
  }

 private:
  // A colour field of a block and the source that reads it beside the block's values.
  struct Colour {
    FieldArray array;
    std::shared_ptr<const FieldSource> source;  // null: the block lacks the field
  };
  // An element block's subdomain: its cells' bounds grown by 10⁻⁹ of the domain's diagonal, so
  // that the half-open box holds every hit of its cells (those on the bounds' upper faces, and
  // on rays lying in them, included), clipped to the domain. Only rays that can meet its cells
  // are cast.
  static Box element_box(const Box& bounds, const Box& domain) {
    const double grow = 1e-9 * domain.diagonal();
    return {glm::max(bounds.lo - grow, domain.lo), glm::min(bounds.hi + grow, domain.hi)};
  }

  struct Block {
    std::shared_ptr<const FieldSource> source;  // no colour (a FieldSource: its own bind_scalar)
    // Where the block's hits belong. None for element blocks: a solver's partition of its cells
    // is no box, and their bounding boxes overlap, so each block keeps every hit of its cells
    // (element_box) and a hit that cells of two blocks or ranks both find on their shared face
    // is merged by the duplicate rule (collapse_duplicate_hits), as one caster merges its own.
    std::optional<Box> owned;
    // What the block reads, for the background path's copy (neither: a FieldSource, which
    // cannot be copied); their colour pointers are null.
    std::optional<GridBlock> grid;
    std::optional<HexBlock> hex;
    std::optional<CellBlock> cells;
    std::vector<Colour> colours;  // grid and element blocks: per AdaptorOptions::colour_fields
  };

  // A source over the grid or element block `b` that reads `colour` as its colour field; over the
  // block's copy holding only the bricks or elements `held` where given.
  static std::shared_ptr<const FieldSource> coloured_source(
      const Block& b, FieldArray colour, std::optional<std::vector<std::uint8_t>> held = {}) {
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
      return std::make_shared<CellElementSource>(static_cast<const CellElementSource&>(*b.source),
                                                 c);
    }
    HexBlock h = *b.hex;
    h.colour = colour.values;
    h.colour_type = colour.type;
    const auto& prepared = static_cast<const HexElementSource&>(*b.source);
    return held ? std::make_shared<HexElementSource>(prepared, h, std::move(*held))
                : std::make_shared<HexElementSource>(prepared, h);
  }
  // A snapshotted step for this rank's caster thread.
  struct CasterJob {
    Job job;
    std::optional<Box> domain;
    Status status = Status::ok();  // the snapshot failed: the step fails on every rank
    double blocked_seconds = 0.0;
  };

  // This rank's casters of one step (one per block and isovalue) and the step's views: alive
  // until the root has meshed, for it may ask every rank for samples.
  struct StepCasters {
    std::vector<std::unique_ptr<RayCaster>> owned;
    StepBlocks blocks;
    std::vector<View> views;
    double tolerance = 0.0;
  };

  // The meshing of a step, merged (§5) or not.
  MeshingOptions meshing_options(bool merge) const {
    MeshingOptions meshing;
    meshing.r = options_.r;
    meshing.refinement.levels = options_.refinement_levels;
    meshing.merging.enabled = merge;
    return meshing;
  }

  // Whether the options inject `kind` into this rank's step `step` (testing only).
  bool fault_here(const char* kind, std::uint64_t step) const {
    return options_.fault == kind && options_.fault_step == step && options_.fault_rank == rank_;
  }

  // The collective half of a due step over `comm` (cast_and_reduce): every rank binds and casts
  // `blocks` and takes part in the reduction to the root, whose `job` gets the views, the
  // fragments, the others' pending merge and the timings (all but "blocked"). A local failure
  // (`local`, or one while binding) fails the step everywhere. The solver's thread runs it on
  // the adaptor's communicator (synchronous path), the caster thread on its duplicate
  // (background path).
  Status collective_step(MPI_Comm comm, const std::vector<Block>& blocks, std::optional<Box> domain,
                         Status local, Job& job, StepCasters& casters) const {
    casters = {};
    casters.blocks.resize(options_.isovalues.size());
    const auto bind_start = Clock::now();
    if (local && !domain) local = Status::invalid_argument("set_domain() was not called");
    if (local)
      local = guard("binding the blocks: ", [&] {
        if (fault_here("out_of_memory", job.step)) throw std::bad_alloc();
        if (fault_here("exception", job.step))
          throw std::logic_error("testing.fault: an injected exception");
        casters.views = make_axis_views(*domain, options_.resolution, options_.views);
        for (const View& v : casters.views)
          casters.tolerance = std::max(
              casters.tolerance, reduction_tolerance(options_.encoding, v, domain->diagonal()));
        // The hits of an isovalue carry a colour where "colour_by" names a field for it, and
        // then every block's.
        for (std::size_t i = 0; i < options_.isovalues.size(); ++i) {
          const int f = options_.surface_field.empty() ? -1 : options_.surface_field[i];
          RayCasterOptions caster_options;
          caster_options.scalars = f >= 0;
          for (std::size_t k = 0; k < blocks.size(); ++k) {
            const Block& b = blocks[k];
            const auto which = [&] {
              return "colour_by: block " + std::to_string(k) + " of rank " + std::to_string(rank_);
            };
            const FieldSource* source = b.source.get();
            if (f >= 0 && (b.grid || b.hex || b.cells)) {
              source = b.colours[std::size_t(f)].source.get();
              if (!source)
                return Status::invalid_argument(which() + " has no field named '" +
                                                options_.colour_fields[std::size_t(f)] +
                                                "' (add_field)");
            } else if (f >= 0 && options_.colour_fields.size() > 1) {
              return Status::invalid_argument(
                  which() + " is a FieldSource, which has one colour field (bind_scalar), and " +
                  std::to_string(options_.colour_fields.size()) + " fields are named");
            }
            casters.owned.push_back(
                std::make_unique<RayCaster>(*source, options_.isovalues[i], caster_options));
            if (caster_options.scalars && !casters.owned.back()->carries_scalars())
              return Status::invalid_argument(
                  which() + " is a FieldSource without a colour field (bind_scalar)");
            casters.blocks[i].push_back(
                {casters.owned.back().get(),
                 {b.owned ? *b.owned : element_box(b.source->bounds(), *domain), *domain}});
          }
        }
        return Status::ok();
      });
    if (!local) {
      casters = {};
      casters.blocks.resize(options_.isovalues.size());
    }
    ReductionFaults faults;
    faults.damage_sent_message = fault_here("corrupt_message", job.step);
    // The root merges what it receives on its worker (mesh_step), off the solver's path.
    const Status s =
        cast_and_reduce(comm, casters.blocks, casters.views, options_.encoding, casters.tolerance,
                        local, true, job.cast, seconds_since(bind_start), faults);
    if (!s) return s;
    if (rank_ == 0) {
      job.views = casters.views;
      job.seconds = {{"cast", job.cast.seconds.cast},
                     {"encode", job.cast.seconds.encode},
                     {"reduce", job.cast.seconds.reduce}};
      job.nonfinite_values = job.cast.nonfinite_values;
    }
    return Status::ok();
  }

  // The root half where meshing needs every rank's samples (refinement, merging that projects),
  // collective over `comm`: the root meshes (mesh_step) while the other ranks serve from `casters`;
  // the root's worker then only encodes and publishes. On the thread that made the step's MPI
  // calls.
  Status mesh_with_samples(MPI_Comm comm, const StepCasters& casters, Job& job) const {
    CastStep none;
    std::vector<MeshingResult> results;
    const Status s = mesh_step(comm, casters.blocks, casters.views, casters.tolerance,
                               meshing_options(job.merge), rank_ == 0 ? job.cast : none, results);
    if (s && rank_ == 0) job.meshed = std::move(results);
    return s;
  }

  // Root, solver's thread, `mutex_` held, for a due step that runs, `interval` seconds after the
  // previous due step (0: none): whether "merging": "auto" has stopped merging. Each merged step
  // counts once, as slow when it is still being merged at a due step (with "busy": "coalesce"
  // the solver would wait for it) or when its merge took more than kAutoMergeShare of the
  // solver's time between due steps: the merge runs on the root's cores beside the solver, which
  // it slows (the Gray–Scott bench on 2 cores: +85 % solver time merging about 60 % of the
  // interval, against +29 % for the trimmed views; docs/benchmarks.md). After two slow merged
  // steps in a row (one can be a cold start) merging stops for good, and the log says so once.
  static constexpr double kAutoMergeShare = 0.25;
  bool auto_merge_stopped(std::uint64_t step, double interval) {
    if (options_.merging != AdaptorOptions::Merging::automatic || !background_) return false;
    if (auto_merge_stopped_) return true;
    std::string why;
    if (merging_now_ && merging_step_ != counted_step_) {
      counted_step_ = merging_step_;
      ++slow_merges_;
      why = "step " + std::to_string(merging_step_) + " was still being merged";
    } else if (!merging_now_ && merged_step_ && *merged_step_ != counted_step_ && interval > 0.0) {
      counted_step_ = *merged_step_;
      const bool slow = last_merge_seconds_ > kAutoMergeShare * interval;
      slow_merges_ = slow ? slow_merges_ + 1 : 0;
      char text[160];
      std::snprintf(text, sizeof text,
                    "merging step %llu took %.2f s, over a quarter of the %.2f s between due steps",
                    (unsigned long long)*merged_step_, last_merge_seconds_, interval);
      why = text;
    }
    if (slow_merges_ >= 2) {
      auto_merge_stopped_ = true;
      if (options_.log)
        std::printf(
            "ldimesh: from step %llu on the views are published trimmed, not merged "
            "(\"merging\": \"auto\"): the root does not keep up (%s); \"merging\": true merges "
            "every step (steps are then skipped while the root merges)\n",
            (unsigned long long)step, why.c_str());
    }
    return auto_merge_stopped_;
  }

  // Why a step on the background path ran synchronously (none: it did not).
  enum class SyncReason { none, field_source, memory };
  // Root's log, where the path of executed steps changes (not at every step): a step that runs
  // synchronously for `reason` (`why`), or in the background again.
  void log_path(std::uint64_t step, SyncReason reason, const std::string& why) {
    if (rank_ != 0 || reason == logged_reason_) return;
    logged_reason_ = reason;
    if (!options_.log) return;
    if (reason == SyncReason::none) {
      std::printf("ldimesh: from step %llu on, steps run in the background again\n",
                  (unsigned long long)step);
      return;
    }
    std::printf(
        "ldimesh: from step %llu on, steps run synchronously: %s%s (the log says when this "
        "changes)\n",
        (unsigned long long)step, why.c_str(),
        options_.merging == AdaptorOptions::Merging::automatic
            ? "; their views are published trimmed, not merged (\"merging\": \"auto\")"
            : "");
  }

  // Root: gives `job` to the worker; true when it replaced a step still waiting ("coalesce").
  bool hand_to_worker(Job job) {
    std::lock_guard lock(mutex_);
    const bool replaced = pending_.has_value();
    if (replaced) {
      job.skipped_steps += pending_->skipped_steps + 1;
      if (options_.log)
        std::printf("ldimesh: step %llu replaces step %llu, which was still waiting\n",
                    (unsigned long long)job.step, (unsigned long long)pending_->step);
    }
    pending_ = std::move(job);
    wake_.notify_all();
    return replaced;
  }

  // ---- The background path: the solver waits for a copy of its blocks only.

  // Whether the domain is set and every block can be copied (grid and high-order blocks: a
  // FieldSource cannot). Whether the copy fits memory_mb is known once the field is read
  // (hand_to_background).
  bool snapshot_copyable() const {
    if (!has_domain_) return false;  // the synchronous path fails the step on every rank
    for (const Block& b : blocks_)
      if (!b.grid && !b.hex && !b.cells) return false;
    return true;
  }

  // Copies what the step reads of the blocks into the snapshot buffers (kept from step to step;
  // copy_grid) and hands the step to
  // this rank's caster thread. Every rank does, even after a local failure (the caster thread
  // then sends empty fragments and the step fails everywhere, as on the synchronous path).
  // Collective. Returns false, `job` untouched, where a rank's copy would exceed memory_mb (known
  // once each rank has chosen what to copy; `largest` is the largest copy's bytes): the step
  // then runs synchronously on every rank.
  bool hand_to_background(Job& job, Clock::time_point start, long long& largest) {
    {
      // With "skip" the root decided the step runs because its own caster was idle, and the
      // others' finish the previous step's reduction with it: a short wait. With "coalesce"
      // the solver waits here for the rest of the previous step's cast and reduction.
      std::unique_lock lock(mutex_);
      caster_idle_.wait(lock, [&] { return !caster_job_ && !casting_; });
    }
    // What the step reads of each block: a grid block's bricks, an element block's elements.
    std::vector<CopyPlan> plans;
    std::size_t planned = 0;
    Status copied = guard("snapshot: ", [&] {
      plans.resize(blocks_.size());
      for (std::size_t k = 0; k < blocks_.size(); ++k) {
        const Block& b = blocks_[k];
        std::vector<FieldArray> colours;
        for (const Colour& c : b.colours)
          colours.push_back(c.array);
        plans[k] = b.grid    ? plan_grid(*b.grid, static_cast<const GridSource&>(*b.source),
                                         options_.isovalues, colours, field_bits_)
                   : b.cells ? plan_cells(*b.cells, colours)
                             : plan_hex(*b.hex, static_cast<const HexElementSource&>(*b.source),
                                        options_.isovalues, colours);
        planned += plans[k].bytes();
      }
      return Status::ok();
    });
    // Whether some rank's copy exceeds memory_mb, and the largest copy. (A rank that failed
    // goes on: its caster thread fails the step everywhere, as on the synchronous path.)
    long long over[2] = {copied && planned > (options_.memory_mb << 20) ? 1 : 0,
                         static_cast<long long>(planned)};
    MPI_Allreduce(MPI_IN_PLACE, over, 2, MPI_LONG_LONG, MPI_MAX, comm_);
    largest = over[1];
    if (over[0]) {  // synchronous: the previous snapshot is no longer needed (the caster is idle)
      snapshot_blocks_.clear();
      snapshot_.clear();
      return false;
    }
    std::size_t bytes = 0;
    if (copied)
      copied = guard("snapshot: ", [&] {
        // Every page the copies will not write is given back before any is written.
        snapshot_.resize(blocks_.size());
        snapshot_blocks_.clear();
        for (std::size_t k = 0; k < blocks_.size(); ++k)
          begin_copy(plans[k], snapshot_[k]);
        for (std::size_t k = 0; k < blocks_.size(); ++k) {
          const Block& b = blocks_[k];
          Block copy;
          copy.owned = b.owned;
          const std::vector<std::uint8_t>& held = plans[k].held;
          if (b.grid) {  // the bricks the step's isovalues need, with the points around them
            const auto& live = static_cast<const GridSource&>(*b.source);
            copy.grid = copy_grid(*b.grid, live, held, snapshot_[k]);
            copy.source = std::make_shared<GridSource>(*copy.grid, live.brick_cells(), held);
          } else if (b.cells) {  // every cell's values; the sub-hexahedra prepared once
            copy.cells = copy_cells(*b.cells, snapshot_[k]);
            copy.source = std::make_shared<CellElementSource>(
                static_cast<const CellElementSource&>(*b.source), *copy.cells);
          } else {  // the geometry as the block's source prepared it (converted and checked once)
            copy.hex = copy_hex(*b.hex, held, snapshot_[k]);
            copy.source = std::make_shared<HexElementSource>(
                static_cast<const HexElementSource&>(*b.source), *copy.hex, held);
          }
          // Each colour field (a grid block's points the casts of the isovalues it colours read,
          // an element block's whole field), and a source over it and the copy's values.
          copy.colours.resize(b.colours.size());
          for (std::size_t f = 0; f < b.colours.size(); ++f) {
            const FieldArray live = b.colours[f].array;
            if (!live.values) continue;
            SparseCopy& into = snapshot_[k].colours[f];
            const std::vector<std::uint8_t>& field_held =
                plans[k].colour_held[f].empty() ? held : plans[k].colour_held[f];
            if (b.grid)
              copy_points(*b.grid, static_cast<const GridSource&>(*b.source), field_held,
                          live.values, live.type, into.held(), into.data());
            else if (b.cells)
              copy_nodal(*b.cells, live.values, live.type, into.data());
            else
              copy_nodal(*b.hex, live.values, live.type, {}, into.data());
            const FieldArray copied{into.data(), live.type};
            copy.colours[f] = {copied, coloured_source(copy, copied, field_held)};
          }
          bytes += snapshot_[k].bytes();
          snapshot_blocks_.push_back(std::move(copy));
        }
        return Status::ok();
      });
    if (!copied) snapshot_blocks_.clear();
    report_.background = true;
    report_.snapshot_bytes = bytes;
    CasterJob cj;
    cj.job = std::move(job);
    cj.domain = domain();
    cj.status = copied;
    cj.blocked_seconds = seconds_since(start);
    {
      std::lock_guard lock(mutex_);
      caster_job_ = std::move(cj);
      if (rank_ == 0) casting_ = true;  // busy from now on for the root's next decision
      caster_wake_.notify_all();
    }
    finish_report(start);
    return true;
  }

  // Every rank's caster thread: the collective half of each snapshotted step on the duplicated
  // communicator, then (root) the hand-off to the worker.
  void cast_in_background() {
    while (true) {
      CasterJob cj;
      wait_as_batch_thread(true);
      {
        std::unique_lock lock(mutex_);
        caster_wake_.wait(lock, [&] { return caster_stopping_ || caster_job_.has_value(); });
        if (!caster_job_) return;
        cj = std::move(*caster_job_);
        caster_job_.reset();
        casting_ = true;
      }
      wait_as_batch_thread(false);
      const std::uint64_t step = cj.job.step;
      const Status failed = guard("", [&] {
        StepCasters casters;
        Status s = collective_step(background_comm_, snapshot_blocks_, cj.domain, cj.status, cj.job,
                                   casters);
        double max_blocked = 0.0;
        MPI_Reduce(&cj.blocked_seconds, &max_blocked, 1, MPI_DOUBLE, MPI_MAX, 0, background_comm_);
        // The snapshot stays until the next step: the ranks serve the root's samples from it.
        if (s && meshing_samples(meshing_options(cj.job.merge))) {
          const bool merging = rank_ == 0 && cj.job.merge;
          if (merging) {
            std::lock_guard lock(mutex_);
            merging_now_ = true;
            merging_step_ = cj.job.step;
          }
          const Clock::time_point merge_start = Clock::now();
          s = mesh_with_samples(background_comm_, casters, cj.job);
          // What the merge (decoding and meshing, the samples' round trips included) took.
          if (merging) {
            std::lock_guard lock(mutex_);
            merging_now_ = false;
            if (s) {
              last_merge_seconds_ = seconds_since(merge_start);
              merged_step_ = cj.job.step;
            }
          }
        }
        LDIMESH_RETURN_IF_ERROR(s);
        if (rank_ == 0) {
          cj.job.seconds["blocked"] = max_blocked;
          hand_to_worker(std::move(cj.job));
        }
        return Status::ok();
      });
      std::lock_guard lock(mutex_);
      casting_ = false;
      merging_now_ = false;
      if (!failed)
        background_failure(failed, "step " + std::to_string(step) + " skipped: ", rank_ == 0);
      caster_idle_.notify_all();
    }
  }

  // A grid block's hits belong to its owned region, an element block's to its cells (Block).
  // The block's own colour array is not read: its fields come by name (add_field).
  template <class Source, class Description>
  Status add_block(Description block, const char* what) {
    block.colour = nullptr;
    last_add_failed_ = true;
    return fail_if(guard(std::string(what) + ": ", [&] {
      auto source = std::make_shared<Source>(block);
      std::optional<Box> owned;
      if constexpr (std::is_same_v<Description, GridBlock>) owned = source->bounds();
      Block b{std::move(source), owned, std::nullopt, std::nullopt, std::nullopt, {}};
      b.colours.resize(options_.colour_fields.size());
      if constexpr (std::is_same_v<Description, GridBlock>)
        b.grid = block;
      else if constexpr (std::is_same_v<Description, CellBlock>)
        b.cells = block;
      else
        b.hex = block;
      blocks_.push_back(std::move(b));
      last_add_failed_ = false;
      return Status::ok();
    }));
  }

  std::optional<Box> domain() const {
    return has_domain_ ? std::optional<Box>(domain_) : std::nullopt;
  }

  // Keeps the failure as the last error and returns it.
  Status fail(Status failure) {
    std::lock_guard lock(mutex_);
    last_error_ = failure.message();
    return failure;
  }
  Status fail_if(Status s) { return s ? s : fail(std::move(s)); }

  // A failure of this rank's background work (caster or worker thread; `mutex_` held): kept
  // for finalize() and last_error(), and logged where `log_it`.
  void background_failure(const Status& failed, const std::string& prefix, bool log_it) {
    worker_status_ = failed.prefixed(prefix);
    last_error_ = worker_status_.message();
    if (options_.log && log_it) std::fprintf(stderr, "ldimesh: error: %s\n", last_error_.c_str());
  }

  void finish_report(Clock::time_point start) {
    report_.blocked_seconds = seconds_since(start);
    MPI_Reduce(&report_.blocked_seconds, &report_.max_blocked_seconds, 1, MPI_DOUBLE, MPI_MAX, 0,
               comm_);
    report_.executed = !report_.skipped_busy && report_.blocked_seconds > 0.0;
  }

  // The root's worker: decode, mesh, encode, publish — off the solver's path.
  void work() {
    while (true) {
      Job job;
      wait_as_batch_thread(true);
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [&] { return stopping_ || pending_.has_value(); });
        if (!pending_) return;
        job = std::move(*pending_);
        pending_.reset();
        working_ = true;
      }
      wait_as_batch_thread(false);
      const Status failed = guard("", [&] { return publish(job); });
      std::lock_guard lock(mutex_);
      // Counted where the worker becomes idle, under the same lock: whoever sees the step
      // published also sees the root free for the next one (a due step is skipped while it is
      // busy; counted earlier, a step due at once could still find it working).
      if (failed) ++published_;
      working_ = false;
      if (!failed) background_failure(failed, "step " + std::to_string(job.step) + ": ", true);
      idle_.notify_all();
    }
  }

  // Writes the step's files into output_dir. A failure (disk full, the folder gone or no longer
  // writable) does not fail the step: it is published and served from memory like any other,
  // and stderr says so once when writing starts failing and once when it works again.
  void write_step(const Snapshot& snapshot) {
    const Status s = write_step_files(options_.output_dir, snapshot);
    if (!s) {
      if (unwritten_steps_++ == 0)
        std::fprintf(stderr,
                     "ldimesh: warning: step %llu not written: %s; steps are served from memory "
                     "until writing works again\n",
                     (unsigned long long)snapshot.step, s.message().c_str());
    } else if (unwritten_steps_ > 0) {
      std::fprintf(stderr,
                   "ldimesh: writing steps to '%s' again from step %llu (%llu steps were not "
                   "written)\n",
                   options_.output_dir.c_str(), (unsigned long long)snapshot.step,
                   (unsigned long long)unwritten_steps_);
      unwritten_steps_ = 0;
    }
  }

  Status publish(Job& job) {
    if (options_.slow_root_seconds > 0.0)
      std::this_thread::sleep_for(std::chrono::duration<double>(options_.slow_root_seconds));
    const MeshingOptions meshing = meshing_options(job.merge);
    // The root half (mesh_step) unless it ran where the samples are: no MPI call here.
    std::vector<MeshingResult> results;
    if (job.meshed) {
      results = std::move(*job.meshed);
    } else if (Status s =
                   mesh_on_root(options_.isovalues.size(), job.views, meshing, job.cast, results);
               !s) {
      return s;
    }
    const double decode_s = job.cast.seconds.decode, mesh_s = job.cast.seconds.mesh;
    StepDescription description;
    description.step = job.step;
    description.time = job.time;
    description.isovalues = options_.isovalues;
    description.views = job.views;
    description.r = trim_r(meshing);
    description.colour_fields = options_.colour_fields;
    description.surface_field = options_.surface_field;
    description.glb = options_.glb;
    PackagedStep packaged;
    LDIMESH_RETURN_IF_ERROR(package_step(description, std::move(results), packaged));
    const GlbInfo& info = packaged.info;
    const double glb_s = packaged.glb_seconds;
    const std::size_t uncoloured = packaged.uncoloured;
    StepMetadata meta = std::move(packaged.metadata);
    meta.seconds.insert(job.seconds.begin(), job.seconds.end());
    meta.seconds["decode"] = decode_s;
    meta.seconds["mesh"] = mesh_s;
    meta.skipped_steps = job.skipped_steps;
    meta.nonfinite_values = job.nonfinite_values;
    std::vector<std::uint8_t> glb = std::move(packaged.glb);
    const std::size_t bytes = glb.size();
    Snapshot snapshot = make_snapshot(std::move(meta), std::move(glb));
    if (!options_.output_dir.empty()) write_step(snapshot);
    LDIMESH_RETURN_IF_ERROR(store_->publish(std::move(snapshot)));
    if (options_.log) {
      std::printf(
          "ldimesh: step %llu  t=%g  %zu triangles  %zu bytes  cast %.3f reduce %.3f mesh %.3f glb "
          "%.3f s%s\n",
          (unsigned long long)job.step, job.time, std::size_t(info.triangles), bytes,
          job.seconds["cast"], job.seconds["reduce"], mesh_s, glb_s,
          step_notes(job, uncoloured).c_str());
      std::fflush(stdout);
    }
    return Status::ok();
  }

  // The log line's warnings: steps dropped before this one, non-finite field values, vertices
  // without a finite colour.
  static std::string step_notes(const Job& job, std::size_t uncoloured) {
    std::string notes;
    if (job.skipped_steps > 0)
      notes += "  (" + std::to_string(job.skipped_steps) + " earlier steps skipped: root busy)";
    if (job.nonfinite_values > 0)
      notes += "  warning: " + std::to_string(job.nonfinite_values) +
               " NaN/Inf field values, the cells touching them left out";
    if (uncoloured > 0)
      notes += "  warning: " + std::to_string(uncoloured) +
               " vertices without a finite colour value (NaN/Inf in the colour field), shown at "
               "the lowest colour";
    return notes;
  }

  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  AdaptorOptions options_;
  std::vector<std::uint8_t> field_bits_;  // per colour field, its isovalues' bits (plan_grid)
  Box domain_;
  bool has_domain_ = false;
  std::vector<Block> blocks_;
  bool last_add_failed_ = false;  // the last add_*_block call failed: add_field refuses
  StepReport report_;
  bool finalized_ = false;
  Clock::time_point last_run_;
  bool ran_before_ = false;
  std::uint64_t skipped_since_handoff_ = 0;      // root, solver thread only
  bool auto_merge_stopped_ = false;              // root, solver thread only
  SyncReason logged_reason_ = SyncReason::none;  // root, solver thread only: log_path
  Clock::time_point last_due_;                   // root, solver thread only
  bool due_before_ = false;                      // root, solver thread only
  // Root, "merging": "auto" (mutex_): the merge running on the caster thread and its step, the
  // last merged step and what it kept the caster busy, the last step counted, slow ones in a row.
  bool merging_now_ = false;
  std::uint64_t merging_step_ = 0;
  std::optional<std::uint64_t> merged_step_;
  double last_merge_seconds_ = 0.0;
  std::uint64_t counted_step_ = UINT64_MAX;
  int slow_merges_ = 0;

  // Root only.
  std::unique_ptr<SnapshotStore> store_;
  std::unique_ptr<HttpServer> server_;
  std::thread worker_;
  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::optional<Job> pending_;
  bool working_ = false;
  bool stopping_ = false;
  std::uint64_t published_ = 0;
  std::uint64_t unwritten_steps_ = 0;  // in a row, not written to output_dir (publish only)
  std::string last_error_;
  Status worker_status_ = Status::ok();  // the last failure of this rank's background work

  // Every rank, background path (MPI_THREAD_MULTIPLE): the caster thread, its communicator (a
  // duplicate, so that its collectives never meet the solver's) and the snapshot it reads.
  bool background_ = false;
  MPI_Comm background_comm_ = MPI_COMM_NULL;
  std::thread caster_;
  std::condition_variable caster_wake_, caster_idle_;
  std::optional<CasterJob> caster_job_;
  bool casting_ = false;  // root: from the hand-off until the step is reduced
  bool caster_stopping_ = false;
  std::vector<BlockCopy> snapshot_;
  std::vector<Block> snapshot_blocks_;  // sources over snapshot_, read by the caster thread
};

}  // namespace

Status Adaptor::create(MPI_Comm comm, std::string_view options_json,
                       std::unique_ptr<Adaptor>& out) {
  out.reset();
  int initialized = 0, finalized = 0;
  MPI_Initialized(&initialized);
  MPI_Finalized(&finalized);
  if (!initialized || finalized)
    return Status::invalid_argument("ldimesh: MPI is not initialised (call MPI_Init_thread first)");
  if (comm == MPI_COMM_NULL)
    return Status::invalid_argument("ldimesh: the communicator is MPI_COMM_NULL");
  try {
    AdaptorOptions options;
    Status status = Status::ok();
    if (!options_json.empty()) {
      status = parse_adaptor_options(options_json, options);
    }
    if (status && !options.fault.empty()) {
      int size = 1;
      MPI_Comm_size(comm, &size);
      if (options.fault_rank >= size)
        status = Status::invalid_options(
            "options: 'testing.fault.rank' must be below the communicator's size (" +
            std::to_string(size) + ")");
    }
    // Everyone gets the same verdict (the document is the same on every rank).
    int failed = status ? 0 : 1;
    MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm);
    if (failed)
      return status ? Status::invalid_options("options: invalid on another rank") : status;
    auto adaptor = std::make_unique<AdaptorImpl>(comm, std::move(options));
    adaptor->start_background();
    Status started = adaptor->start_root();
    int start_failed = started ? 0 : 1;
    MPI_Bcast(&start_failed, 1, MPI_INT, 0, comm);
    if (start_failed)
      return started ? Status::other_rank("the root could not start (see its message)") : started;
    out = std::move(adaptor);
    return Status::ok();
  } catch (...) {
    return status_from_current_exception("ldimesh: ");
  }
}

Status Adaptor::create_from_file(MPI_Comm comm, const std::string& path,
                                 std::unique_ptr<Adaptor>& out) {
  std::string file = path;
  if (file.empty())
    if (const char* env = std::getenv("LDIMESH_OPTIONS")) file = env;
  if (file.empty()) return create(comm, "", out);
  std::ifstream in(file);
  if (!in) return Status::io("options: cannot read '" + file + "'");
  std::stringstream text;
  text << in.rdbuf();
  return create(comm, text.str(), out);
}

}  // namespace ldimesh
