// The built-in analytic surfaces (docs/surfaces.md lists them with their formulas).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {

struct SurfaceInfo {
  std::string name;
  std::string formula;  // human-readable, as in docs/surfaces.md
  Box domain;           // the box the views are laid over
  double isovalue;      // the default isovalue
  double clip_radius;   // > 0: the surface is clipped to this ball around the origin
  std::unique_ptr<FieldSource> (*make_source)(const SurfaceInfo&, int bricks_per_axis);
  // The field's value at p, its gradient into `gradient` (distances to the surface).
  double (*field)(const glm::dvec3& p, glm::dvec3& gradient);
};

// All built-in surfaces, in a fixed order.
std::span<const SurfaceInfo> builtin_surfaces();

// The surface called `name`, or nullptr.
const SurfaceInfo* find_surface(std::string_view name);

// A ray-caster source for the built-in surface `name` with bricks_per_axis³ culling bricks.
// Throws std::invalid_argument for an unknown name.
std::unique_ptr<FieldSource> make_surface_source(std::string_view name, int bricks_per_axis = 32);

}  // namespace ldimesh
