// libFuzzer target for decode_glb (scripts/fuzz.sh glb builds and runs it with ASan and UBSan):
// what ldimesh-fetch and `ldimesh distance` read may come from anywhere. Any input must be
// decoded or refused without a crash, an out-of-bounds read or undefined behaviour; refused,
// the output mesh is unchanged; accepted, the mesh is well formed (check_mesh with finite
// values, one view per face; scalars finite, or NaN at the vertices of primitives without
// _SCALAR) and encode_glb takes it (its contract for any well-formed mesh; without the scalars
// where some are NaN).
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes a seed corpus of encode_glb's output
// into DIR and exits: with and without scalars and views, sequential and Edgebreaker
// connectivity, two surfaces of which one has _SCALAR, and an empty mesh.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/transport/glb.hpp"

#include "fuzz_seeds.hpp"

namespace {

// An octahedron of unit normals; with views, each face in the view of its z sign (else all in
// view 0: encode_glb takes one view per face).
ldimesh::Mesh octahedron(bool scalars, bool views) {
  ldimesh::Mesh m;
  m.positions = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  m.normals = m.positions;
  m.triangles = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
  if (scalars) m.scalars = {0.0f, 0.2f, 0.4f, 0.6f, 0.8f, 1.0f};
  m.triangle_view.assign(8, 0);
  if (views) {
    m.view_dirs = {{0, 0, 1}, {0, 0, -1}};
    m.triangle_view = {0, 0, 0, 0, 1, 1, 1, 1};
  }
  return m;
}

void write_seed(const std::string& path, const ldimesh::Mesh& mesh,
                const ldimesh::GlbOptions& options) {
  std::vector<std::uint8_t> glb;
  if (ldimesh::Status s = ldimesh::encode_glb(mesh, options, glb); !s) {
    std::fprintf(stderr, "fuzz: encode_glb failed: %s\n", s.message().c_str());
    std::exit(1);
  }
  ldimesh::fuzz::write_file(path, glb);
}

}  // namespace

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  ldimesh::GlbOptions sequential;
  sequential.compression_level = 0;
  write_seed(dir + "/seed-plain.glb", octahedron(false, false), {});
  write_seed(dir + "/seed-scalar-views.glb", octahedron(true, true), {});
  write_seed(dir + "/seed-sequential.glb", octahedron(true, true), sequential);
  // Two surfaces, the first coloured, the second not ("colour_by" per isovalue).
  ldimesh::Mesh two = octahedron(true, false), inner = octahedron(true, false);
  for (glm::vec3& p : inner.positions)
    p *= 0.5f;
  ldimesh::append_mesh(two, inner);
  ldimesh::GlbOptions mixed;
  mixed.surfaces = {0, 6};
  mixed.scalar_groups = {0, -1};
  write_seed(dir + "/seed-mixed-scalar.glb", two, mixed);
  write_seed(dir + "/seed-empty.glb", ldimesh::Mesh{}, {});
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  ldimesh::Mesh mesh;
  mesh.positions = {{7, 7, 7}};  // a marker: refused input must leave it
  if (!ldimesh::decode_glb({data, size}, mesh)) {
    if (mesh.positions.size() != 1 || mesh.positions[0].x != 7.0f) __builtin_trap();
    return 0;
  }
  // NaN where a primitive has no _SCALAR (never ±Inf); re-encoded without the scalars then.
  bool nan = false;
  for (const float x : mesh.scalars) {
    if (std::isinf(x)) __builtin_trap();
    nan = nan || std::isnan(x);
  }
  if (nan) mesh.scalars.clear();
  if (!ldimesh::check_mesh(mesh, {.views_per_face = true, .finite = true})) __builtin_trap();
  std::vector<std::uint8_t> again;
  if (!ldimesh::encode_glb(mesh, {}, again)) __builtin_trap();
  return 0;
}
