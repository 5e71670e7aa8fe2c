// A job's server for the browser test, without the job: publishes real meshes as the root rank
// would. Step 1 (the torus) is published at start; each line "next" on standard input publishes
// the next step (the Barth sextic, then Klein bottle …), each coloured by its vertices' x;
// "nested" publishes the next step as two isovalues of the sphere's field (two concentric
// spheres, a surface each in the GLB); "nested-colours" the same with the outer sphere not
// coloured and the inner one coloured by "T" (300 + 100·x: other units), "nested-fields" with
// the outer one by x and the inner one by T (each surface its own field and range, as the adaptor's
// "colour_by" per isovalue writes them); "quit" or the end of input stops. Prints "url URL" once
// the server listens and "published STEP TRIANGLES" after each step.
//
//   ldimesh_test_publisher REPO_ROOT
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace {

// A colour field of the published surfaces at a vertex.
float field_at(const std::string& name, const glm::vec3& p) {
  return name == "T" ? 300.0f + 100.0f * p.x : p.x;
}

// Meshes `surface` at `res` at each of `isovalues` (default: the surface's own) and publishes
// them as step `step`, a surface of the GLB each, each coloured by its entry of `fields` ("" for
// none; default: all by x); returns the GLB's triangle count.
std::size_t publish(ldimesh::SnapshotStore& store, std::uint64_t step, const char* surface, int res,
                    std::vector<double> isovalues = {}, std::vector<std::string> fields = {}) {
  const ldimesh::SurfaceInfo* s = ldimesh::find_surface(surface);
  const auto source = ldimesh::make_surface_source(surface);
  if (isovalues.empty()) isovalues = {s->isovalue};
  ldimesh::MeshingResult result;
  std::vector<ldimesh::Ldi> ldis;
  ldimesh::GlbOptions options;
  for (const double isovalue : isovalues) {
    const ldimesh::RayCaster caster(*source, isovalue);
    ldis.clear();
    for (const ldimesh::View& v : ldimesh::make_axis_views(s->domain, res))
      ldis.push_back(caster.cast(v));
    const ldimesh::MeshingResult one = ldimesh::mesh_ldis(ldis, {});
    options.surfaces.push_back(std::uint32_t(result.mesh.positions.size()));
    ldimesh::append_mesh(result.mesh, one.mesh);
    result.samples += one.samples;
    result.quads += one.quads;
    result.seconds = one.seconds;
  }
  // A field to colour by: each vertex's x (the camera sees both ends of every surface), or each
  // surface's own (0 where it has none, which the GLB leaves out).
  const bool own = !fields.empty();
  if (!own) fields.assign(isovalues.size(), "x");
  std::vector<std::string> names;  // each field once
  for (std::size_t s = 0; s < isovalues.size(); ++s) {
    const std::size_t last =
        s + 1 < isovalues.size() ? options.surfaces[s + 1] : result.mesh.positions.size();
    for (std::size_t v = options.surfaces[s]; v < last; ++v)
      result.mesh.scalars.push_back(
          fields[s].empty() ? 0.0f : field_at(fields[s], result.mesh.positions[v]));
    const auto at = std::find(names.begin(), names.end(), fields[s]);
    if (own) options.scalar_groups.push_back(fields[s].empty() ? -1 : int(at - names.begin()));
    if (!fields[s].empty() && at == names.end()) names.push_back(fields[s]);
  }
  if (isovalues.size() == 1) options.surfaces.clear();
  options.pixel_size = ldis.front().view.spacing;
  std::vector<std::uint8_t> glb;
  ldimesh::GlbInfo info;
  if (const ldimesh::Status st = ldimesh::encode_glb(result.mesh, options, glb, &info); !st)
    throw std::runtime_error(st.message());
  std::vector<ldimesh::View> views;
  for (const ldimesh::Ldi& l : ldis)
    views.push_back(l.view);
  ldimesh::StepMetadata meta = ldimesh::describe_step(step, 0.1 * double(step), isovalues, views,
                                                      0.5, result.samples, result.quads, info);
  if (names.size() == 1)
    meta.scalar = ldimesh::ScalarRange{names[0], info.scalar_min, info.scalar_max};
  for (std::size_t s = 0; own && s < isovalues.size(); ++s)
    meta.surface_scalars.push_back(
        info.surface_scalar_ranges[s]
            ? std::optional(ldimesh::ScalarRange{fields[s], (*info.surface_scalar_ranges[s])[0],
                                                 (*info.surface_scalar_ranges[s])[1]})
            : std::nullopt);
  meta.seconds = {{"mesh", result.seconds.match + result.seconds.trim + result.seconds.assemble}};
  ldimesh::Snapshot snapshot = ldimesh::make_snapshot(std::move(meta), std::move(glb));
  if (const ldimesh::Status st = store.publish(std::move(snapshot)); !st)
    throw std::runtime_error(st.message());
  return info.triangles;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s REPO_ROOT\n", argv[0]);
    return 2;
  }
  try {
    const std::filesystem::path root = argv[1];
    ldimesh::SnapshotStore store;
    ldimesh::HttpServerOptions options;
    options.static_dir = root / "viewer" / "web";
    options.vendor_three_dir = root / "node_modules" / "three";
    ldimesh::HttpServer server(store, options);
    if (const ldimesh::Status st = server.start(); !st) throw std::runtime_error(st.message());
    std::printf("url %s\n", server.url().c_str());
    std::fflush(stdout);
    const char* surfaces[] = {"torus", "barth", "klein", "sphere"};
    std::uint64_t step = 1;
    std::printf("published %llu %zu\n", (unsigned long long)step,
                publish(store, step, surfaces[0], 96));
    std::fflush(stdout);
    for (std::string line; std::getline(std::cin, line) && line != "quit";) {
      if (line != "next" && line != "nested" && line != "nested-colours" && line != "nested-fields")
        continue;
      ++step;
      const std::size_t triangles =
          line == "nested"           ? publish(store, step, "sphere", 96, {1.0, 0.36})
          : line == "nested-colours" ? publish(store, step, "sphere", 96, {1.0, 0.36}, {"", "T"})
          : line == "nested-fields"  ? publish(store, step, "sphere", 96, {1.0, 0.36}, {"x", "T"})
                                     : publish(store, step, surfaces[(step - 1) % 4], 96);
      std::printf("published %llu %zu\n", (unsigned long long)step, triangles);
      std::fflush(stdout);
    }
    server.stop();
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "publisher: %s\n", e.what());
    return 1;
  }
}
