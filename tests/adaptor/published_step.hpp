// What the adaptor tests read back: a published step's metadata and mesh from its output_dir
// files, and checks of what a viewer gets; where they write it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <gtest/gtest.h>
#include <mpi.h>

#include "../mpi/mpi_gtest.hpp"
#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh::testing {

// Whether MPI runs with MPI_THREAD_MULTIPLE (the --thread-multiple runs: the background path).
inline bool thread_multiple() {
  int level = MPI_THREAD_SINGLE;
  MPI_Query_thread(&level);
  return level >= MPI_THREAD_MULTIPLE;
}

// A fresh folder for test `name` of an adaptor test program, distinct per thread level: the
// funneled and the --thread-multiple runs may run at once.
inline std::string adaptor_temp_dir(const std::string& prefix, const std::string& name) {
  return fresh_temp_dir(thread_multiple() ? prefix + "_mt" : prefix, name);
}

// The metadata of step `step` written into `dir` (read_step_files: GLB and metadata checked);
// a test failure and empty metadata (step 0) when the files are missing or invalid.
inline StepMetadata published_step(const std::string& dir, std::uint64_t step) {
  Snapshot snapshot;
  StepMetadata meta;
  if (Status s = read_step_files(dir, step, snapshot); !s) {
    ADD_FAILURE() << "step " << step << " in " << dir << ": " << s.message();
    return meta;
  }
  if (Status s = metadata_from_json(snapshot.metadata_json, meta); !s)
    ADD_FAILURE() << "step " << step << ": " << s.message();
  return meta;
}

// The mesh of step `step` in `dir`, decoded from its GLB; a test failure and an empty mesh when
// the files are missing or the GLB does not decode.
inline Mesh published_mesh(const std::string& dir, std::uint64_t step) {
  Snapshot snapshot;
  Mesh mesh;
  if (Status s = read_step_files(dir, step, snapshot); !s || !snapshot.glb) {
    ADD_FAILURE() << "step " << step << " in " << dir << ": " << s.message();
    return mesh;
  }
  if (Status s = decode_glb(*snapshot.glb, mesh); !s)
    ADD_FAILURE() << "step " << step << ": " << s.message();
  return mesh;
}

// The mesh of a grid's field f = |x|² over [−1, 1]³ at isovalue `iso`, as a viewer gets it:
// every vertex on the sphere |x| = √iso within what the grid and the GLB allow — the trilinear
// interpolant of the convex |x|² on cells of width h lies above it by at most 3h²/4 (h²/4 per
// axis), which moves the surface inwards by at most 3h²/(8r), never outwards; Draco's positions
// are quantized to a tenth of a pixel (the domain's side 2 over `resolution` pixels) either way.
inline void expect_on_grid_sphere(const Mesh& mesh, double iso, double h, int resolution) {
  const double r = std::sqrt(iso), inwards = 3.0 * h * h / (8.0 * r);
  const double quantization = 0.1 * 2.0 / resolution;
  ASSERT_GT(mesh.vertex_count(), 500u);
  double lo = INFINITY, hi = 0.0;
  for (const glm::vec3& p : mesh.positions) {
    const double d = glm::length(glm::dvec3(p));
    lo = std::min(lo, d), hi = std::max(hi, d);
  }
  EXPECT_GE(lo, r - inwards - quantization)
      << "a published vertex is inside the sphere |x| = " << r;
  EXPECT_LE(hi, r + quantization) << "a published vertex is outside the sphere |x| = " << r;
}

// The colour of every vertex of `mesh` that `on(position)` selects is `colour(position)` within
// the bound of expect_coloured_by, its _SCALAR u standing for range.min + u·(range.max −
// range.min).
template <class On, class Colour>
inline void expect_part_coloured_by(const Mesh& mesh, const ScalarRange& range, On on,
                                    Colour colour, double slope, double pixel,
                                    int glb_scalar_bits = StepGlbSettings{}.scalar_bits) {
  ASSERT_EQ(mesh.scalars.size(), mesh.vertex_count());
  const double span = range.max - range.min;
  const double bound = 3.0 * slope * 0.1 * pixel + span / (2.0 * 4094.0) +
                       span / (2.0 * double((1 << glb_scalar_bits) - 1)) + 1e-5;
  double worst = 0.0;
  std::size_t selected = 0;
  for (std::size_t v = 0; v < mesh.vertex_count(); ++v) {
    const glm::dvec3 x(mesh.positions[v]);
    if (!on(x)) continue;
    ++selected;
    const double value = range.min + double(mesh.scalars[v]) * span;
    const double err = std::abs(value - colour(x));
    if (!(err <= worst)) worst = err;  // NaN too
  }
  EXPECT_GT(selected, 300u);
  EXPECT_LT(worst, bound) << "colour of a published vertex vs the field there";
}

// Every vertex's colour is `colour(vertex)` within what the wire and the GLB allow, computed
// here from their bit budgets: positions within a tenth of a pixel (`pixel`) per axis, times the
// field's largest slope `slope` per axis; the value within half a step of 12 bits (the fragments'
// scalar_bits) and of `glb_scalar_bits` (the published GLB's _SCALAR, option glb.scalar_bits) over
// the range; and float rounding.
template <class Colour>
inline void expect_coloured_by(const Mesh& mesh, const StepMetadata& meta, const std::string& name,
                               Colour colour, double slope, double pixel,
                               int glb_scalar_bits = StepGlbSettings{}.scalar_bits) {
  ASSERT_TRUE(meta.scalar.has_value()) << "the step's metadata names no field";
  EXPECT_EQ(meta.scalar->name, name);
  ASSERT_EQ(mesh.scalars.size(), mesh.vertex_count());
  ASSERT_GT(mesh.vertex_count(), 300u);
  // The decoded scalars are the GLB's _SCALAR: 0 and 1 at the range's ends.
  const auto [lo, hi] = std::minmax_element(mesh.scalars.begin(), mesh.scalars.end());
  EXPECT_NEAR(*lo, 0.0f, 1e-6f);
  EXPECT_NEAR(*hi, 1.0f, 1e-6f);
  expect_part_coloured_by(
      mesh, *meta.scalar, [](glm::dvec3) { return true; }, colour, slope, pixel, glb_scalar_bits);
}

}  // namespace ldimesh::testing
