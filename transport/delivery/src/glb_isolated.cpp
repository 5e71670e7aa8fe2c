// decode_glb_isolated: decode_glb in a child process whose CPU time is limited (glb.hpp).
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "ldimesh/core/base/isolated.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh {

double glb_decode_cpu_limit(std::size_t glb_bytes) {
  return 2.0 + std::floor(5.0 * double(glb_bytes) / double(1 << 20));
}

Status decode_glb_isolated(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info,
                           double cpu_seconds) {
  IsolatedTask task;
  task.prefix = "glb: ";
  task.process = "the decoder process";
  task.doing = "decoding";
  task.over_cpu =
      "a damaged or hostile Draco stream: Draco's decoder can spend seconds on a few bytes";
  task.cpu_seconds = cpu_seconds == 0.0 ? glb_decode_cpu_limit(glb.size()) : cpu_seconds;
  // The child sends the mesh's arrays, then GlbInfo's fields.
  std::vector<std::uint8_t> bytes;
  LDIMESH_RETURN_IF_ERROR(run_isolated(
      task,
      [&](std::vector<std::uint8_t>& result) {
        Mesh mesh;
        GlbInfo decoded;
        LDIMESH_RETURN_IF_ERROR(decode_glb(glb, mesh, &decoded));
        ByteWriter w(result);
        w.put_vector(mesh.positions);
        w.put_vector(mesh.normals);
        w.put_vector(mesh.scalars);
        w.put_vector(mesh.quads);
        w.put_vector(mesh.triangles);
        w.put_vector(mesh.quad_view);
        w.put_vector(mesh.triangle_view);
        w.put_vector(mesh.view_dirs);
        w.put(std::uint64_t(decoded.triangles));
        w.put(std::uint64_t(decoded.vertices));
        w.put(std::uint8_t(decoded.has_scalar));
        w.put(decoded.scalar_min);
        w.put(decoded.scalar_max);
        std::vector<std::uint8_t> present;
        std::vector<std::array<float, 2>> ranges;
        for (const auto& range : decoded.surface_scalar_ranges) {
          present.push_back(range ? 1 : 0);
          ranges.push_back(range.value_or(std::array<float, 2>{}));
        }
        w.put_vector(present);
        w.put_vector(ranges);
        return Status::ok();
      },
      bytes));
  ByteReader r(bytes);
  Mesh mesh;
  std::uint64_t triangles = 0, vertices = 0;
  std::uint8_t has_scalar = 0;
  GlbInfo decoded;
  std::vector<std::uint8_t> present;
  std::vector<std::array<float, 2>> ranges;
  if (!r.get_vector(mesh.positions) || !r.get_vector(mesh.normals) || !r.get_vector(mesh.scalars) ||
      !r.get_vector(mesh.quads) || !r.get_vector(mesh.triangles) || !r.get_vector(mesh.quad_view) ||
      !r.get_vector(mesh.triangle_view) || !r.get_vector(mesh.view_dirs) || !r.get(triangles) ||
      !r.get(vertices) || !r.get(has_scalar) || !r.get(decoded.scalar_min) ||
      !r.get(decoded.scalar_max) || !r.get_vector(present) || !r.get_vector(ranges) ||
      present.size() != ranges.size() || !r.done())
    return Status::internal("glb: the output of the decoder process is truncated");
  decoded.triangles = std::size_t(triangles);
  decoded.vertices = std::size_t(vertices);
  decoded.has_scalar = has_scalar != 0;
  for (std::size_t s = 0; s < present.size(); ++s)
    decoded.surface_scalar_ranges.push_back(present[s] ? std::optional(ranges[s]) : std::nullopt);
  out = std::move(mesh);
  if (info) *info = decoded;
  return Status::ok();
}

}  // namespace ldimesh
