// libFuzzer target for parse_ply (scripts/fuzz.sh ply builds and runs it with ASan and UBSan).
// Any input must be read or refused without a crash, an out-of-bounds read or undefined
// behaviour; a mesh the reader accepts must be well formed (check_mesh with finite values:
// indices in range, one normal per vertex), which is what every later stage relies on.
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes a seed corpus into DIR and exits:
// write_ply's own output (binary, with views and normals), and hand-written ASCII and
// big-endian files with quads, polygons, extra elements and properties, no normals.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/io/mesh_io.hpp"

#include "fuzz_seeds.hpp"

namespace {

// A tetrahedron with two views and a quad, as the mesher hands meshes to write_ply.
ldimesh::Mesh small_mesh() {
  ldimesh::Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}};
  m.normals = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.6f, 0.8f, 0}};
  m.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2};
  m.quads = {1, 2, 3, 4};
  m.triangle_view = {0, 1, 1};
  m.quad_view = {0};
  m.view_dirs = {{1, 0, 0}, {0, 0, -1}};
  return m;
}

}  // namespace

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  if (ldimesh::Status s = ldimesh::write_ply(dir + "/seed-write-ply.ply", small_mesh()); !s) {
    std::fprintf(stderr, "fuzz: write_ply failed: %s\n", s.message().c_str());
    std::exit(1);
  }
  write_file(dir + "/seed-ascii.ply",
             "ply\nformat ascii 1.0\ncomment a square and a pentagon\nelement vertex 6\n"
             "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
             "element face 2\nproperty list uchar int vertex_indices\nproperty int flags\n"
             "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
             "0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n0.5 1.5 0 5\n-0.5 0.5 1 6\n"
             "4 0 1 2 3 7\n5 0 3 4 2 5 8\n0 1\n");
  // Big-endian: one triangle, double coordinates, ushort list sizes.
  std::string be =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\n"
      "property double y\nproperty double z\nelement face 1\n"
      "property list ushort uint vertex_index\nend_header\n";
  const double coords[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  for (double c : coords) {
    unsigned char b[8];
    std::memcpy(b, &c, 8);
    for (int k = 7; k >= 0; --k)
      be.push_back(char(b[k]));
  }
  be += std::string("\0\3", 2);
  for (unsigned v : {0u, 1u, 2u})
    be += std::string{char(0), char(0), char(0), char(v)};
  write_file(dir + "/seed-big-endian.ply", be);
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  ldimesh::Mesh mesh;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  if (!ldimesh::parse_ply(bytes, mesh)) {
    if (mesh.vertex_count() != 0 || mesh.face_count() != 0) __builtin_trap();  // left empty
    return 0;
  }
  if (!ldimesh::check_mesh(mesh, {.finite = true})) __builtin_trap();
  return 0;
}
