#include "ldimesh/core/pipeline.hpp"

#include <chrono>
#include <stdexcept>

#include "ldimesh/core/trim.hpp"

namespace ldimesh {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// §3 per view, then §4 on all views together (one sampling round trip per pass), then one mesh.
MeshingResult mesh_refined(std::span<const Ldi> ldis, const MeshingOptions& options,
                           SampleSource& samples) {
  MeshingResult result;
  Mesh& mesh = result.mesh;
  for (const Ldi& ldi : ldis)
    mesh.view_dirs.push_back(ldi.view.dir);
  std::vector<ViewQuads> quads(ldis.size());
  for (std::size_t k = 0; k < ldis.size(); ++k) {
    const Ldi& ldi = ldis[k];
    result.samples += ldi.sample_count();
    auto start = std::chrono::steady_clock::now();
    quads[k].untrimmed = build_quads(ldi, options.matching);
    result.quads_untrimmed += quads[k].untrimmed.size() / 4;
    result.seconds.match += seconds_since(start);

    start = std::chrono::steady_clock::now();
    quads[k].kept = quads[k].untrimmed;
    result.quads += trim_by_view_quality(quads[k].kept, sample_positions(ldi), ldi.view.dir,
                                         mesh.view_dirs, options.r);
    result.seconds.trim += seconds_since(start);
  }

  auto start = std::chrono::steady_clock::now();
  const std::vector<RefinedView> refined =
      refine_views(ldis, quads, options.faces, options.refinement, options.matching, mesh.view_dirs,
                   options.r, samples, result.refinement);
  result.seconds.refine = seconds_since(start);

  start = std::chrono::steady_clock::now();
  for (std::size_t k = 0; k < refined.size(); ++k) {
    const RefinedView& r = refined[k];
    const std::uint32_t base = std::uint32_t(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), r.positions.begin(), r.positions.end());
    mesh.normals.insert(mesh.normals.end(), r.normals.begin(), r.normals.end());
    mesh.scalars.insert(mesh.scalars.end(), r.scalars.begin(), r.scalars.end());
    const std::uint8_t view = std::uint8_t(k);
    if (options.faces == FaceType::quads) {
      for (std::uint32_t v : r.faces)
        mesh.quads.push_back(base + v);
      mesh.quad_view.insert(mesh.quad_view.end(), r.faces.size() / 4, view);
    } else {
      for (std::uint32_t v : r.faces)
        mesh.triangles.push_back(base + v);
      mesh.triangle_view.insert(mesh.triangle_view.end(), r.faces.size() / 3, view);
    }
  }
  result.seconds.assemble += seconds_since(start);
  return result;
}

}  // namespace

MeshingResult mesh_ldis(std::span<const Ldi> ldis, const MeshingOptions& options,
                        SampleSource* samples) {
  if (!(options.r >= 0.0 && options.r <= 1.0))
    throw std::invalid_argument("trimming parameter r must lie in [0, 1]");
  if (ldis.size() > 255) throw std::invalid_argument("at most 255 views");
  if (options.refinement.levels != 0) {
    if (!samples) throw std::invalid_argument("refinement needs a sample source");
    return mesh_refined(ldis, options, *samples);
  }

  MeshingResult result;
  Mesh& mesh = result.mesh;
  for (const Ldi& ldi : ldis)
    mesh.view_dirs.push_back(ldi.view.dir);

  for (std::size_t k = 0; k < ldis.size(); ++k) {
    const Ldi& ldi = ldis[k];
    result.samples += ldi.sample_count();

    auto start = std::chrono::steady_clock::now();
    std::vector<std::uint32_t> quads = build_quads(ldi, options.matching);
    result.quads_untrimmed += quads.size() / 4;
    result.seconds.match += seconds_since(start);

    start = std::chrono::steady_clock::now();
    const std::vector<glm::vec3> positions = sample_positions(ldi);
    result.quads += trim_by_view_quality(quads, positions, ldi.view.dir, mesh.view_dirs, options.r);
    result.seconds.trim += seconds_since(start);

    start = std::chrono::steady_clock::now();
    // One vertex per sample used by a kept quad, in sample order.
    constexpr std::uint32_t kUnused = UINT32_MAX;
    std::vector<std::uint32_t> vertex_of(ldi.sample_count(), kUnused);
    for (std::uint32_t s : quads)
      vertex_of[s] = 0;
    const std::uint32_t base = std::uint32_t(mesh.positions.size());
    std::uint32_t next = base;
    for (std::size_t s = 0; s < vertex_of.size(); ++s) {
      if (vertex_of[s] == kUnused) continue;
      vertex_of[s] = next++;
      mesh.positions.push_back(positions[s]);
      mesh.normals.push_back(ldi.normal[s]);
      if (!ldi.scalar.empty()) mesh.scalars.push_back(ldi.scalar[s]);
    }
    const std::uint8_t view = std::uint8_t(k);
    for (std::size_t q = 0; q < quads.size(); q += 4) {
      const std::uint32_t v[4] = {vertex_of[quads[q]], vertex_of[quads[q + 1]],
                                  vertex_of[quads[q + 2]], vertex_of[quads[q + 3]]};
      if (options.faces == FaceType::quads) {
        mesh.quads.insert(mesh.quads.end(), v, v + 4);
        mesh.quad_view.push_back(view);
      } else {
        append_quad_triangles(mesh.positions, v, mesh.triangles);
        mesh.triangle_view.insert(mesh.triangle_view.end(), {view, view});
      }
    }
    result.seconds.assemble += seconds_since(start);
  }
  return result;
}

}  // namespace ldimesh
