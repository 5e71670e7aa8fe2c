// ldimesh-grayscott: 3D Gray–Scott reaction–diffusion (Pearson 1993, "Complex patterns in a
// simple system") on a block-decomposed uniform grid, with the isosurface of V published live
// (coloured by U with option "colour_by": "U", as scripts/demo does).
//
//   ∂u/∂t = Du ∇²u − u v² + F (1 − u)        ∂v/∂t = Dv ∇²v + u v² − (F + k) v
//
// Explicit Euler, 7-point Laplacian in grid units (spacing 1 in the equations), zero-flux
// (Neumann) boundaries: the halo point outside the domain mirrors the point inside it
// (u₋₁ = u₁), which makes the boundary point's Laplacian the symmetric one. The domain is
// [0, 1]³ for the views: N points per axis at spacing 1/(N − 1).
//
// Each rank owns the points [lo, hi) of its block (block_grid over the ranks) and stores them
// with two halo points on each side, x fastest: the layout a finite-volume or finite-difference
// code hands over. The Laplacian needs one; the second lets the adaptor compute the normals at
// the rank's edge by central differences as one process would (docs/method.md, "Normals"), so
// that the published mesh is the same for any number of ranks. The adaptor reads V in place,
// halo included (see v_block).
//
//   mpiexec -n 2 build/bin/ldimesh-grayscott --size 64 --steps 200
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <mpi.h>
#include <CLI/CLI.hpp>

#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "miniapp.hpp"

namespace {

using ldimesh::Adaptor;
using ldimesh::miniapp::CommonArgs;
using ldimesh::miniapp::MiniApp;

struct Parameters {
  double F = 0.04, k = 0.06, Du = 0.16, Dv = 0.08, dt = 0.5;
  double noise = 0.01;  // relative amplitude of the seed's perturbation
};

// The value in [-1, 1) of a hash of the global point index: the seed's perturbation is the same
// whatever the decomposition, so 1 and 3 ranks compute bit-identical fields.
double hash_noise(std::uint64_t index, std::uint64_t salt) {
  std::uint64_t x = index * 0x9E3779B97F4A7C15ull + salt;
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  x ^= x >> 31;
  return double(x >> 11) * 0x1.0p-52 - 1.0;
}

// Explicit Euler with the 7-point Laplacian multiplies the grid's finest mode (the checkerboard,
// Laplacian eigenvalue −12) by 1 − 12 D dt per step: below −1 it grows without bound, below 0 it
// flips sign every step, and the field shows the grid's lattice instead of the physics (at
// dt = 1 and Du = 0.16 the factor is −0.92: U speckled). A time step is taken only where that
// factor is at least 0, dt ≤ 1 / (12 max(Du, Dv)) (0.52 at the defaults, whose dt = 0.5 leaves
// 0.04).
ldimesh::Status check_time_step(const Parameters& p) {
  const double d = std::max(p.Du, p.Dv);
  if (!(p.dt > 0.0) || !(p.Du >= 0.0) || !(p.Dv >= 0.0))
    return ldimesh::Status::invalid_argument(
        "--dt, --Du and --Dv: dt must be positive and the "
        "diffusion coefficients not negative");
  if (p.dt * 12.0 * d > 1.0) {
    // The limit rounded down to three significant digits, so that the step it names is taken.
    const double limit = 1.0 / (12.0 * d);
    const double unit = std::pow(10.0, std::floor(std::log10(limit)) - 2.0);
    char text[320];
    std::snprintf(
        text, sizeof text,
        "--dt %g is too large for explicit Euler with D = %g: the finest grid mode's "
        "factor 1 - 12 D dt = %.3g is below 0 (%s); use --dt %.3g or less "
        "(1/(12 max(Du, Dv)))",
        p.dt, d, 1.0 - 12.0 * d * p.dt,
        1.0 - 12.0 * d * p.dt < -1.0 ? "the solution blows up" : "it oscillates at the grid scale",
        std::floor(limit / unit) * unit);
    return ldimesh::Status::invalid_argument(text);
  }
  return ldimesh::Status::ok();
}

// Halo points on each side of a rank's block.
constexpr std::int64_t kHalo = 2;

// One rank's block: owned points [lo, hi) per axis, stored with kHalo halo points on each side.
class GrayScottBlock {
 public:
  GrayScottBlock(std::int64_t global, std::array<int, 3> blocks, int rank, const Parameters& p)
      : global_(global), p_(p) {
    const std::array<int, 3> coord{rank % blocks[0], (rank / blocks[0]) % blocks[1],
                                   rank / (blocks[0] * blocks[1])};
    for (int a = 0; a < 3; ++a) {
      lo_[a] = global * coord[a] / blocks[a];
      hi_[a] = global * (coord[a] + 1) / blocks[a];
      n_[a] = hi_[a] - lo_[a];
      std::array<int, 3> below = coord, above = coord;
      --below[a];
      ++above[a];
      below_[a] = coord[a] > 0 ? rank_of(below, blocks) : MPI_PROC_NULL;
      above_[a] = coord[a] + 1 < blocks[a] ? rank_of(above, blocks) : MPI_PROC_NULL;
    }
    stride_ = {1, n_[0] + 2 * kHalo, (n_[0] + 2 * kHalo) * (n_[1] + 2 * kHalo)};
    const std::size_t count = std::size_t(stride_[2] * (n_[2] + 2 * kHalo));
    for (auto* f : {&u_, &v_, &u_next_, &v_next_})
      f->assign(count, 0.0);
    for (int a = 0; a < 3; ++a)
      make_plane_type(a);
    seed();
  }

  ~GrayScottBlock() {
    for (MPI_Datatype& t : plane_)
      MPI_Type_free(&t);
  }
  GrayScottBlock(const GrayScottBlock&) = delete;
  GrayScottBlock& operator=(const GrayScottBlock&) = delete;

  // One explicit Euler step of both fields; the halos of the new fields are exchanged, so that
  // V is complete (halo included) whenever the adaptor reads it.
  void advance() {
    const std::int64_t sy = stride_[1], sz = stride_[2];
    const double F = p_.F, k = p_.k, Du = p_.Du, Dv = p_.Dv, dt = p_.dt;
    for (std::int64_t kk = kHalo; kk < n_[2] + kHalo; ++kk)
      for (std::int64_t j = kHalo; j < n_[1] + kHalo; ++j) {
        const std::int64_t row = j * sy + kk * sz;
        const double* u = u_.data() + row;
        const double* v = v_.data() + row;
        double* un = u_next_.data() + row;
        double* vn = v_next_.data() + row;
        for (std::int64_t i = kHalo; i < n_[0] + kHalo; ++i) {
          const double lap_u =
              u[i - 1] + u[i + 1] + u[i - sy] + u[i + sy] + u[i - sz] + u[i + sz] - 6.0 * u[i];
          const double lap_v =
              v[i - 1] + v[i + 1] + v[i - sy] + v[i + sy] + v[i - sz] + v[i + sz] - 6.0 * v[i];
          const double uvv = u[i] * v[i] * v[i];
          un[i] = u[i] + dt * (Du * lap_u - uvv + F * (1.0 - u[i]));
          vn[i] = v[i] + dt * (Dv * lap_v + uvv - (F + k) * v[i]);
        }
      }
    std::swap(u_, u_next_);
    std::swap(v_, v_next_);
    exchange_halo(u_);
    exchange_halo(v_);
  }

  // V as a grid block of the solver's own array, nothing copied. Along each axis:
  //  - a neighbour below: the block starts at the halo point lo − 2 as ghost_lo = 2. Those
  //    points are owned by the neighbour, and so are the cells below lo (their lowest corners
  //    are the neighbour's): this block produces no hit there, the neighbour does. The ghosts
  //    give the normals' central differences at lo their point below.
  //  - a neighbour above: the block ends at the halo point hi + 1 as ghost_hi = 2, so that the
  //    cell [hi − 1, hi], whose lowest corner hi − 1 is owned here, is produced here and only
  //    here, and the normals at hi have their point above.
  //  - the domain boundary: no ghost; the halo there holds mirrored values, not grid points.
  //    At the top the last owned point N − 1 has no cell above it.
  // So the cells with lowest corner in [lo, hi) ∩ [0, N − 2] are this rank's: the ranks tile the
  // (N − 1)³ cells exactly, none twice, none missing. The halo's edges and corners are exchanged
  // too (axis after axis), as the cell [hi − 1, hi]² × … needs them.
  // V's block: the owned points and the halo points toward other ranks (ghost layers), read in
  // place from the current buffer.
  ldimesh::GridBlock v_block() const {
    ldimesh::GridBlock b;
    const double h = 1.0 / double(global_ - 1);
    for (int a = 0; a < 3; ++a) {
      b.ghost_lo[a] = below_[a] != MPI_PROC_NULL ? int(kHalo) : 0;
      b.ghost_hi[a] = above_[a] != MPI_PROC_NULL ? int(kHalo) : 0;
      b.dims[a] = n_[a] + b.ghost_lo[a] + b.ghost_hi[a];
      b.origin[a] = double(lo_[a] - b.ghost_lo[a]) * h;
      b.spacing[a] = h;
      b.strides[a] = stride_[a];
    }
    b.values = v_.data() + first_point();
    b.type = ldimesh::ScalarType::float64;
    return b;
  }
  // U in the layout of v_block() (for add_field).
  const double* u_in_block() const { return u_.data() + first_point(); }

  const double* v_data() const { return v_.data(); }

 private:
  static int rank_of(std::array<int, 3> c, std::array<int, 3> blocks) {
    return c[0] + blocks[0] * (c[1] + blocks[1] * c[2]);
  }

  // The local index of the block's first point: the first halo point below where there is a
  // neighbour, else the first owned point.
  std::int64_t first_point() const {
    std::int64_t at = 0;
    for (int a = 0; a < 3; ++a)
      at += (below_[a] != MPI_PROC_NULL ? 0 : kHalo) * stride_[a];
    return at;
  }

  std::int64_t local_index(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i * stride_[0] + j * stride_[1] + k * stride_[2];
  }

  // u = 1, v = 0, and in a cube of max(8, N/5) points around the centre u = 0.5, v = 0.25
  // (Pearson's seed), both perturbed by ±noise.
  void seed() {
    const std::int64_t half = std::max<std::int64_t>(4, global_ / 10);
    const std::int64_t c0 = global_ / 2 - half, c1 = global_ / 2 + half;
    for (std::int64_t k = 0; k < n_[2]; ++k)
      for (std::int64_t j = 0; j < n_[1]; ++j)
        for (std::int64_t i = 0; i < n_[0]; ++i) {
          const std::int64_t g[3] = {lo_[0] + i, lo_[1] + j, lo_[2] + k};
          const bool inside =
              g[0] >= c0 && g[0] < c1 && g[1] >= c0 && g[1] < c1 && g[2] >= c0 && g[2] < c1;
          const std::uint64_t id = std::uint64_t(g[0] + global_ * (g[1] + global_ * g[2]));
          const std::int64_t at = local_index(i + kHalo, j + kHalo, k + kHalo);
          u_[at] = (inside ? 0.5 : 1.0) * (1.0 + p_.noise * hash_noise(id, 1));
          v_[at] = inside ? 0.25 * (1.0 + p_.noise * hash_noise(id, 2)) : 0.0;
        }
    exchange_halo(u_);
    exchange_halo(v_);
  }

  // kHalo planes orthogonal to `axis` across the whole local array (halos included), as an MPI
  // datatype to be used at the address of the first plane's first value.
  void make_plane_type(int axis) {
    // MPI's subarray order is C order: z slowest.
    const int sizes[3] = {int(n_[2] + 2 * kHalo), int(n_[1] + 2 * kHalo), int(n_[0] + 2 * kHalo)};
    int sub[3] = {sizes[0], sizes[1], sizes[2]};
    sub[2 - axis] = int(kHalo);
    const int starts[3] = {0, 0, 0};
    MPI_Datatype t;
    MPI_Type_create_subarray(3, sizes, sub, starts, MPI_ORDER_C, MPI_DOUBLE, &t);
    MPI_Type_commit(&t);
    plane_[axis] = t;
  }

  double* plane(std::vector<double>& f, int axis, std::int64_t index) {
    return f.data() + index * stride_[axis];
  }

  // Copies plane `from` to plane `to` along `axis` (the whole local extent of the other axes).
  void copy_plane(std::vector<double>& f, int axis, std::int64_t from, std::int64_t to) {
    const int b = (axis + 1) % 3, c = (axis + 2) % 3;
    for (std::int64_t y = 0; y < n_[c] + 2 * kHalo; ++y)
      for (std::int64_t x = 0; x < n_[b] + 2 * kHalo; ++x) {
        const std::int64_t off = x * stride_[b] + y * stride_[c];
        f[to * stride_[axis] + off] = f[from * stride_[axis] + off];
      }
  }

  // Fills the halo: per axis (x, then y, then z, each over the full extent of the others, so
  // edges and corners arrive too) the neighbours' kHalo planes by MPI_Sendrecv, or at the domain
  // boundary the mirrored interior plane (zero flux; the outer halo planes there, read by
  // neither the Laplacian nor the adaptor, repeat it).
  void exchange_halo(std::vector<double>& f) {
    const std::int64_t h = kHalo;
    for (int a = 0; a < 3; ++a) {
      const std::int64_t n = n_[a];
      MPI_Sendrecv(plane(f, a, h), 1, plane_[a], below_[a], 0, plane(f, a, n + h), 1, plane_[a],
                   above_[a], 0, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      MPI_Sendrecv(plane(f, a, n), 1, plane_[a], above_[a], 1, plane(f, a, 0), 1, plane_[a],
                   below_[a], 1, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      for (std::int64_t k = 0; k < h; ++k) {
        if (below_[a] == MPI_PROC_NULL) copy_plane(f, a, h + 1, h - 1 - k);
        if (above_[a] == MPI_PROC_NULL) copy_plane(f, a, n + h - 2, n + h + k);
      }
    }
  }

  std::int64_t global_;
  Parameters p_;
  std::array<std::int64_t, 3> lo_{}, hi_{}, n_{}, stride_{};
  std::array<int, 3> below_{}, above_{};
  std::array<MPI_Datatype, 3> plane_{};
  std::vector<double> u_, v_, u_next_, v_next_;
};

}  // namespace

int main(int argc, char** argv) {
  MiniApp app("ldimesh-grayscott", argc, argv);
  CLI::App cli{"3D Gray-Scott reaction-diffusion with its V isosurface published live"};
  CommonArgs args;
  args.steps = 100;
  Parameters p;
  std::int64_t size = 64;
  int substeps = 10;
  app.add_common_options(cli, args);
  cli.add_option("--size", size, "global grid points per axis")
      ->check(CLI::Range(std::int64_t(4), std::int64_t(4096)))
      ->capture_default_str();
  cli.add_option("--substeps", substeps, "solver time steps per output step (execute call)")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  cli.add_option("--F", p.F, "feed rate")->capture_default_str();
  cli.add_option("--k", p.k, "kill rate")->capture_default_str();
  cli.add_option("--Du", p.Du, "diffusion of U (grid units)")->capture_default_str();
  cli.add_option("--Dv", p.Dv, "diffusion of V (grid units)")->capture_default_str();
  cli.add_option("--dt", p.dt,
                 "time step (explicit Euler: at most 1/(12 max(Du, Dv)), where the finest grid "
                 "mode is still damped without changing sign)")
      ->capture_default_str();
  if (const auto code = app.parse(cli, argc, argv)) return *code;
  if (const ldimesh::Status s = check_time_step(p); !s) {
    app.check(s, "start");
    return ldimesh::miniapp::kExitUsage;
  }

  const ldimesh::Box domain{{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}};
  const std::array<int, 3> blocks = ldimesh::block_grid(domain, app.size());
  for (int a = 0; a < 3; ++a) {
    // Every block needs two points per axis (kHalo): one cell at the top boundary, and the
    // halo planes a neighbour receives are owned ones.
    if (size < 2 * blocks[a]) {
      app.check(ldimesh::Status::invalid_argument("--size " + std::to_string(size) +
                                                  " is too small for " + std::to_string(blocks[a]) +
                                                  " blocks along an axis"),
                "start");
      return ldimesh::miniapp::kExitUsage;
    }
  }
  GrayScottBlock block(size, blocks, app.rank(), p);

  char line[256];
  std::snprintf(line, sizeof line,
                "ldimesh-grayscott: %lld^3 points on %d ranks (%d x %d x %d blocks), %d substeps "
                "per step, %llu steps, F=%g k=%g Du=%g Dv=%g dt=%g",
                static_cast<long long>(size), app.size(), blocks[0], blocks[1], blocks[2], substeps,
                static_cast<unsigned long long>(args.steps), p.F, p.k, p.Du, p.Dv, p.dt);
  app.print(line);

  std::unique_ptr<Adaptor> adaptor;
  if (!app.create_adaptor(args, /*default_isovalue=*/0.25, adaptor))
    return ldimesh::miniapp::kExitOptions;
  app.check(adaptor->set_domain(domain), "set_domain");
  // V lives in one of two buffers that swap every solver step: the block is described anew
  // whenever the step ends in the other one (the pointer changed; nothing is copied). U and V
  // are its named fields (option "colour_by": "U" colours the V isosurface by U).
  const double* described = nullptr;
  auto describe_v = [&] {
    if (block.v_data() == described) return;
    adaptor->clear_blocks();
    const ldimesh::GridBlock v = block.v_block();
    if (app.check(adaptor->add_grid_block(v), "add_grid_block") &&
        app.check(adaptor->add_field("U", block.u_in_block(), ldimesh::ScalarType::float64),
                  "add_field") &&
        app.check(adaptor->add_field("V", v.values, ldimesh::ScalarType::float64), "add_field"))
      described = block.v_data();
  };

  app.run(*adaptor, args, [&](std::uint64_t step) {
    for (int s = 0; s < substeps; ++s)
      block.advance();
    describe_v();
    return double(step) * substeps * p.dt;
  });
  return 0;
}
