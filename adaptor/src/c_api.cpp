// The C API (ldimesh.h) over ldimesh::Adaptor. Every entry point catches everything: no
// exception crosses into C or Fortran.
#include "ldimesh.h"

#include <cstring>
#include <limits>
#include <new>
#include <string>

#include "ldimesh/adaptor.hpp"

struct ldimesh_adaptor {
  std::unique_ptr<ldimesh::Adaptor> impl;
  std::string error;  // this handle's last error (C API checks and the adaptor's)
  std::string url;
  // Values the block added last reads (ldimesh_add_field checks a field's array against it);
  // 0 before the first block.
  std::int64_t block_values = 0;
};

namespace {

using ldimesh::Status;

// The last failed create on this thread (there is no handle to keep it on).
thread_local std::string create_error;

// The C code of a status: from its cause, whichever call it came from.
int code_of(const Status& s) {
  switch (s.code()) {
    case ldimesh::StatusCode::ok:
      return LDIMESH_OK;
    case ldimesh::StatusCode::invalid_argument:
      return LDIMESH_ERROR_ARGUMENT;
    case ldimesh::StatusCode::invalid_options:
      return LDIMESH_ERROR_OPTIONS;
    case ldimesh::StatusCode::other_rank:
      return LDIMESH_ERROR_STEP;
    case ldimesh::StatusCode::corrupt_input:
      return LDIMESH_ERROR_CORRUPT;
    case ldimesh::StatusCode::io:
      return LDIMESH_ERROR_IO;
    case ldimesh::StatusCode::out_of_memory:
      return LDIMESH_ERROR_MEMORY;
    case ldimesh::StatusCode::internal:
      break;
  }
  return LDIMESH_ERROR_RUNTIME;
}

// Keeps `message` on the handle and returns `code`.
int fail(ldimesh_adaptor* a, int code, std::string message) {
  if (a) a->error = std::move(message);
  return code;
}

// Runs `body` (which returns a Status) behind the boundary's guard: keeps a failure's message
// on the handle and returns its code.
template <class Body>
int guarded(ldimesh_adaptor* a, const char* where, Body&& body) {
  const Status s = ldimesh::guard(where, body);
  if (!s) a->error = s.message();
  return code_of(s);
}

int no_handle() {
  // Nothing to keep the message on: a caller checking ldimesh_last_error(NULL) finds it.
  create_error = "ldimesh: the adaptor handle is NULL (did ldimesh_create fail?)";
  return LDIMESH_ERROR_ARGUMENT;
}

template <class Create>
int create_with(ldimesh_adaptor** out, Create&& create) {
  if (!out) {
    create_error = "ldimesh_create: out is NULL";
    return LDIMESH_ERROR_ARGUMENT;
  }
  *out = nullptr;
  const Status s = ldimesh::guard("ldimesh_create: ", [&] {
    auto handle = std::make_unique<ldimesh_adaptor>();
    LDIMESH_RETURN_IF_ERROR(create(handle->impl));
    handle->url = handle->impl->url();
    *out = handle.release();
    return Status::ok();
  });
  if (s)
    create_error.clear();
  else
    create_error = s.message();
  return code_of(s);
}

// A Fortran communicator handle in C; MPI_COMM_NULL before MPI_Init (MPI_Comm_f2c is not
// allowed then), which Adaptor::create refuses with a message.
MPI_Comm comm_from_fortran(MPI_Fint comm) {
  int initialized = 0;
  MPI_Initialized(&initialized);
  return initialized ? MPI_Comm_f2c(comm) : MPI_COMM_NULL;
}

bool scalar_type(int type, ldimesh::ScalarType& out) {
  if (type == LDIMESH_FLOAT32)
    out = ldimesh::ScalarType::float32;
  else if (type == LDIMESH_FLOAT64)
    out = ldimesh::ScalarType::float64;
  else
    return false;
  return true;
}

// n · m, false on overflow of int64 (both non-negative).
bool mul(std::int64_t n, std::int64_t m, std::int64_t& out) {
  if (n != 0 && m > std::numeric_limits<std::int64_t>::max() / n) return false;
  out = n * m;
  return true;
}

}  // namespace

extern "C" {

int ldimesh_create(MPI_Comm comm, const char* options_json, ldimesh_adaptor** out) {
  return create_with(out, [&](std::unique_ptr<ldimesh::Adaptor>& impl) {
    return ldimesh::Adaptor::create(comm, options_json ? options_json : "", impl);
  });
}

int ldimesh_create_from_file(MPI_Comm comm, const char* path, ldimesh_adaptor** out) {
  return create_with(out, [&](std::unique_ptr<ldimesh::Adaptor>& impl) {
    return ldimesh::Adaptor::create_from_file(comm, path ? path : "", impl);
  });
}

int ldimesh_create_fortran(MPI_Fint comm, const char* options_json, ldimesh_adaptor** out) {
  return ldimesh_create(comm_from_fortran(comm), options_json, out);
}

int ldimesh_create_from_file_fortran(MPI_Fint comm, const char* path, ldimesh_adaptor** out) {
  return ldimesh_create_from_file(comm_from_fortran(comm), path, out);
}

void ldimesh_grid_block_init(ldimesh_grid_block* block) {
  if (!block) return;
  std::memset(block, 0, sizeof *block);
  block->type = LDIMESH_FLOAT64;
  for (double& s : block->spacing)
    s = 1.0;
}

void ldimesh_hex_block_init(ldimesh_hex_block* block) {
  if (!block) return;
  std::memset(block, 0, sizeof *block);
  block->type = LDIMESH_FLOAT64;
  block->nodes = LDIMESH_NODES_GLL;
}

int ldimesh_set_domain(ldimesh_adaptor* a, const double lo[3], const double hi[3]) {
  if (!a) return no_handle();
  if (!lo || !hi) return fail(a, LDIMESH_ERROR_ARGUMENT, "ldimesh_set_domain: lo or hi is NULL");
  return guarded(a, "ldimesh_set_domain: ", [&] {
    return a->impl->set_domain({{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}});
  });
}

int ldimesh_add_grid_block(ldimesh_adaptor* a, const ldimesh_grid_block* b) {
  if (!a) return no_handle();
  a->block_values = 0;  // until a block is added: a field would belong to none
  const std::string what = "ldimesh_add_grid_block: ";
  if (!b) return fail(a, LDIMESH_ERROR_ARGUMENT, what + "block is NULL");
  ldimesh::GridBlock g;
  if (!scalar_type(b->type, g.type))
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "type must be LDIMESH_FLOAT32 or LDIMESH_FLOAT64");
  for (int i = 0; i < 3; ++i) {
    if (b->dims[i] < 2)
      return fail(a, LDIMESH_ERROR_ARGUMENT,
                  what + "dims[" + std::to_string(i) + "] = " + std::to_string(b->dims[i]) +
                      ": a block needs at least 2 points per axis");
    if (b->strides[i] < 0)
      return fail(a, LDIMESH_ERROR_ARGUMENT, what + "strides must not be negative");
  }
  const bool contiguous = b->strides[0] == 0 && b->strides[1] == 0 && b->strides[2] == 0;
  // The values the block reads: the index of its last point, plus one.
  std::int64_t needed = 1;
  if (contiguous) {
    if (!mul(b->dims[0], b->dims[1], needed) || !mul(needed, b->dims[2], needed))
      return fail(a, LDIMESH_ERROR_ARGUMENT, what + "dims overflow");
  } else {
    for (int i = 0; i < 3; ++i) {
      std::int64_t span = 0;
      if (b->strides[i] == 0)
        return fail(a, LDIMESH_ERROR_ARGUMENT,
                    what + "strides must be all zero (contiguous) or all positive");
      if (!mul(b->dims[i] - 1, b->strides[i], span) ||
          needed > std::numeric_limits<std::int64_t>::max() - span)
        return fail(a, LDIMESH_ERROR_ARGUMENT, what + "strides overflow");
      needed += span;
    }
  }
  if (b->value_count < needed)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "the array holds " + std::to_string(b->value_count) +
                    " values, the block reads " + std::to_string(needed) + " (dims " +
                    std::to_string(b->dims[0]) + "×" + std::to_string(b->dims[1]) + "×" +
                    std::to_string(b->dims[2]) + ")");
  g.dims = {b->dims[0], b->dims[1], b->dims[2]};
  g.values = b->values;
  g.strides = {b->strides[0], b->strides[1], b->strides[2]};
  g.origin = {b->origin[0], b->origin[1], b->origin[2]};
  g.spacing = {b->spacing[0], b->spacing[1], b->spacing[2]};
  g.coords = {b->coords[0], b->coords[1], b->coords[2]};
  for (int i = 0; i < 3; ++i) {
    g.ghost_lo[i] = b->ghost_lo[i];
    g.ghost_hi[i] = b->ghost_hi[i];
  }
  const int code =
      guarded(a, "ldimesh_add_grid_block: ", [&] { return a->impl->add_grid_block(g); });
  if (code == LDIMESH_OK) a->block_values = needed;
  return code;
}

int ldimesh_add_hex_block(ldimesh_adaptor* a, const ldimesh_hex_block* b) {
  if (!a) return no_handle();
  a->block_values = 0;  // until a block is added: a field would belong to none
  const std::string what = "ldimesh_add_hex_block: ";
  if (!b) return fail(a, LDIMESH_ERROR_ARGUMENT, what + "block is NULL");
  ldimesh::HexBlock h;
  if (!scalar_type(b->type, h.type))
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "type must be LDIMESH_FLOAT32 or LDIMESH_FLOAT64");
  switch (b->nodes) {
    case LDIMESH_NODES_GLL:
      h.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
      break;
    case LDIMESH_NODES_GL:
      h.nodes = ldimesh::NodeSet::gauss_legendre;
      break;
    case LDIMESH_NODES_EQUISPACED:
      h.nodes = ldimesh::NodeSet::equispaced;
      break;
    default:
      return fail(a, LDIMESH_ERROR_ARGUMENT, what + "nodes must be LDIMESH_NODES_*");
  }
  if (b->order < 1 || b->order > ldimesh::kMaxHexOrder)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "order must lie in 1.." + std::to_string(ldimesh::kMaxHexOrder));
  if (b->element_count < 1)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count must be at least 1");
  const std::int64_t per_element = std::int64_t(b->order + 1) * (b->order + 1) * (b->order + 1);
  const std::int64_t stride = b->element_stride == 0 ? per_element : b->element_stride;
  if (stride < per_element)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "element_stride is smaller than the (p+1)³ values of an element");
  std::int64_t needed = 0;
  if (!mul(b->element_count - 1, stride, needed))
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count overflows");
  if (needed > std::numeric_limits<std::int64_t>::max() - per_element)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count overflows");
  needed += per_element;
  if (b->value_count < needed)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "the array holds " + std::to_string(b->value_count) +
                    " values, the elements read " + std::to_string(needed));
  if (b->geometry_order < 0 || b->geometry_order > ldimesh::kMaxHexOrder)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "geometry_order must lie in 0.." + std::to_string(ldimesh::kMaxHexOrder));
  if (b->geometry_order > 0) {
    const std::int64_t q1 = b->geometry_order + 1;
    std::int64_t doubles = 0;
    if (!mul(b->element_count, 3 * q1 * q1 * q1, doubles))
      return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count overflows");
    if (!b->geometry || b->geometry_count < doubles)
      return fail(a, LDIMESH_ERROR_ARGUMENT,
                  what + "the geometry array holds " + std::to_string(b->geometry_count) +
                      " doubles, the elements read " + std::to_string(doubles));
  }
  h.order = b->order;
  h.element_count = std::size_t(b->element_count);
  h.corners = b->corners;
  h.geometry_order = b->geometry_order;
  h.geometry = b->geometry;
  if (b->ordering != LDIMESH_ORDER_LEXICOGRAPHIC && b->ordering != LDIMESH_ORDER_VTK)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "ordering must be LDIMESH_ORDER_*");
  h.ordering = b->ordering == LDIMESH_ORDER_VTK ? ldimesh::NodeOrdering::vtk_lagrange
                                                : ldimesh::NodeOrdering::lexicographic;
  h.values = b->values;
  h.element_stride = std::size_t(stride);
  const int code = guarded(a, "ldimesh_add_hex_block: ", [&] { return a->impl->add_hex_block(h); });
  if (code == LDIMESH_OK) a->block_values = needed;
  return code;
}

void ldimesh_cell_block_init(ldimesh_cell_block* block) {
  if (!block) return;
  std::memset(block, 0, sizeof *block);
  block->cell_type = LDIMESH_CELL_TETRAHEDRON;
  block->order = 1;
  block->type = LDIMESH_FLOAT64;
}

int ldimesh_add_cell_block(ldimesh_adaptor* a, const ldimesh_cell_block* b) {
  if (!a) return no_handle();
  a->block_values = 0;  // until a block is added: a field would belong to none
  const std::string what = "ldimesh_add_cell_block: ";
  if (!b) return fail(a, LDIMESH_ERROR_ARGUMENT, what + "block is NULL");
  ldimesh::CellBlock c;
  if (!scalar_type(b->type, c.value_type))
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "type must be LDIMESH_FLOAT32 or LDIMESH_FLOAT64");
  if (b->cell_type < LDIMESH_CELL_HEXAHEDRON || b->cell_type > LDIMESH_CELL_PYRAMID14)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "cell_type must be LDIMESH_CELL_*");
  static_assert(int(ldimesh::CellType::hexahedron) == LDIMESH_CELL_HEXAHEDRON &&
                int(ldimesh::CellType::serendipity_hexahedron) == LDIMESH_CELL_HEXAHEDRON20 &&
                int(ldimesh::CellType::tetrahedron) == LDIMESH_CELL_TETRAHEDRON &&
                int(ldimesh::CellType::wedge) == LDIMESH_CELL_WEDGE &&
                int(ldimesh::CellType::serendipity_wedge) == LDIMESH_CELL_WEDGE15 &&
                int(ldimesh::CellType::pyramid) == LDIMESH_CELL_PYRAMID &&
                int(ldimesh::CellType::pyramid14) == LDIMESH_CELL_PYRAMID14);
  c.type = ldimesh::CellType(b->cell_type);
  const std::size_t nodes = ldimesh::cell_nodes(c.type, b->order);
  if (nodes == 0)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "a " + ldimesh::cell_type_name(c.type) + " of order " +
                    std::to_string(b->order) + " does not exist");
  if (b->element_count < 1)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count must be at least 1");
  const std::int64_t per_element = std::int64_t(nodes);
  const std::int64_t stride = b->element_stride == 0 ? per_element : b->element_stride;
  if (stride < per_element)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "element_stride is smaller than the " + std::to_string(per_element) +
                    " nodes of a cell");
  const std::size_t geometry_nodes =
      ldimesh::cell_geometry_nodes(c.type, b->order, b->geometry_order);
  if (geometry_nodes == 0)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "geometry_order " + std::to_string(b->geometry_order) + " of a " +
                    ldimesh::cell_type_name(c.type) + " does not exist (0: the field's)");
  std::int64_t needed = 0, doubles = 0;
  if (!mul(b->element_count - 1, stride, needed) ||
      !mul(b->element_count, 3 * std::int64_t(geometry_nodes), doubles))
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count overflows");
  if (needed > std::numeric_limits<std::int64_t>::max() - per_element)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "element_count overflows");
  needed += per_element;
  if (!b->values || b->value_count < needed)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "the array holds " + std::to_string(b->value_count) +
                    " values, the cells read " + std::to_string(needed));
  if (!b->points || b->point_count < doubles)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "the point array holds " + std::to_string(b->point_count) +
                    " doubles, the cells read " + std::to_string(doubles));
  if (b->node_order != LDIMESH_CELL_ORDER_VTK && b->node_order != LDIMESH_CELL_ORDER_GMSH)
    return fail(a, LDIMESH_ERROR_ARGUMENT, what + "node_order must be LDIMESH_CELL_ORDER_*");
  c.node_order = b->node_order == LDIMESH_CELL_ORDER_GMSH ? ldimesh::CellNodeOrder::gmsh
                                                          : ldimesh::CellNodeOrder::vtk;
  c.order = b->order;
  c.geometry_order = b->geometry_order;
  c.element_count = std::size_t(b->element_count);
  c.points = b->points;
  c.values = b->values;
  c.element_stride = std::size_t(stride);
  const int code =
      guarded(a, "ldimesh_add_cell_block: ", [&] { return a->impl->add_cell_block(c); });
  if (code == LDIMESH_OK) a->block_values = needed;
  return code;
}

int ldimesh_add_field(ldimesh_adaptor* a, const char* name, const void* values, int64_t value_count,
                      int type) {
  if (!a) return no_handle();
  const std::string what = "ldimesh_add_field: ";
  if (!name || !*name) return fail(a, LDIMESH_ERROR_ARGUMENT, what + "name is NULL or empty");
  ldimesh::ScalarType t;
  if (!scalar_type(type, t))
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "type must be LDIMESH_FLOAT32 or LDIMESH_FLOAT64");
  if (a->block_values == 0)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what +
                    "no block added yet, or the last one was refused (the field belongs to "
                    "the block added last)");
  if (value_count < a->block_values)
    return fail(a, LDIMESH_ERROR_ARGUMENT,
                what + "field '" + name + "': the array holds " + std::to_string(value_count) +
                    " values, the block reads " + std::to_string(a->block_values));
  return guarded(a, "", [&] { return a->impl->add_field(name, values, t); });
}

int ldimesh_clear_blocks(ldimesh_adaptor* a) {
  if (!a) return no_handle();
  a->block_values = 0;
  return guarded(a, "ldimesh_clear_blocks: ", [&] {
    a->impl->clear_blocks();
    return Status::ok();
  });
}

int ldimesh_execute(ldimesh_adaptor* a, uint64_t step, double time) {
  if (!a) return no_handle();
  return guarded(a, "ldimesh_execute: ", [&] { return a->impl->execute(step, time); });
}

int ldimesh_finalize(ldimesh_adaptor* a) {
  if (!a) return no_handle();
  return guarded(a, "ldimesh_finalize: ", [&] { return a->impl->finalize(); });
}

void ldimesh_destroy(ldimesh_adaptor* a) {
  if (!a) return;
  try {
    a->impl->finalize();
  } catch (...) {
  }
  delete a;
}

const char* ldimesh_last_error(const ldimesh_adaptor* a) {
  return a ? a->error.c_str() : create_error.c_str();
}

int ldimesh_set_error(ldimesh_adaptor* a, const char* message) {
  if (!a) return no_handle();
  return fail(a, LDIMESH_ERROR_ARGUMENT, message ? message : "");
}

const char* ldimesh_url(const ldimesh_adaptor* a) {
  return a ? a->url.c_str() : "";
}

uint64_t ldimesh_published_steps(const ldimesh_adaptor* a) {
  return a ? a->impl->published_steps() : 0;
}

int ldimesh_last_report(const ldimesh_adaptor* a, ldimesh_step_report* out) {
  if (!a) return no_handle();
  if (!out) return LDIMESH_ERROR_ARGUMENT;
  const ldimesh::StepReport& r = a->impl->last_report();
  out->step = r.step;
  out->executed = r.executed ? 1 : 0;
  out->skipped_busy = r.skipped_busy ? 1 : 0;
  out->replaced_pending = r.replaced_pending ? 1 : 0;
  out->blocked_seconds = r.blocked_seconds;
  out->max_blocked_seconds = r.max_blocked_seconds;
  out->nonfinite_values = r.nonfinite_values;
  out->background = r.background ? 1 : 0;
  out->snapshot_bytes = r.snapshot_bytes;
  return LDIMESH_OK;
}

}  // extern "C"
