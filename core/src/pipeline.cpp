#include "ldimesh/core/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>

#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/mesh/trim.hpp"

namespace ldimesh {
namespace {

// Appends the kept §3 quads of view `view`: one vertex per sample they use, in sample order.
void append_view(Mesh& mesh, const Ldi& ldi, const std::vector<glm::vec3>& positions,
                 const std::vector<std::uint32_t>& quads, std::uint8_t view, FaceType faces) {
  constexpr std::uint32_t kUnused = UINT32_MAX;
  std::vector<std::uint32_t> vertex_of(ldi.sample_count(), kUnused);
  for (std::uint32_t s : quads)
    vertex_of[s] = 0;
  std::uint32_t next = std::uint32_t(mesh.positions.size());
  for (std::size_t s = 0; s < vertex_of.size(); ++s) {
    if (vertex_of[s] == kUnused) continue;
    vertex_of[s] = next++;
    mesh.positions.push_back(positions[s]);
    mesh.normals.push_back(ldi.normal[s]);
    if (!ldi.scalar.empty()) mesh.scalars.push_back(ldi.scalar[s]);
  }
  for (std::size_t q = 0; q < quads.size(); q += 4) {
    const std::uint32_t v[4] = {vertex_of[quads[q]], vertex_of[quads[q + 1]],
                                vertex_of[quads[q + 2]], vertex_of[quads[q + 3]]};
    if (faces == FaceType::quads) {
      mesh.quads.insert(mesh.quads.end(), v, v + 4);
      mesh.quad_view.push_back(view);
    } else {
      append_quad_triangles(mesh.positions, v, mesh.triangles);
      mesh.triangle_view.insert(mesh.triangle_view.end(), {view, view});
    }
  }
}

// Appends the refined faces of view `view`.
void append_refined(Mesh& mesh, const RefinedView& r, std::uint8_t view, FaceType faces) {
  const std::uint32_t base = std::uint32_t(mesh.positions.size());
  mesh.positions.insert(mesh.positions.end(), r.positions.begin(), r.positions.end());
  mesh.normals.insert(mesh.normals.end(), r.normals.begin(), r.normals.end());
  mesh.scalars.insert(mesh.scalars.end(), r.scalars.begin(), r.scalars.end());
  std::vector<std::uint32_t>& out = faces == FaceType::quads ? mesh.quads : mesh.triangles;
  std::vector<std::uint8_t>& out_view =
      faces == FaceType::quads ? mesh.quad_view : mesh.triangle_view;
  for (std::uint32_t v : r.faces)
    out.push_back(base + v);
  out_view.insert(out_view.end(), r.faces.size() / (faces == FaceType::quads ? 4 : 3), view);
}

}  // namespace

MeshingResult mesh_ldis(std::span<const Ldi> ldis, const MeshingOptions& options,
                        SampleSource* samples) {
  if (!(options.r >= 0.0 && options.r <= 1.0))
    throw std::invalid_argument("trimming parameter r must lie in [0, 1]");
  if (ldis.size() > 255) throw std::invalid_argument("at most 255 views");
  const bool refine = options.refinement.levels != 0;
  if (refine && !samples) throw std::invalid_argument("refinement needs a sample source");
  const bool merge = options.merging.enabled;
  const double r = trim_r(options);
  // Merging takes the views' quads and splits what it needs to: a triangulated view loses one
  // triangle of a quad to the boundary layer and leaves a zig-zag rim that ear cutting with
  // refined views could not close (sphere 32², --refine 1: 8 open holes; as quads: none).
  const FaceType view_faces = merge ? FaceType::quads : options.faces;

  MeshingResult result;
  Mesh& mesh = result.mesh;
  for (const Ldi& ldi : ldis)
    mesh.view_dirs.push_back(ldi.view.dir);

  // §3 per view; without refinement each view is assembled at once, with it all views are
  // refined together (§4: one sampling round trip per pass for all of them).
  std::vector<ViewQuads> refine_input(refine ? ldis.size() : 0);
  for (std::size_t k = 0; k < ldis.size(); ++k) {
    const Ldi& ldi = ldis[k];
    result.samples += ldi.sample_count();

    auto start = std::chrono::steady_clock::now();
    std::vector<std::uint32_t> quads = build_quads(ldi, options.matching);
    result.quads_untrimmed += quads.size() / 4;
    result.seconds.match += seconds_since(start);

    start = std::chrono::steady_clock::now();
    const std::vector<glm::vec3> positions = sample_positions(ldi);
    if (refine) refine_input[k].untrimmed = quads;
    result.quads += trim_by_view_quality(quads, positions, ldi.view.dir, mesh.view_dirs, r);
    result.seconds.trim += seconds_since(start);

    if (refine) {
      refine_input[k].kept = std::move(quads);
      continue;
    }
    start = std::chrono::steady_clock::now();
    append_view(mesh, ldi, positions, quads, std::uint8_t(k), view_faces);
    result.seconds.assemble += seconds_since(start);
  }
  if (refine) {
    auto start = std::chrono::steady_clock::now();
    const std::vector<RefinedView> refined =
        refine_views(ldis, refine_input, view_faces, options.refinement, options.matching,
                     mesh.view_dirs, r, *samples, result.refinement);
    result.seconds.refine = seconds_since(start);
    start = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < refined.size(); ++k)
      append_refined(mesh, refined[k], std::uint8_t(k), view_faces);
    result.seconds.assemble += seconds_since(start);
  }
  if (merge) {
    std::vector<View> views;
    MergeOptions merging = options.merging;
    for (const Ldi& ldi : ldis) {
      views.push_back(ldi.view);
      if (options.merging.cell_size <= 0.0)
        merging.cell_size = std::max(merging.cell_size, ldi.view.spacing);
    }
    const SurfaceProjection project = samples && !views.empty() && merging_projects(merging)
                                          ? sample_projection(*samples, views)
                                          : SurfaceProjection();
    mesh = merge_views(std::move(mesh), options.faces, merging, result.merging, project);
    result.seconds.bridge = result.merging.bridge_seconds;
    result.seconds.sew = result.merging.sew_seconds;
    result.seconds.quality = result.merging.quality_seconds;
  }
  return result;
}

}  // namespace ldimesh
