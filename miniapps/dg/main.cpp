// ldimesh-dg: a DG-style high-order simulation. The domain [0, 1]³ is tiled by E³ hexahedral
// elements of order p with Gauss–Lobatto–Legendre nodes; the elements are split over the ranks
// (block_grid over the element grid), and each rank keeps its elements' nodal values in one
// array, element after element: the layout of a spectral-element or DG code. The solution is
// analytic: two Gaussian blobs advected by opposite constant velocities through the periodic
// box, u(x, t) = Σ± exp(−|x − x±(t)|² / σ²) with x±(t) = x±(0) ± c t (nearest periodic image),
// sampled at the nodes every step. They approach, merge and part again: the isosurface changes
// topology. The adaptor reads the nodal array in place through a HexBlock.
//
// With --mesh shell the mesh is curved and unstructured, as a real solver's: the spherical shell
// 0.5 ≤ r ≤ 1 as a cubed sphere (6 · E² · L elements, geometry of order q at GLL nodes, every
// node on its sphere), nodes in VTK's Lagrange order (as deal.II's DataOut and FLEXI write them),
// the element list dealt to the ranks in contiguous runs (a rank's elements need not fill a box,
// and the ranks' boxes overlap). Two blobs orbit inside the shell in opposite directions, meet
// and part; --field radius puts u = |x|² there instead (its isosurfaces are spheres).
//
//   mpiexec -n 4 build/bin/ldimesh-dg --elements 8 --order 3 --steps 100
//   mpiexec -n 4 build/bin/ldimesh-dg --mesh shell --elements 4 --order 4 --steps 100
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <glm/glm.hpp>

#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/cubed_shell.hpp"
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

// Two blobs orbiting the z axis in opposite directions inside the shell, on the sphere r = 0.75
// (--mesh shell): u(x, t) = Σ± exp(−|x − x±(t)|² / σ²). They meet a quarter turn from where
// they start. --field radius: u = |x|² (steady; its isovalue r² gives the sphere of radius r).
struct ShellField {
  double sigma = 0.18;
  double angular_velocity = 1.5707963267948966;  // a quarter turn per unit of time
  bool radius = false;

  double operator()(glm::dvec3 x, double t) const {
    if (radius) return glm::dot(x, x);
    const double a = angular_velocity * t;
    const glm::dvec3 plus{0.75 * std::cos(a), 0.75 * std::sin(a), 0.12};
    const glm::dvec3 minus{-0.75 * std::cos(a), 0.75 * std::sin(a), -0.12};
    const double s2 = sigma * sigma;
    const glm::dvec3 dp = x - plus, dm = x - minus;
    return std::exp(-glm::dot(dp, dp) / s2) + std::exp(-glm::dot(dm, dm) / s2);
  }
};

// One rank's run of the shell's elements: geometry nodes and nodal values in VTK's Lagrange
// order, element after element. The field is sampled where the solver's own geometry puts its
// nodes (the order-q map through the geometry nodes), as a DG code evaluates its solution.
class ShellBlock {
 public:
  ShellBlock(const ldimesh::CubedShell& shell, int order, int geometry_order, int rank, int ranks)
      : order_(order), geometry_order_(geometry_order) {
    const std::size_t total = shell.element_count();
    const std::size_t first = total * std::size_t(rank) / std::size_t(ranks);
    count_ = total * std::size_t(rank + 1) / std::size_t(ranks) - first;
    const int q = geometry_order;
    const std::size_t gn = std::size_t(q + 1) * (q + 1) * (q + 1);
    const std::vector<double> xq =
        ldimesh::node_positions(q, ldimesh::NodeSet::gauss_lobatto_legendre);
    geometry_.resize(count_ * gn * 3);
    for (std::size_t e = 0; e < count_; ++e)
      for (int k = 0; k <= q; ++k)
        for (int j = 0; j <= q; ++j)
          for (int i = 0; i <= q; ++i) {
            const glm::dvec3 x = shell.point(first + e, {xq[i], xq[j], xq[k]});
            double* g = &geometry_[3 * (e * gn + ldimesh::vtk_lagrange_index(i, j, k, q))];
            g[0] = x.x, g[1] = x.y, g[2] = x.z;
          }
    // The field's nodes in space, through the geometry's polynomial.
    const int n = order + 1;
    const std::size_t vn = std::size_t(n) * n * n;
    values_.assign(count_ * vn, 0.0);
    positions_.resize(count_ * vn);
    if (count_ == 0) return;
    const ldimesh::HexElementSource shape(hex_block());
    const std::vector<double> xp =
        ldimesh::node_positions(order, ldimesh::NodeSet::gauss_lobatto_legendre);
    for (std::size_t e = 0; e < count_; ++e)
      for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i)
            positions_[e * vn + ldimesh::vtk_lagrange_index(i, j, k, order)] =
                shape.to_world(e, {xp[i], xp[j], xp[k]});
  }

  void sample(const ShellField& u, double t) {
    for (std::size_t m = 0; m < values_.size(); ++m)
      values_[m] = u(positions_[m], t);
  }

  ldimesh::HexBlock hex_block() const {
    ldimesh::HexBlock b;
    b.order = order_;
    b.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
    b.element_count = count_;
    b.geometry_order = geometry_order_;
    b.geometry = geometry_.data();
    b.values = values_.data();
    b.type = ldimesh::ScalarType::float64;
    b.ordering = ldimesh::NodeOrdering::vtk_lagrange;
    return b;
  }

 private:
  int order_, geometry_order_;
  std::size_t count_ = 0;
  std::vector<double> geometry_;  // (q + 1)³ nodes × (x, y, z) per element
  std::vector<double> values_;
  std::vector<glm::dvec3> positions_;  // of the field's nodes, in the values' order
};

// --mesh shell: the rank's run of the shell's elements, described once, sampled every step.
int run_shell(MiniApp& app, const CommonArgs& args, const ldimesh::CubedShell& shell, int order,
              int geometry_order, const ShellField& u, double dt) {
  if (shell.element_count() < std::size_t(app.size())) {
    app.check(ldimesh::Status::invalid_argument(
                  "the shell's " + std::to_string(shell.element_count()) +
                  " elements are fewer than the " + std::to_string(app.size()) + " ranks"),
              "start");
    return ldimesh::miniapp::kExitUsage;
  }
  // The elements' geometry is checked where the field's node positions are computed; a rank
  // that fails says so, and every rank stops (none waits in a collective for it).
  std::unique_ptr<ShellBlock> made;
  int failed = 0;
  try {
    made = std::make_unique<ShellBlock>(shell, order, geometry_order, app.rank(), app.size());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh-dg: rank %d: the shell's elements: %s\n", app.rank(), e.what());
    failed = 1;
  }
  MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, app.comm());
  if (failed) return ldimesh::miniapp::kExitUsage;
  ShellBlock& block = *made;
  block.sample(u, 0.0);
  char line[320];
  std::snprintf(line, sizeof line,
                "ldimesh-dg: shell 0.5 <= r <= 1, 6 x %d^2 x %d = %zu curved elements of order "
                "%d, geometry order %d (GLL, VTK node order), field %s, on %d ranks, %llu steps, "
                "dt=%g",
                shell.n, shell.layers, shell.element_count(), order, geometry_order,
                u.radius ? "radius" : "blobs", app.size(),
                static_cast<unsigned long long>(args.steps), dt);
  app.print(line);

  std::unique_ptr<Adaptor> adaptor;
  if (!app.create_adaptor(args, /*default_isovalue=*/u.radius ? 0.5625 : 0.5, adaptor))
    return ldimesh::miniapp::kExitOptions;
  app.check(adaptor->set_domain({{-1.0, -1.0, -1.0}, {1.0, 1.0, 1.0}}), "set_domain");
  app.check(adaptor->add_hex_block(block.hex_block()), "add_hex_block");
  app.run(*adaptor, args, [&](std::uint64_t step) {
    const double t = double(step) * dt;
    block.sample(u, t);
    return t;
  });
  return 0;
}

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
  std::string mesh = "box", field = "blobs";
  int layers = 2, geometry_order = 2;
  cli.add_option("--mesh", mesh,
                 "box: E³ straight elements tiling [0, 1]³ split into blocks; shell: the curved, "
                 "unstructured cubed-sphere shell 0.5 ≤ r ≤ 1 (6 · E² · layers elements, VTK node "
                 "order, dealt to the ranks in runs)")
      ->check(CLI::IsMember({"box", "shell"}))
      ->capture_default_str();
  cli.add_option("--layers", layers, "shell: elements through the thickness")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cli.add_option("--geometry-order", geometry_order, "shell: order q of the elements' geometry")
      ->check(CLI::Range(1, ldimesh::kMaxHexOrder))
      ->capture_default_str();
  cli.add_option("--field", field,
                 "shell: blobs (two orbiting Gaussian blobs) or radius (u = |x|², steady)")
      ->check(CLI::IsMember({"blobs", "radius"}))
      ->capture_default_str();
  if (const auto code = app.parse(cli, argc, argv)) return *code;
  if (mesh == "shell") {
    ShellField u;
    u.sigma = blobs.sigma;
    u.radius = field == "radius";
    return run_shell(app, args, ldimesh::CubedShell{elements, layers, 0.5, 1.0}, order,
                     geometry_order, u, dt);
  }

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
