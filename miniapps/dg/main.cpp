// ldimesh-dg: a DG-style high-order simulation. The domain [0, 1]³ is tiled by E³ hexahedral
// elements of order p with Gauss–Lobatto–Legendre nodes; the elements are split over the ranks
// (block_grid over the element grid), and each rank keeps its elements' nodal values in one
// array, element after element: the layout of a spectral-element or DG code. The solution is
// analytic: two Gaussian blobs advected by opposite constant velocities through the periodic
// box, u(x, t) = Σ± exp(−|x − x±(t)|² / σ²) with x±(t) = x±(0) ± c t (nearest periodic image),
// sampled at the nodes every step. They approach, merge and part again: the isosurface changes
// topology. The adaptor reads the nodal array in place through a HexBlock.
//
//   mpiexec -n 4 build/bin/ldimesh-dg --elements 8 --order 3 --steps 100
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <glm/glm.hpp>

#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "miniapp.hpp"

namespace {

using ldimesh::Adaptor;
using ldimesh::miniapp::CommonArgs;
using ldimesh::miniapp::MiniApp;

struct Blobs {
  glm::dvec3 start_plus{0.25, 0.45, 0.5}, start_minus{0.75, 0.55, 0.5};
  glm::dvec3 velocity{0.25, 0.04, 0.02};
  double sigma = 0.18;

  // The component of a − b along each axis wrapped into [−0.5, 0.5): the nearest image.
  static glm::dvec3 periodic_offset(glm::dvec3 a, glm::dvec3 b) {
    const glm::dvec3 d = a - b;
    return d - glm::floor(d + 0.5);
  }
  double operator()(glm::dvec3 x, double t) const {
    const glm::dvec3 dp = periodic_offset(x, start_plus + velocity * t);
    const glm::dvec3 dm = periodic_offset(x, start_minus - velocity * t);
    const double s2 = sigma * sigma;
    return std::exp(-glm::dot(dp, dp) / s2) + std::exp(-glm::dot(dm, dm) / s2);
  }
};

// One rank's elements: corners and nodal values, element after element.
class ElementBlock {
 public:
  ElementBlock(int elements, int order, std::array<int, 3> blocks, int rank)
      : order_(order),
        nodes_(ldimesh::node_positions(order, ldimesh::NodeSet::gauss_lobatto_legendre)) {
    const std::array<int, 3> coord{rank % blocks[0], (rank / blocks[0]) % blocks[1],
                                   rank / (blocks[0] * blocks[1])};
    std::array<int, 3> lo{}, hi{};
    for (int a = 0; a < 3; ++a) {
      lo[a] = elements * coord[a] / blocks[a];
      hi[a] = elements * (coord[a] + 1) / blocks[a];
    }
    // Element faces from one formula on every rank, so that neighbours share them exactly.
    auto face = [&](int i) { return double(i) / double(elements); };
    for (int k = lo[2]; k < hi[2]; ++k)
      for (int j = lo[1]; j < hi[1]; ++j)
        for (int i = lo[0]; i < hi[0]; ++i) {
          lower_.push_back({face(i), face(j), face(k)});
          upper_.push_back({face(i + 1), face(j + 1), face(k + 1)});
          for (int c = 0; c < 8; ++c) {
            corners_.push_back(face(i + (c & 1)));
            corners_.push_back(face(j + ((c >> 1) & 1)));
            corners_.push_back(face(k + ((c >> 2) & 1)));
          }
        }
    const std::size_t n = std::size_t(order + 1);
    values_.assign(lower_.size() * n * n * n, 0.0);
  }

  // Samples the solution at every node: node (i, j, k) of element e is value
  // i + (p + 1)(j + (p + 1) k) of the element.
  void sample(const Blobs& u, double t) {
    const int n = order_ + 1;
    std::size_t at = 0;
    for (std::size_t e = 0; e < lower_.size(); ++e) {
      const glm::dvec3 lo = lower_[e], size = upper_[e] - lower_[e];
      for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i)
            values_[at++] = u(lo + size * glm::dvec3(nodes_[i], nodes_[j], nodes_[k]), t);
    }
  }

  ldimesh::HexBlock hex_block() const {
    ldimesh::HexBlock b;
    b.order = order_;
    b.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
    b.element_count = lower_.size();
    b.corners = corners_.data();
    b.values = values_.data();
    b.type = ldimesh::ScalarType::float64;
    return b;
  }

 private:
  int order_;
  std::vector<double> nodes_;  // GLL positions on [0, 1]
  std::vector<glm::dvec3> lower_, upper_;
  std::vector<double> corners_;
  std::vector<double> values_;
};

}  // namespace

int main(int argc, char** argv) {
  MiniApp app("ldimesh-dg", argc, argv);
  CLI::App cli{"High-order hexahedral elements (GLL nodes) carrying advected Gaussian blobs"};
  CommonArgs args;
  args.steps = 100;
  int elements = 8;
  int order = 3;
  double dt = 0.02;
  Blobs blobs;
  app.add_common_options(cli, args);
  cli.add_option("--elements", elements, "elements per axis")
      ->check(CLI::Range(1, 512))
      ->capture_default_str();
  cli.add_option("--order", order, "polynomial order p of the elements")
      ->check(CLI::Range(1, ldimesh::kMaxHexOrder))
      ->capture_default_str();
  cli.add_option("--dt", dt, "time per step")->capture_default_str();
  cli.add_option("--sigma", blobs.sigma, "width of the blobs")->capture_default_str();
  if (const auto code = app.parse(cli, argc, argv)) return *code;

  const ldimesh::Box domain{{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}};
  const std::array<int, 3> blocks = ldimesh::block_grid(domain, app.size());
  for (int a = 0; a < 3; ++a) {
    if (elements < blocks[a]) {
      app.check(ldimesh::Status::invalid_argument("--elements " + std::to_string(elements) +
                                                  " is too small for " + std::to_string(blocks[a]) +
                                                  " blocks along an axis"),
                "start");
      return ldimesh::miniapp::kExitUsage;
    }
  }
  ElementBlock block(elements, order, blocks, app.rank());
  block.sample(blobs, 0.0);

  char line[256];
  std::snprintf(line, sizeof line,
                "ldimesh-dg: %d^3 elements of order %d (GLL) on %d ranks (%d x %d x %d blocks), "
                "%llu steps, dt=%g",
                elements, order, app.size(), blocks[0], blocks[1], blocks[2],
                static_cast<unsigned long long>(args.steps), dt);
  app.print(line);

  std::unique_ptr<Adaptor> adaptor;
  if (!app.create_adaptor(args, /*default_isovalue=*/0.5, adaptor))
    return ldimesh::miniapp::kExitOptions;
  app.check(adaptor->set_domain(domain), "set_domain");
  // Described once: the nodal array stays where it is and is rewritten every step.
  app.check(adaptor->add_hex_block(block.hex_block()), "add_hex_block");

  app.run(*adaptor, args, [&](std::uint64_t step) {
    const double t = double(step) * dt;
    block.sample(blobs, t);
    return t;
  });
  return 0;
}
