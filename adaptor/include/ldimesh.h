/* The ldimesh in situ adaptor, C API (C99 and C++; the Fortran module ldimesh_mod binds it).
 *
 * The same life cycle as the C++ ldimesh::Adaptor (ldimesh/adaptor.hpp, docs/adaptor.md):
 *
 *   ldimesh_adaptor* a = NULL;
 *   if (ldimesh_create(MPI_COMM_WORLD, options_json, &a) != LDIMESH_OK)
 *     fprintf(stderr, "%s\n", ldimesh_last_error(NULL));    // the simulation goes on without it
 *   ldimesh_set_domain(a, lo, hi);
 *   ldimesh_add_grid_block(a, &block);                       // once; arrays are read in place
 *   for (step = 1; ...; ++step) { solve(); ldimesh_execute(a, step, t); }
 *   ldimesh_destroy(a);                                      // drains pending work
 *
 * Every function that can fail returns a status code (its cause: see the codes below); the
 * message is kept for ldimesh_last_error(). No function throws, aborts, exits or calls
 * MPI_Abort; a failed in situ step is skipped and the next one is tried. Every function accepts
 * a NULL adaptor, so a solver may keep calling after a failed create: those returning a code
 * return LDIMESH_ERROR_ARGUMENT, ldimesh_url gives "", ldimesh_published_steps 0,
 * ldimesh_last_error(NULL) the message of this thread's last failed create, and ldimesh_destroy
 * does nothing. Call an adaptor's functions from one thread at a time (the solver's).
 *
 * MPI must be initialised. With MPI_THREAD_MULTIPLE (MPI_Init_thread) a due step copies the
 * blocks' arrays and returns; the ray casting and the reduction run on a thread of every rank
 * (docs/adaptor.md, option "background"). With less (MPI_THREAD_FUNNELED at least) the step
 * runs synchronously and the adaptor calls MPI only from the thread that calls it; the root's
 * worker thread never calls MPI. ldimesh_create, ldimesh_execute, ldimesh_finalize and
 * ldimesh_destroy are collective over the adaptor's communicator.
 */
#ifndef LDIMESH_H
#define LDIMESH_H

#include <stddef.h>
#include <stdint.h>

#include <mpi.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Status codes, by cause, whichever function returns them; ldimesh_last_error says which. */
enum {
  LDIMESH_OK = 0,
  LDIMESH_ERROR_ARGUMENT = 1, /* a NULL or malformed argument, a wrong-size array, a block the
                                 step cannot use, a call out of order (no domain) */
  LDIMESH_ERROR_OPTIONS = 2,  /* the options document is invalid (the message names the key) */
  LDIMESH_ERROR_STEP = 3,     /* the step failed on another rank (its message is there) and was
                                 skipped here */
  LDIMESH_ERROR_RUNTIME = 4,  /* an internal error: a bug, please report it with the message */
  LDIMESH_ERROR_CORRUPT = 5,  /* data failed validation (a message between ranks, a file) */
  LDIMESH_ERROR_IO = 6,       /* a file, folder, socket or port could not be used */
  LDIMESH_ERROR_MEMORY = 7    /* out of memory */
};

/* Element types of the solver's arrays. */
enum { LDIMESH_FLOAT32 = 0, LDIMESH_FLOAT64 = 1 };

/* Node sets of high-order elements. */
enum {
  LDIMESH_NODES_GLL = 0,       /* Gauss–Lobatto–Legendre (spectral elements) */
  LDIMESH_NODES_GL = 1,        /* Gauss–Legendre (DG) */
  LDIMESH_NODES_EQUISPACED = 2 /* evenly spaced, both ends (Lagrange finite elements) */
};

/* Node order within an element (ldimesh_hex_block.ordering). */
enum {
  LDIMESH_ORDER_LEXICOGRAPHIC = 0, /* node (i, j, k) at i + (n+1)(j + (n+1)k): ξ fastest */
  LDIMESH_ORDER_VTK = 1            /* VTK_LAGRANGE_HEXAHEDRON's (deal.II's DataOut, .vtu files) */
};

typedef struct ldimesh_adaptor ldimesh_adaptor;

/* One rank-local block of point data (ldimesh::GridBlock). Initialise with
 * ldimesh_grid_block_init(), then set at least dims, values and value_count. */
typedef struct ldimesh_grid_block {
  int64_t dims[3];    /* points per axis, ghost layers included */
  const void* values; /* read in place at every due step */
  /* How many values the array holds: the block must fit in it (a wrong-size array is an
   * error, not a read past its end). */
  int64_t value_count;
  int type;           /* LDIMESH_FLOAT32 or LDIMESH_FLOAT64 */
  int64_t strides[3]; /* values between neighbouring points per axis; 0,0,0: x fastest */
  double origin[3];   /* uniform grid: point (i,j,k) at origin + (i,j,k)·spacing */
  double spacing[3];
  const double* coords[3]; /* rectilinear grid instead, when all three are set: dims[a] each */
  int ghost_lo[3];         /* ghost point layers below / above (owned by neighbours) */
  int ghost_hi[3];
} ldimesh_grid_block;

/* A rank-local block of hexahedral elements of order p (ldimesh::HexBlock). The values are read
 * at every due step and may change between steps; the corners and geometry nodes are prepared
 * when the block is added and must not change while it is added (ldimesh_clear_blocks and add
 * it again to move the mesh). */
typedef struct ldimesh_hex_block {
  int order; /* 1..8 */
  int nodes; /* LDIMESH_NODES_* */
  int64_t element_count;
  const double* corners;  /* 8 corners × (x, y, z) per element (docs/adaptor.md) */
  const void* values;     /* (p+1)³ nodal values per element, ξ fastest */
  int64_t value_count;    /* values the array holds */
  int type;               /* LDIMESH_FLOAT32 or LDIMESH_FLOAT64 */
  int64_t element_stride; /* values between elements; 0: (p+1)³ */
  /* Curved elements (optional): geometry of order q = geometry_order (1..8, independent of p),
     (q+1)³ nodes × (x, y, z) per element at the node set `nodes`, ξ fastest; corners is then
     not read. geometry_count: the doubles the array holds, at least 3 (q+1)³ element_count.
     0: the corners describe the elements (affine or trilinear). */
  int geometry_order;
  const double* geometry;
  int64_t geometry_count;
  int ordering; /* LDIMESH_ORDER_*: of the values and the geometry nodes (not the corners) */
} ldimesh_hex_block;

/* Cell types of ldimesh_cell_block (ldimesh::CellType), each in VTK's node order. */
enum {
  LDIMESH_CELL_HEXAHEDRON = 0,   /* Lagrange Q_p: VTK_HEXAHEDRON (p=1), VTK_TRIQUADRATIC_HEXAHEDRON
                                    (2),   VTK_LAGRANGE_HEXAHEDRON */
  LDIMESH_CELL_HEXAHEDRON20 = 1, /* VTK_QUADRATIC_HEXAHEDRON (p=2, 20 nodes) */
  LDIMESH_CELL_TETRAHEDRON = 2,  /* P_p: VTK_TETRA (1), VTK_QUADRATIC_TETRA (2),
                                    VTK_LAGRANGE_TETRAHEDRON */
  LDIMESH_CELL_WEDGE = 3,        /* P_p x P_p: VTK_WEDGE (1), VTK_BIQUADRATIC_QUADRATIC_WEDGE (2),
                                    VTK_LAGRANGE_WEDGE */
  LDIMESH_CELL_WEDGE15 = 4,      /* VTK_QUADRATIC_WEDGE (p=2, 15 nodes) */
  LDIMESH_CELL_PYRAMID = 5,      /* VTK_PYRAMID (p=1, 5 nodes), VTK_QUADRATIC_PYRAMID (2, 13) */
  LDIMESH_CELL_PYRAMID14 = 6     /* gmsh's 14-node pyramid (p=2): VTK_QUADRATIC_PYRAMID's 13
                                    nodes, then the base's centre */
};

/* A rank-local block of cells of one type and order (ldimesh::CellBlock): a mixed mesh is one
 * block per type and order. Geometry and field share the nodes (isoparametric) unless
 * geometry_order names the points' own order. The values are
 * read at every due step and may change between steps; the points are prepared when the block is
 * added and must not change while it is added. */
typedef struct ldimesh_cell_block {
  int cell_type; /* LDIMESH_CELL_* */
  int order;     /* 1..8 for hexahedra, tetrahedra and wedges; 2 for the 20- and 15-node cells
                    and the 14-node pyramid; 1 or 2 for pyramids */
  int64_t element_count;
  const double* points;   /* the cell's nodes × (x, y, z) per cell, VTK's node order */
  int64_t point_count;    /* doubles the array holds: at least 3 · nodes · element_count (the
                             geometry's nodes where geometry_order is set) */
  const void* values;     /* a value per node per cell */
  int64_t value_count;    /* values the array holds */
  int type;               /* LDIMESH_FLOAT32 or LDIMESH_FLOAT64 */
  int64_t element_stride; /* values between cells; 0: the node count */
  int node_order;         /* LDIMESH_CELL_ORDER_VTK (default) or LDIMESH_CELL_ORDER_GMSH: of the
                             points and values within a cell (gmsh: tetrahedra and hexahedra of
                             order 1-8, 20-node hexahedra, prisms of 6, 15, 18 nodes, pyramids of
                             5, 13, 14) */
  int geometry_order;     /* 0 (default): the points are the field's nodes (isoparametric); else
                             q = 1..8: the points are the nodes of the cell of the same shape and
                             order q (1: straight sides, the corners; for the 20-, 15- and
                             14-node cells q = 1 gives the linear hexahedron's 8, the wedge's 6 and
                             the pyramid's 5 corners), and point_count counts those nodes */
} ldimesh_cell_block;

/* ldimesh_cell_block.node_order */
enum { LDIMESH_CELL_ORDER_VTK = 0, LDIMESH_CELL_ORDER_GMSH = 1 };

/* What the last ldimesh_execute did on this rank. */
typedef struct ldimesh_step_report {
  uint64_t step;
  int executed;               /* 1: the step ran (cast and reduced) */
  int skipped_busy;           /* 1: skipped, the root was still busy ("busy": "skip") */
  int replaced_pending;       /* 1: replaced a waiting step ("busy": "coalesce") */
  double blocked_seconds;     /* this rank's time inside ldimesh_execute */
  double max_blocked_seconds; /* the slowest rank's (root only) */
  uint64_t nonfinite_values;  /* NaN/Inf field values met on all ranks (root only; synchronous
                                 path) */
  int background;             /* 1: snapshotted, cast and reduced on the caster thread */
  uint64_t snapshot_bytes;    /* what this rank's copy of its blocks holds (background path) */
} ldimesh_step_report;

/* Collective. Creates the adaptor from a JSON options document ("" or NULL: defaults). On
 * failure *out is NULL and ldimesh_last_error(NULL) tells why, on every rank. */
int ldimesh_create(MPI_Comm comm, const char* options_json, ldimesh_adaptor** out);
/* The same with the options read from a file; path NULL or "": the file named by the
 * environment variable LDIMESH_OPTIONS, or defaults when unset. */
int ldimesh_create_from_file(MPI_Comm comm, const char* path, ldimesh_adaptor** out);
/* The same with a Fortran communicator handle (MPI_Comm_f2c); for the Fortran module. */
int ldimesh_create_fortran(MPI_Fint comm, const char* options_json, ldimesh_adaptor** out);
int ldimesh_create_from_file_fortran(MPI_Fint comm, const char* path, ldimesh_adaptor** out);

/* Fills `block` with the defaults: everything zero, float64, spacing 1. */
void ldimesh_grid_block_init(ldimesh_grid_block* block);
void ldimesh_hex_block_init(ldimesh_hex_block* block);
/* Everything zero, float64, LDIMESH_CELL_TETRAHEDRON of order 1. */
void ldimesh_cell_block_init(ldimesh_cell_block* block);

/* The global domain [lo, hi] the views cover, the same on every rank. */
int ldimesh_set_domain(ldimesh_adaptor* a, const double lo[3], const double hi[3]);
/* Adds one block of this rank's data; checked here (sizes, dims, strides). */
int ldimesh_add_grid_block(ldimesh_adaptor* a, const ldimesh_grid_block* block);
int ldimesh_add_hex_block(ldimesh_adaptor* a, const ldimesh_hex_block* block);
int ldimesh_add_cell_block(ldimesh_adaptor* a, const ldimesh_cell_block* block);
/* A further named field of the block added last (temperature beside density), read in place like
 * its values and in their layout (a grid: the same dims and strides; elements: the same nodes and
 * element_stride), of `type` LDIMESH_FLOAT32 or LDIMESH_FLOAT64; value_count as for the block.
 * With option "colour_by": "NAME" the isosurfaces are coloured by the field of that name, which
 * every block must then have ("colour_by": [a name or null per isovalue]: each isosurface by its
 * own field, or by none). Adding a name again replaces that field. */
int ldimesh_add_field(ldimesh_adaptor* a, const char* name, const void* values, int64_t value_count,
                      int type);
/* Forgets this rank's blocks (to describe them anew). */
int ldimesh_clear_blocks(ldimesh_adaptor* a);

/* Collective. Runs the in situ step if it is due (options "cadence"). */
int ldimesh_execute(ldimesh_adaptor* a, uint64_t step, double time);
/* Collective. Waits for the root's pending work and stops the server. Returns the error of
 * the last failed background step, if any. */
int ldimesh_finalize(ldimesh_adaptor* a);
/* Collective. Finalizes if not done and frees the adaptor; NULL is fine. */
void ldimesh_destroy(ldimesh_adaptor* a);

/* The message of the last error on this adaptor ("" if none); with NULL, of the last failed
 * create on this thread. Valid until the next call on the same adaptor (or thread). */
const char* ldimesh_last_error(const ldimesh_adaptor* a);
/* Keeps `message` as the adaptor's last error and returns LDIMESH_ERROR_ARGUMENT (for
 * bindings that check arguments themselves, such as the Fortran module). */
int ldimesh_set_error(ldimesh_adaptor* a, const char* message);
/* Root: the viewer's URL with its token ("" elsewhere, or without a server). */
const char* ldimesh_url(const ldimesh_adaptor* a);
/* Root: steps published so far. */
uint64_t ldimesh_published_steps(const ldimesh_adaptor* a);
int ldimesh_last_report(const ldimesh_adaptor* a, ldimesh_step_report* out);

#ifdef __cplusplus
}
#endif

#endif /* LDIMESH_H */
