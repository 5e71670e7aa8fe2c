/* ldimesh-heat-c: a heat-equation solver in C that links the adaptor through its C API
 * (ldimesh.h), as a C code would. miniapps/fortran/heat.f90 is the same solver in Fortran:
 * both compute bit-identical fields and publish identical meshes (tests/miniapps).
 *
 * ∂u/∂t = ∇²u on N³ points over [0, 1]³, u = 0 on the boundary, explicit Euler with the
 * 7-point Laplacian in grid units and dt = 0.15 (stable below 1/6), `--substeps` solver steps
 * per output step. Initially three Gaussian blobs; the isosurface u = 0.5 (the adaptor's
 * default isovalue) shows three spheres that swell, merge and shrink until the heat has
 * spread and no surface is left.
 *
 * Slab decomposition along z: rank r owns the point layers [z0, z1) and stores them with two
 * halo layers on each side (MPI_Sendrecv after every solver step): the Laplacian reads one, the
 * adaptor's normals the second (central differences at the rank's edge, as one process computes
 * them: the same mesh on any number of ranks; docs/adaptor.md). The block handed over is the
 * owned layers plus the halo layers below (ghost_lo = 2) and above (ghost_hi = 2) where a
 * neighbour is; at the domain boundary no ghost.
 *
 * Usage: mpiexec -n R ldimesh-heat-c [--size N] [--steps S] [--substeps K] [--options FILE]
 *                                    [--poison-step S]
 * --poison-step S writes a NaN into one point of the last rank's field during output step S
 * only (restored after it), to show how the adaptor reports non-finite values.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mpi.h>

#include "ldimesh.h"

static const char* kName = "ldimesh-heat-c";

typedef struct {
  long size, steps, substeps, poison_step;
  const char* options;
} Args;

/* Parses the command line; returns 0, or the exit code (1: usage). */
static int parse(int argc, char** argv, int rank, Args* args) {
  args->size = 48;
  args->steps = 40;
  args->substeps = 5;
  args->poison_step = 0;
  args->options = "";
  for (int i = 1; i < argc; ++i) {
    long* target = NULL;
    if (strcmp(argv[i], "--help") == 0) {
      if (rank == 0)
        printf(
            "usage: %s [--size N] [--steps S] [--substeps K] [--options FILE] "
            "[--poison-step S]\n",
            kName);
      return -1;
    }
    if (i + 1 >= argc) {
      if (rank == 0) fprintf(stderr, "%s: %s needs a value\n", kName, argv[i]);
      return 1;
    }
    if (strcmp(argv[i], "--options") == 0) {
      args->options = argv[++i];
      continue;
    }
    if (strcmp(argv[i], "--size") == 0)
      target = &args->size;
    else if (strcmp(argv[i], "--steps") == 0)
      target = &args->steps;
    else if (strcmp(argv[i], "--substeps") == 0)
      target = &args->substeps;
    else if (strcmp(argv[i], "--poison-step") == 0)
      target = &args->poison_step;
    if (!target) {
      if (rank == 0) fprintf(stderr, "%s: unknown argument %s (see --help)\n", kName, argv[i]);
      return 1;
    }
    char* end = NULL;
    *target = strtol(argv[++i], &end, 10);
    if (*end != '\0' || *target < 0) {
      if (rank == 0) fprintf(stderr, "%s: %s: not a number: %s\n", kName, argv[i - 1], argv[i]);
      return 1;
    }
  }
  if (args->size < 4 || args->steps < 1 || args->substeps < 1) {
    if (rank == 0) fprintf(stderr, "%s: --size must be ≥ 4, --steps and --substeps ≥ 1\n", kName);
    return 1;
  }
  return 0;
}

/* The initial temperature at grid point (i, j, k): three Gaussian blobs. */
static double initial(long n, long i, long j, long k) {
  static const double centres[3][3] = {{0.35, 0.4, 0.45}, {0.65, 0.45, 0.55}, {0.5, 0.68, 0.5}};
  const double h = 1.0 / (double)(n - 1);
  const double x = (double)i * h, y = (double)j * h, z = (double)k * h;
  double u = 0.0;
  for (int b = 0; b < 3; ++b) {
    const double dx = x - centres[b][0], dy = y - centres[b][1], dz = z - centres[b][2];
    u = u + exp(-(dx * dx + dy * dy + dz * dz) / 0.02);
  }
  return u;
}

/* Fills the two halo layers on each side of `u` (`layers` layers of `plane` values) from the
 * neighbours' two owned layers next to them (MPI_PROC_NULL: none; tags `tag` and `tag` + 1). */
static void exchange_halo(double* u, long layers, long plane, int below, int above, int tag) {
  const int count = (int)(2 * plane);
  MPI_Sendrecv(u + (layers - 4) * plane, count, MPI_DOUBLE, above, tag, u, count, MPI_DOUBLE, below,
               tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  MPI_Sendrecv(u + 2 * plane, count, MPI_DOUBLE, below, tag + 1, u + (layers - 2) * plane, count,
               MPI_DOUBLE, above, tag + 1, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
}

int main(int argc, char** argv) {
  int provided = 0, rank = 0, size = 1;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  Args args;
  int rc = parse(argc, argv, rank, &args);
  if (rc != 0) {
    MPI_Finalize();
    return rc < 0 ? 0 : rc;
  }
  const long n = args.size;
  if (n < 2 * size) {
    if (rank == 0) fprintf(stderr, "%s: --size must be at least 2 × ranks\n", kName);
    MPI_Finalize();
    return 1;
  }
  const long z0 = rank * n / size, z1 = (rank + 1) * n / size;
  const long layers = z1 - z0 + 4; /* owned + two halo layers each side */
  const long plane = n * n;
  double* u = calloc((size_t)(layers * plane), sizeof(double));
  double* v = calloc((size_t)(layers * plane), sizeof(double));
  if (!u || !v) {
    fprintf(stderr, "%s: rank %d: out of memory\n", kName, rank);
    MPI_Abort(MPI_COMM_WORLD, 1); /* the solver's own decision, not the adaptor's */
  }
  /* Local layer l holds global layer z0 - 2 + l. */
  for (long l = 0; l < layers; ++l) {
    const long k = z0 - 2 + l;
    if (k < 0 || k >= n) continue;
    for (long j = 0; j < n; ++j)
      for (long i = 0; i < n; ++i)
        u[l * plane + j * n + i] = initial(n, i, j, k);
  }
  /* u = 0 on the boundary, kept so by never updating it. */
  for (long l = 0; l < layers; ++l)
    for (long j = 0; j < n; ++j)
      for (long i = 0; i < n; ++i) {
        const long k = z0 - 2 + l;
        if (i == 0 || j == 0 || i == n - 1 || j == n - 1 || k <= 0 || k >= n - 1)
          u[l * plane + j * n + i] = 0.0;
      }
  memcpy(v, u, (size_t)(layers * plane) * sizeof(double));
  const int below = rank > 0 ? rank - 1 : MPI_PROC_NULL;
  const int above = rank < size - 1 ? rank + 1 : MPI_PROC_NULL;

  if (rank == 0) printf("%s: %ld³ points on %d ranks, %ld steps\n", kName, n, size, args.steps);
  ldimesh_adaptor* insitu = NULL;
  if (ldimesh_create_from_file(MPI_COMM_WORLD, args.options, &insitu) != LDIMESH_OK) {
    /* Every rank gets the same verdict: a configuration error stops the run before it starts. */
    if (rank == 0)
      fprintf(stderr, "%s: in situ adaptor not created: %s\n", kName, ldimesh_last_error(NULL));
    free(u);
    free(v);
    MPI_Finalize();
    return 2;
  }
  if (rank == 0) {
    const char* url = ldimesh_url(insitu);
    printf("viewer: %s\n", url[0] ? url : "none (server disabled)");
    fflush(stdout);
  }
  const double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {1.0, 1.0, 1.0};
  if (ldimesh_set_domain(insitu, lo, hi) != LDIMESH_OK && rank == 0)
    fprintf(stderr, "%s: set_domain: %s\n", kName, ldimesh_last_error(insitu));

  /* The block: from the halo layers below (a neighbour there) or the first owned layer, to the
   * halo layers above (a neighbour there) or the last owned layer. */
  const long first = below != MPI_PROC_NULL ? 0 : 2;
  const long last = above != MPI_PROC_NULL ? layers - 1 : layers - 3;
  const double h = 1.0 / (double)(n - 1);
  const double dt = 0.15;
  for (long step = 1; step <= args.steps; ++step) {
    for (long s = 0; s < args.substeps; ++s) {
      exchange_halo(u, layers, plane, below, above, 0);
      for (long l = 2; l < layers - 2; ++l) {
        const long k = z0 - 2 + l;
        if (k <= 0 || k >= n - 1) continue;
        for (long j = 1; j < n - 1; ++j)
          for (long i = 1; i < n - 1; ++i) {
            const long p = l * plane + j * n + i;
            const double lap = (u[p - 1] + u[p + 1]) + (u[p - n] + u[p + n]) +
                               (u[p - plane] + u[p + plane]) - 6.0 * u[p];
            v[p] = u[p] + dt * lap;
          }
      }
      double* t = u;
      u = v;
      v = t;
    }
    /* The halo layers of the new field for the block's ghost layers. */
    exchange_halo(u, layers, plane, below, above, 2);

    /* u now points at the other buffer: describe the block anew (a pointer, no copy). */
    ldimesh_grid_block block;
    ldimesh_grid_block_init(&block);
    block.dims[0] = n;
    block.dims[1] = n;
    block.dims[2] = last - first + 1;
    block.values = u + first * plane;
    block.value_count = (layers - first) * plane;
    block.type = LDIMESH_FLOAT64;
    block.origin[2] = (double)(z0 - 2 + first) * h;
    for (int a = 0; a < 3; ++a)
      block.spacing[a] = h;
    block.ghost_lo[2] = below != MPI_PROC_NULL ? 2 : 0;
    block.ghost_hi[2] = above != MPI_PROC_NULL ? 2 : 0;
    ldimesh_clear_blocks(insitu);
    if (ldimesh_add_grid_block(insitu, &block) != LDIMESH_OK)
      fprintf(stderr, "%s: rank %d: add_grid_block: %s\n", kName, rank, ldimesh_last_error(insitu));

    const int poison = step == args.poison_step && rank == size - 1;
    const long poisoned = (layers / 2) * plane + (n / 2) * n + n / 2;
    double saved = 0.0;
    if (poison) {
      saved = u[poisoned];
      u[poisoned] = NAN;
    }
    const double time = (double)(step * args.substeps) * dt * h * h;
    /* A failed in situ step is reported and the simulation goes on. */
    if (ldimesh_execute(insitu, (uint64_t)step, time) != LDIMESH_OK && rank == 0)
      fprintf(stderr, "%s: step %ld: in situ: %s\n", kName, step, ldimesh_last_error(insitu));
    if (poison) u[poisoned] = saved;
    ldimesh_step_report report;
    if (rank == 0 && ldimesh_last_report(insitu, &report) == LDIMESH_OK &&
        report.nonfinite_values > 0)
      printf("%s: step %ld: the field held %llu non-finite values\n", kName, step,
             (unsigned long long)report.nonfinite_values);
  }
  if (ldimesh_finalize(insitu) != LDIMESH_OK && rank == 0)
    fprintf(stderr, "%s: in situ finalize: %s\n", kName, ldimesh_last_error(insitu));
  if (rank == 0)
    printf("%s: done, %ld steps, %llu published\n", kName, args.steps,
           (unsigned long long)ldimesh_published_steps(insitu));
  ldimesh_destroy(insitu);
  free(u);
  free(v);
  MPI_Finalize();
  return 0;
}
