// ldimesh-analytic: the paper's analytic surfaces (ldimesh surfaces lists them) split over the
// ranks, animated so that the live view changes: at step s the field is f(x / σ(s)), the
// surface scaled by σ(s) = 0.9 + 0.1 cos(2π s / period) about the origin, so it breathes
// between 80 % and 100 % of its size (step 0 is the paper's surface). Each rank adds the same
// global source with its own box of the decomposition (decompose_box): it casts only the hits
// in its box, and the root meshes the whole surface.
//
//   mpiexec -n 4 build/bin/ldimesh-analytic --surface barth --steps 100
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "miniapp.hpp"

namespace {

using ldimesh::Adaptor;
using ldimesh::FieldSource;
using ldimesh::SurfaceInfo;
using ldimesh::miniapp::CommonArgs;
using ldimesh::miniapp::MiniApp;

// f(x / scale): the isosurface of `field` scaled by `scale` about the origin. One formula for
// doubles, intervals and jets, like the fields it wraps.
template <class Field>
struct Scaled {
  Field field;
  double inverse_scale = 1.0;
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return field(x * inverse_scale, y * inverse_scale, z * inverse_scale);
  }
};

template <class Field>
std::shared_ptr<const FieldSource> scaled_source(const SurfaceInfo& s, double scale, int bricks) {
  return std::make_shared<ldimesh::AnalyticSource<Scaled<Field>>>(
      Scaled<Field>{Field{}, 1.0 / scale}, s.domain, s.clip_radius * scale, bricks);
}

// The built-in surface `s` scaled by `scale`: its field type by name (SurfaceInfo hides it).
// A surface not listed here is shown unscaled.
std::shared_ptr<const FieldSource> surface_source(const SurfaceInfo& s, double scale, int bricks) {
  namespace f = ldimesh::fields;
  if (s.name == "sphere") return scaled_source<f::Sphere>(s, scale, bricks);
  if (s.name == "torus") return scaled_source<f::Torus>(s, scale, bricks);
  if (s.name == "barth") return scaled_source<f::BarthSextic>(s, scale, bricks);
  if (s.name == "klein") return scaled_source<f::KleinBottle>(s, scale, bricks);
  if (s.name == "marschner-lobb") return scaled_source<f::MarschnerLobb>(s, scale, bricks);
  if (s.name == "slices") return scaled_source<f::Slices>(s, scale, bricks);
  return std::shared_ptr<const FieldSource>(s.make_source(s, bricks));
}

}  // namespace

int main(int argc, char** argv) {
  MiniApp app("ldimesh-analytic", argc, argv);
  CLI::App cli{"The paper's analytic surfaces over the ranks, breathing, published live"};
  CommonArgs args;
  args.steps = 100;
  std::string surface = "barth";
  int period = 40;
  int bricks = 32;
  app.add_common_options(cli, args);
  std::vector<std::string> names;
  for (const SurfaceInfo& s : ldimesh::builtin_surfaces())
    names.push_back(s.name);
  cli.add_option("--surface", surface, "the surface (ldimesh surfaces lists them)")
      ->check(CLI::IsMember(names))
      ->capture_default_str();
  cli.add_option("--period", period, "steps per breath (0: no animation)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cli.add_option("--bricks", bricks, "culling bricks per axis of the whole domain")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  if (const auto code = app.parse(cli, argc, argv)) return *code;

  const SurfaceInfo& info = *ldimesh::find_surface(surface);
  const std::vector<ldimesh::Box> boxes = ldimesh::decompose_box(info.domain, app.size());
  const std::array<int, 3> blocks = ldimesh::block_grid(info.domain, app.size());
  char line[256];
  std::snprintf(line, sizeof line,
                "ldimesh-analytic: %s on %d ranks (%d x %d x %d boxes), %llu steps, period %d",
                surface.c_str(), app.size(), blocks[0], blocks[1], blocks[2],
                static_cast<unsigned long long>(args.steps), period);
  app.print(line);

  std::unique_ptr<Adaptor> adaptor;
  if (!app.create_adaptor(args, info.isovalue, adaptor)) return ldimesh::miniapp::kExitOptions;
  app.check(adaptor->set_domain(info.domain), "set_domain");

  app.run(*adaptor, args, [&](std::uint64_t step) {
    const double phase =
        period > 0 ? 2.0 * std::numbers::pi * double(step % std::uint64_t(period)) / period : 0.0;
    const double scale = 0.9 + 0.1 * std::cos(phase);
    // The field changed: describe it anew (a real code would update its arrays in place).
    adaptor->clear_blocks();
    app.check(adaptor->add_source(surface_source(info, scale, bricks), boxes[app.rank()]),
              "add_source");
    return double(step);
  });
  return 0;
}
