// A C++ program that links the installed adaptor: each rank hands over one curved hexahedron
// (geometry of order 2, a field of order 4 in VTK's Lagrange order would do as well; here
// lexicographic) of the shell 1 ≤ r ≤ 2 around the x axis, the field r² − 2.25, and publishes
// `steps` steps of the isosurface r = 1.5. Usage: mpiexec -n R consumer-cxx OPTIONS_JSON STEPS;
// exits 0 when every step was published.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <mpi.h>

#include "ldimesh/adaptor.hpp"

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  if (argc != 3) {
    if (rank == 0) std::fprintf(stderr, "usage: consumer-cxx OPTIONS_JSON STEPS\n");
    MPI_Finalize();
    return 1;
  }
  const int steps = std::atoi(argv[2]);
  std::unique_ptr<ldimesh::Adaptor> adaptor;
  if (ldimesh::Status s = ldimesh::Adaptor::create(MPI_COMM_WORLD, argv[1], adaptor); !s) {
    std::fprintf(stderr, "consumer-cxx: %s\n", s.message().c_str());
    MPI_Finalize();
    return 1;
  }
  // Rank r's element: x ∈ [r, r + 1] along the axis, polar angle [0, π/2] in the y–z plane,
  // radius [1, 2]; geometry nodes (q = 2) at ξ ∈ {0, ½, 1} on the true circles.
  const int q = 2, p = 4;
  const double pi = std::acos(-1.0);
  std::vector<double> geometry, values;
  const auto point = [&](double u, double v, double w) {
    const double phi = 0.5 * pi * v, radius = 1.0 + w;
    return std::vector<double>{rank + u, radius * std::cos(phi), radius * std::sin(phi)};
  };
  for (int k = 0; k <= q; ++k)
    for (int j = 0; j <= q; ++j)
      for (int i = 0; i <= q; ++i) {
        const std::vector<double> x = point(double(i) / q, double(j) / q, double(k) / q);
        geometry.insert(geometry.end(), x.begin(), x.end());
      }
  // The field at the field's GLL nodes of order 4: r² − 2.25 depends on the radius only, which
  // is linear in ζ.
  const double gll4[5] = {0.0, 0.5 - std::sqrt(21.0) / 14.0, 0.5, 0.5 + std::sqrt(21.0) / 14.0,
                          1.0};
  for (int k = 0; k <= p; ++k)
    for (int j = 0; j <= p; ++j)
      for (int i = 0; i <= p; ++i) {
        const double radius = 1.0 + gll4[k];
        values.push_back(radius * radius - 2.25);
      }
  ldimesh::HexBlock block;
  block.order = p;
  block.element_count = 1;
  block.values = values.data();
  block.geometry_order = q;
  block.geometry = geometry.data();
  int failures = 0;
  const auto check = [&](const ldimesh::Status& s, const char* what) {
    if (!s)
      std::fprintf(stderr, "consumer-cxx: rank %d: %s: %s\n", rank, what, s.message().c_str());
    failures += !s;
  };
  check(adaptor->set_domain({{0.0, -2.0, -2.0}, {double(ranks), 2.0, 2.0}}), "set_domain");
  check(adaptor->add_hex_block(block), "add_hex_block");
  for (int step = 0; step < steps; ++step)
    check(adaptor->execute(std::uint64_t(step), double(step)), "execute");
  check(adaptor->finalize(), "finalize");
  const std::uint64_t published = adaptor->published_steps();
  if (rank == 0)
    std::printf("consumer-cxx: %llu step(s) published\n", (unsigned long long)published);
  const bool ok = failures == 0 && (rank != 0 || published == std::uint64_t(steps));
  adaptor.reset();
  MPI_Finalize();
  return ok ? 0 : 1;
}
