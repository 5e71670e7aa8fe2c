#include "ldimesh/core/base/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <span>

namespace ldimesh {
namespace {

bool finite(const glm::vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// Whether some face of `arity` corners in `faces` repeats a vertex.
bool repeats_a_corner(const std::vector<std::uint32_t>& faces, std::size_t arity) {
  for (std::size_t f = 0; f + arity <= faces.size(); f += arity)
    for (std::size_t i = 0; i < arity; ++i)
      for (std::size_t j = i + 1; j < arity; ++j)
        if (faces[f + i] == faces[f + j]) return true;
  return false;
}

}  // namespace

Status check_mesh(const Mesh& m, const MeshChecks& checks) {
  const std::size_t n = m.vertex_count();
  const auto fail = [](const char* what) { return Status::invalid_argument(what); };
  if (m.normals.size() != n) return fail("normals and positions differ in count");
  if (!m.scalars.empty() && m.scalars.size() != n)
    return fail("scalars and positions differ in count");
  if (m.quads.size() % 4 != 0 || m.triangles.size() % 3 != 0)
    return fail("a partial face (quads not a multiple of 4 indices, or triangles of 3)");
  const auto views_fit = [&](std::size_t views, std::size_t faces) {
    return views == faces || (!checks.views_per_face && views == 0);
  };
  if (!views_fit(m.quad_view.size(), m.quad_count()) ||
      !views_fit(m.triangle_view.size(), m.triangle_count()))
    return fail("quad_view or triangle_view differ from the face counts");
  const auto in_range = [n](std::uint32_t i) { return i < n; };
  if (!std::all_of(m.quads.begin(), m.quads.end(), in_range) ||
      !std::all_of(m.triangles.begin(), m.triangles.end(), in_range))
    return fail("a face index is out of range");
  if (checks.distinct_corners && (repeats_a_corner(m.quads, 4) || repeats_a_corner(m.triangles, 3)))
    return fail("a face with a repeated vertex");
  if (checks.finite) {
    if (!std::all_of(m.positions.begin(), m.positions.end(), finite) ||
        !std::all_of(m.normals.begin(), m.normals.end(), finite))
      return fail("a position or normal is not finite");
    if (!std::all_of(m.scalars.begin(), m.scalars.end(), [](float s) { return std::isfinite(s); }))
      return fail("a scalar is not finite");
  }
  return Status::ok();
}

void append_mesh(Mesh& a, const Mesh& b) {
  const std::uint32_t base = std::uint32_t(a.positions.size());
  if (a.view_dirs.empty()) a.view_dirs = b.view_dirs;
  a.positions.insert(a.positions.end(), b.positions.begin(), b.positions.end());
  a.normals.insert(a.normals.end(), b.normals.begin(), b.normals.end());
  a.scalars.insert(a.scalars.end(), b.scalars.begin(), b.scalars.end());
  for (std::uint32_t i : b.triangles)
    a.triangles.push_back(base + i);
  for (std::uint32_t i : b.quads)
    a.quads.push_back(base + i);
  a.triangle_view.insert(a.triangle_view.end(), b.triangle_view.begin(), b.triangle_view.end());
  a.quad_view.insert(a.quad_view.end(), b.quad_view.begin(), b.quad_view.end());
}

std::size_t replace_nonfinite_scalars(Mesh& m) {
  const std::span<float> all(m.scalars);
  return replace_nonfinite_scalars(std::span(&all, 1));
}

std::size_t replace_nonfinite_scalars(std::span<const std::span<float>> parts) {
  float lowest = INFINITY;
  std::size_t bad = 0;
  for (const std::span<float> part : parts)
    for (float s : part) {
      if (std::isfinite(s))
        lowest = std::min(lowest, s);
      else
        ++bad;
    }
  if (bad == 0) return 0;
  if (!std::isfinite(lowest)) lowest = 0.0f;
  for (const std::span<float> part : parts)
    for (float& s : part)
      if (!std::isfinite(s)) s = lowest;
  return bad;
}

}  // namespace ldimesh
