// Coherent casting of rays parallel to a coordinate axis. Every ray this project casts — the
// pixel rays of the axis views and the extra samples of §4 and §5 along them — is such a ray, and
// sources whose primitives are axis-aligned in some way (grid cells, elements) find their roots
// without a BVH walk per ray: a grid walks the cells along the ray axis, where the
// trilinear interpolant is linear; elements loop over the pixels they cover (object order).
// The results are those of the source's Embree binding (docs/method.md, "Two casters").
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/view.hpp"

namespace ldimesh {

// One root of the field along a ray.
struct RayHit {
  double t = 0.0;       // distance from the ray origin (the view's depth)
  glm::vec3 normal{};   // unit gradient direction at the hit
  float scalar = 0.0f;  // the colour field there (FieldSource::bind_scalar), when there is one
};

// A ray o + t·d with d = ±e_axis, and the closed stretch [t0, t1] of it to report roots on.
// t1 < t0: the query holds no ray here (a pixel whose ray misses the subdomain).
struct AxisRay {
  glm::dvec3 org{0.0};
  double t0 = 0.0;
  double t1 = -1.0;
};

// A root of ray `ray` (its index in AxisRays::rays).
struct AxisHit {
  std::uint32_t ray = 0;
  RayHit hit;
};

// The hits of a query: growable arrays whose append inlines into the casters' kernels, which
// are large enough that the compiler left std::vector's push_back a call per hit, a visible
// share of a grid cast's profile. The rays' indices are kept apart
// from the hits, so that grouping the hits by ray reads 4 bytes per hit, not 32. Growth is the
// out-of-line part.
class AxisHits {
 public:
  [[gnu::always_inline]] void push_back(const AxisHit& hit) {
    if (size_ == capacity_) [[unlikely]]
      grow();
    rays_[size_] = hit.ray;
    hits_[size_++] = hit.hit;
  }
  void clear() { size_ = 0; }
  std::size_t size() const { return size_; }
  // Hit k's ray (its index in AxisRays::rays) and the hit.
  std::span<const std::uint32_t> rays() const { return {rays_.get(), size_}; }
  std::span<const RayHit> hits() const { return {hits_.get(), size_}; }

 private:
  void grow();  // doubles the capacity, keeping the hits
  std::unique_ptr<std::uint32_t[]> rays_;
  std::unique_ptr<RayHit[]> hits_;
  std::size_t size_ = 0, capacity_ = 0;
};

// Rays along one axis direction.
struct AxisRays {
  int axis = 2;             // the coordinate axis the rays are parallel to
  glm::dvec3 dir{0, 0, 1};  // exactly ±e_axis
  std::span<const AxisRay> rays;
  // Set when the rays are the pixel centres of a rectangle of this view (an axis view), row after
  // row: ray k is pixel (column_begin + k % w, row_begin + k / w), w = columns, or the view's
  // width where columns is 0 (whole rows). Sources that loop over the pixels their primitives
  // cover use it; others ignore it.
  const View* lattice = nullptr;
  int row_begin = 0;
  int column_begin = 0;
  int columns = 0;
  // The rectangle's width.
  int width() const { return columns > 0 ? columns : (lattice ? lattice->width : 0); }
};

// A source bound to one isovalue for axis-parallel rays.
class AxisCaster {
 public:
  virtual ~AxisCaster() = default;
  // Appends every root with t in [t0, t1] of every ray to `hits`, in any order, exactly as the
  // source's Embree binding reports them (roots on a face two primitives share may come twice;
  // the caster merges them). Thread-safe.
  virtual void cast(const AxisRays& rays, AxisHits& hits) const = 0;
  // Builds what casting along `axis` needs, once (thread-safe). The caster calls it before its
  // parallel loops, so that cast() itself runs no parallel work of its own.
  virtual void prepare(int /*axis*/) const {}
  // The same figures as the Embree binding's (GeometryBinding).
  virtual std::size_t primitive_count() const = 0;
  // Whether the caster should hand this source an axis view's pixels in blocks of columns (all
  // rows) rather than blocks of rows: a grid whose rows along the view's v axis are its fastest
  // memory axis, where a block of rows is a slab a few cells thin along it.
  virtual bool prefers_column_tasks(const View& /*view*/) const { return false; }
  virtual std::uint64_t nonfinite_values() const { return 0; }
};

// The axis (0, 1, 2) that `v` is parallel to, when v is exactly ±e_axis; −1 otherwise.
inline int exact_axis(glm::dvec3 v) {
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    if ((v[a] == 1.0 || v[a] == -1.0) && v[b] == 0.0 && v[c] == 0.0) return a;
  }
  return -1;
}

}  // namespace ldimesh
