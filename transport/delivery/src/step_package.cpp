#include "ldimesh/transport/step_package.hpp"

#include <algorithm>
#include <chrono>
#include <optional>
#include <utility>

namespace ldimesh {

std::size_t replace_nonfinite_colours(Mesh& mesh, const std::vector<std::uint32_t>& surfaces,
                                      const std::vector<int>& groups) {
  if (mesh.scalars.empty() || groups.empty()) return 0;
  const std::size_t count = std::max<std::size_t>(1, surfaces.size());
  const auto range = [&](std::size_t s) {
    const std::size_t first = surfaces.empty() ? 0 : surfaces[s];
    const std::size_t last = s + 1 < surfaces.size() ? surfaces[s + 1] : mesh.scalars.size();
    return std::span<float>(mesh.scalars.data() + first, last - first);
  };
  std::size_t replaced = 0;
  for (int g = 0; g <= *std::max_element(groups.begin(), groups.end()); ++g) {
    std::vector<std::span<float>> parts;
    for (std::size_t s = 0; s < count; ++s)
      if (groups[s] == g) parts.push_back(range(s));
    replaced += replace_nonfinite_scalars(parts);
  }
  return replaced;
}

Status package_step(const StepDescription& d, std::vector<StepSurface> results, PackagedStep& out) {
  out = {};
  const bool coloured = !d.colour_fields.empty();
  std::vector<int> fields = d.surface_field;
  if (fields.empty()) fields.assign(results.size(), coloured ? 0 : -1);
  std::size_t samples = 0, quads = 0;
  std::vector<std::uint32_t> surfaces;  // where each isovalue's vertices start
  for (std::size_t i = 0; i < results.size(); ++i) {
    StepSurface& r = results[i];
    samples += r.samples;
    quads += r.quads;
    surfaces.push_back(std::uint32_t(out.mesh.positions.size()));
    if (i == 0)
      out.mesh = std::move(r.mesh);
    else
      append_mesh(out.mesh, r.mesh);
    // An isosurface without a colour field beside coloured ones: values the GLB leaves out.
    if (coloured && fields[i] < 0) out.mesh.scalars.resize(out.mesh.positions.size(), 0.0f);
  }
  // Where the surfaces are not all coloured by one field, each field its own range.
  std::vector<int> groups = fields;
  const bool mixed = d.colour_fields.size() > 1 ||
                     (coloured && std::find(groups.begin(), groups.end(), -1) != groups.end());
  if (!mixed) groups.assign(surfaces.size(), coloured ? 0 : -1);
  out.uncoloured = replace_nonfinite_colours(out.mesh, surfaces, groups);
  if (!d.encode) return Status::ok();

  const auto start = std::chrono::steady_clock::now();
  GlbOptions glb_options = step_glb_options(d.views.front(), d.glb);
  if (surfaces.size() > 1) glb_options.surfaces = std::move(surfaces);  // a mesh each
  if (mixed) glb_options.scalar_groups = groups;
  LDIMESH_RETURN_IF_ERROR(encode_glb(out.mesh, glb_options, out.glb, &out.info));
  out.glb_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  StepMetadata& meta = out.metadata;
  meta = describe_step(d.step, d.time, d.isovalues, d.views, d.r, samples, quads, out.info);
  meta.seconds["glb"] = out.glb_seconds;
  if (out.info.has_scalar && d.colour_fields.size() == 1)
    meta.scalar = ScalarRange{d.colour_fields[0], out.info.scalar_min, out.info.scalar_max};
  if (mixed)
    for (std::size_t i = 0; i < groups.size(); ++i) {
      std::optional<ScalarRange> range;
      if (groups[i] >= 0 && i < out.info.surface_scalar_ranges.size() &&
          out.info.surface_scalar_ranges[i])
        range = ScalarRange{d.colour_fields[std::size_t(groups[i])],
                            (*out.info.surface_scalar_ranges[i])[0],
                            (*out.info.surface_scalar_ranges[i])[1]};
      meta.surface_scalars.push_back(std::move(range));
    }
  return Status::ok();
}

}  // namespace ldimesh
