// The adaptor over a solver's own partition of a mixed mesh: cells of every shape dealt to the
// ranks one by one, as an unstructured partition may put neighbours anywhere, publish the bytes
// one process publishes with all of them.
#include <mpi.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../mpi/mpi_gtest.hpp"
#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "published_step.hpp"

namespace ldimesh {
namespace {

using testing::rank_of;
using testing::ranks;

// The linear cells of one shape, in VTK's vertex order, with u = |x|² at the vertices.
struct Cells {
  CellType type;
  std::vector<double> points, values;
  std::size_t count = 0;
  void add(std::initializer_list<glm::dvec3> corners) {
    for (const glm::dvec3& x : corners) {
      points.insert(points.end(), {x.x, x.y, x.z});
      values.push_back(glm::dot(x, x));
    }
    ++count;
  }
};

// The cube [−1, 1]³ of n³ subcubes, every fourth cell (in the mesh's order, counted over all
// shapes) to each of `parts` parts, this rank's `part`: hexahedra in the columns with i + j even;
// in the others, along z, two wedges cut by the diagonal plane through (i, j) and (i + 1, j + 1),
// then six pyramids around the subcube's centre whose bottom and top ones are cut again into
// two tetrahedra along that diagonal (conforming: the mixed mesh of ldimesh-dealii --cells
// mixed). Many pixel rays lie in the diagonal faces, and u = |x|² interpolated linearly is only
// C⁰: the cells on either side of a face find its roots with different normals.
std::array<Cells, 4> mixed_cube(int n, int part, int parts) {
  std::array<Cells, 4> out{Cells{CellType::hexahedron, {}, {}}, Cells{CellType::wedge, {}, {}},
                           Cells{CellType::pyramid, {}, {}}, Cells{CellType::tetrahedron, {}, {}}};
  int index = 0;
  const auto deal = [&](int shape, std::initializer_list<glm::dvec3> corners) {
    if (index++ % parts == part) out[std::size_t(shape)].add(corners);
  };
  const double h = 2.0 / n;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        glm::dvec3 c[8];  // c[a + 2b + 4c]: the corner (i + a, j + b, k + c)
        for (int m = 0; m < 8; ++m)
          c[m] = glm::dvec3(-1.0) + h * glm::dvec3(i + (m & 1), j + (m >> 1 & 1), k + (m >> 2));
        const glm::dvec3 centre = 0.5 * (c[0] + c[7]);
        if ((i + j) % 2 == 0) {
          deal(0, {c[0], c[1], c[3], c[2], c[4], c[5], c[7], c[6]});
        } else if (k % 2 == 0) {
          deal(1, {c[0], c[1], c[3], c[4], c[5], c[7]});
          deal(1, {c[0], c[3], c[2], c[4], c[7], c[6]});
        } else {
          deal(2, {c[0], c[2], c[6], c[4], centre});  // x = i
          deal(2, {c[1], c[5], c[7], c[3], centre});  // x = i + 1
          deal(2, {c[0], c[4], c[5], c[1], centre});  // y = j
          deal(2, {c[2], c[3], c[7], c[6], centre});  // y = j + 1
          deal(3, {c[0], c[1], c[3], centre});        // z = k, cut along c₀ c₃
          deal(3, {c[0], c[3], c[2], centre});
          deal(3, {c[4], c[7], c[5], centre});  // z = k + 1, cut along c₄ c₇
          deal(3, {c[4], c[6], c[7], centre});
        }
      }
  return out;
}

// Collective over `comm`: step 0 of the cells of `part` of `parts`, one block per shape, written
// to `dir`; the published GLB's bytes on the comm's first rank.
std::vector<std::uint8_t> publish(MPI_Comm comm, int part, int parts, const std::string& dir) {
  std::unique_ptr<Adaptor> a;
  const Status created = Adaptor::create(
      comm,
      R"({"server": {"enabled": false}, "resolution": 96, "log": false, "isovalues": [0.5625], )"
      R"("output_dir": ")" +
          dir + R"("})",
      a);
  EXPECT_TRUE(created) << created.message();
  if (!a) return {};
  EXPECT_TRUE(a->set_domain({glm::dvec3(-1.0), glm::dvec3(1.0)}));
  std::array<Cells, 4> cells = mixed_cube(8, part, parts);
  for (Cells& c : cells) {
    if (c.count == 0) continue;
    CellBlock b;
    b.type = c.type;
    b.order = 1;
    b.element_count = c.count;
    b.points = c.points.data();
    b.values = c.values.data();
    EXPECT_TRUE(a->add_cell_block(b)) << a->last_error();
  }
  EXPECT_TRUE(a->execute(0, 0.0)) << a->last_error();
  EXPECT_TRUE(a->finalize()) << a->last_error();
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  if (rank != 0) return {};
  Snapshot snapshot;
  const Status read = read_step_files(dir, 0, snapshot);
  EXPECT_TRUE(read) << read.message();
  return read && snapshot.glb ? *snapshot.glb : std::vector<std::uint8_t>{};
}

// Each rank's blocks span nearly the whole cube (their bounding boxes overlap), and roots on the
// faces between shapes and ranks are found twice: every rank keeps its cells' hits, and the
// duplicates are merged by the rule one process uses, so the step is the same to the byte.
TEST(AdaptorPartition, MixedCellsDealtOneByOnePublishTheOneProcessBytes) {
  if (ranks() == 1) GTEST_SKIP() << "one rank publishes what one process does by definition";
  const std::string base = testing::adaptor_temp_dir("ldimesh_partition", "mixed");
  const std::vector<std::uint8_t> dealt =
      publish(MPI_COMM_WORLD, rank_of(), ranks(), base + "/dealt");
  if (rank_of() != 0) return;
  const std::vector<std::uint8_t> one = publish(MPI_COMM_SELF, 0, 1, base + "/one");
  ASSERT_GT(one.size(), 10000u);
  EXPECT_TRUE(dealt == one) << "the step of " << ranks() << " ranks differs from one process's ("
                            << dealt.size() << " and " << one.size() << " bytes)";
}

}  // namespace
}  // namespace ldimesh
