#include "ldimesh/core/metrics/distance.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---- The sampled mesh ----

// A mesh as triangles (quads split along the shorter diagonal, the rule of mesh_ldis and the
// GLB encoder) with the vertices its faces use and its polygon edges (a quad's diagonal is not
// one).
struct Surface {
  const std::vector<glm::vec3>* positions = nullptr;
  std::vector<std::uint32_t> triangles;  // 3 vertex indices per triangle
  std::vector<std::uint32_t> vertices;   // used by a face, ascending
  std::vector<std::uint64_t> edges;      // (lo << 32) | hi, lo < hi, ascending, unique
  Box bounds{glm::dvec3(kInf), glm::dvec3(-kInf)};
  double max_coordinate = 0.0;  // the largest |x|, |y| or |z| of a used vertex

  glm::dvec3 position(std::uint32_t i) const { return glm::dvec3((*positions)[i]); }
  std::size_t triangle_count() const { return triangles.size() / 3; }
};

Surface make_surface(const Mesh& m, const char* name) {
  const std::string what = std::string("distance: mesh ") + name;
  if (m.face_count() == 0) throw std::invalid_argument(what + " has no faces");
  if (m.quads.size() % 4 != 0 || m.triangles.size() % 3 != 0)
    throw std::invalid_argument(what + ": face index arrays of a wrong length");
  const std::size_t n = m.positions.size();
  for (const auto* list : {&m.quads, &m.triangles})
    for (std::uint32_t i : *list)
      if (i >= n)
        throw std::invalid_argument(what + ": face index " + std::to_string(i) + " out of range (" +
                                    std::to_string(n) + " vertices)");
  Surface s;
  s.positions = &m.positions;
  s.triangles.reserve(6 * m.quad_count() + m.triangles.size());
  std::vector<std::uint64_t>& edges = s.edges;
  edges.reserve(4 * m.quad_count() + m.triangles.size());
  auto add_edges = [&](const std::uint32_t* v, int count) {
    for (int k = 0; k < count; ++k) {
      const std::uint32_t a = v[k], b = v[(k + 1) % count];
      if (a != b) edges.push_back(std::uint64_t(std::min(a, b)) << 32 | std::max(a, b));
    }
  };
  for (std::size_t q = 0; q < m.quad_count(); ++q) {
    const std::uint32_t* v = &m.quads[4 * q];
    append_quad_triangles(m.positions, v, s.triangles);
    add_edges(v, 4);
  }
  s.triangles.insert(s.triangles.end(), m.triangles.begin(), m.triangles.end());
  for (std::size_t t = 0; t < m.triangle_count(); ++t)
    add_edges(&m.triangles[3 * t], 3);
  tbb::parallel_sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());

  std::vector<std::uint8_t> used(n, 0);
  for (std::uint32_t i : s.triangles)
    used[i] = 1;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!used[i]) continue;
    const glm::dvec3 p = s.position(i);
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw std::invalid_argument(what + ": vertex " + std::to_string(i) +
                                  " has a non-finite position");
    s.vertices.push_back(i);
    s.bounds.lo = glm::min(s.bounds.lo, p);
    s.bounds.hi = glm::max(s.bounds.hi, p);
    s.max_coordinate = std::max({s.max_coordinate, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  }
  return s;
}

// Splits n samples over items in proportion to their sizes: item i gets
// floor(n·Sᵢ/S) − floor(n·Sᵢ₋₁/S) with Sᵢ the running sum of the sizes, so every item gets its
// share rounded up or down and the total is exactly n. Returns the prefix sums (size + 1).
std::vector<std::uint64_t> share(const std::vector<double>& sizes, std::uint64_t n) {
  std::vector<std::uint64_t> first(sizes.size() + 1, 0);
  double total = 0.0;
  for (double s : sizes)
    total += s;
  if (!(total > 0.0) || !std::isfinite(total)) return first;  // nothing to share out
  double running = 0.0;
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    running += sizes[i];
    first[i + 1] = std::max(first[i], std::uint64_t(std::floor(double(n) * (running / total))));
  }
  return first;
}

// Where the samples of a surface go: first[i]..first[i+1] are the samples of edge or triangle i.
struct SamplePlan {
  std::vector<std::uint64_t> edge_first;
  std::vector<std::uint64_t> face_first;
  SampleCounts counts;
};

SamplePlan plan_samples(const Surface& s, std::uint64_t target) {
  SamplePlan plan;
  plan.counts.vertices = s.vertices.size();
  const std::uint64_t rest = target > plan.counts.vertices ? target - plan.counts.vertices : 0;
  std::vector<double> lengths(s.edges.size()), areas(s.triangle_count());
  tbb::parallel_for(std::size_t(0), lengths.size(), [&](std::size_t e) {
    const std::uint64_t v = s.edges[e];
    lengths[e] = glm::length(s.position(std::uint32_t(v >> 32)) - s.position(std::uint32_t(v)));
  });
  tbb::parallel_for(std::size_t(0), areas.size(), [&](std::size_t t) {
    const std::uint32_t* v = &s.triangles[3 * t];
    const glm::dvec3 a = s.position(v[0]);
    areas[t] = 0.5 * glm::length(glm::cross(s.position(v[1]) - a, s.position(v[2]) - a));
  });
  // A quarter of the rest on edges (Metro samples edges too: the largest deviations sit at
  // creases and borders); faces take the remainder. A mesh without area puts all on edges.
  std::uint64_t on_edges = rest / 4;
  plan.face_first = share(areas, rest - on_edges);
  if (plan.face_first.back() == 0) on_edges = rest;
  plan.edge_first = share(lengths, on_edges);
  plan.counts.edges = plan.edge_first.back();
  plan.counts.faces = plan.face_first.back();
  return plan;
}

// A 64-bit mix (splitmix64's finaliser): the per-triangle offsets of the face samples.
std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

double unit(std::uint64_t bits) {
  return double(bits >> 11) * 0x1.0p-53;
}

// ---- Measuring: fixed chunks, summed in order ----

enum class Outcome { measured, not_converged, outside_clip };

struct Measurement {
  double distance = 0.0;
  Outcome outcome = Outcome::measured;
};

enum class Where { vertex, edge, face };

// What the samples of one chunk (or all) add up to.
struct Tally {
  SampleCounts counts;
  double sum = 0.0, sum2 = 0.0, max = -1.0;
  glm::dvec3 max_at{0.0};
  std::uint64_t not_converged = 0, outside_clip = 0;

  void record(Where where, const glm::dvec3& p, const Measurement& m) {
    if (m.outcome == Outcome::not_converged) {
      ++not_converged;
      return;
    }
    if (m.outcome == Outcome::outside_clip) {
      ++outside_clip;
      return;
    }
    (where == Where::vertex ? counts.vertices
     : where == Where::edge ? counts.edges
                            : counts.faces)++;
    sum += m.distance;
    sum2 += m.distance * m.distance;
    if (m.distance > max) {
      max = m.distance;
      max_at = p;
    }
  }
  void add(const Tally& t) {
    counts.vertices += t.counts.vertices;
    counts.edges += t.counts.edges;
    counts.faces += t.counts.faces;
    sum += t.sum;
    sum2 += t.sum2;
    if (t.max > max) {
      max = t.max;
      max_at = t.max_at;
    }
    not_converged += t.not_converged;
    outside_clip += t.outside_clip;
  }
  DistanceStats stats() const {
    DistanceStats s;
    s.samples = counts;
    const double n = double(counts.total());
    if (n > 0) {
      s.mean = sum / n;
      s.rms = std::sqrt(sum2 / n);
      s.max = max;
      s.max_at = max_at;
    }
    return s;
  }
};

// Measures every sample of `s` with a probe from make_probe() (one per chunk, called in sample
// order within the chunk). Chunks are fixed ranges of vertices, edges and triangles, each summed
// in order, and the chunk sums are added in order: the result does not depend on how the
// chunks are spread over threads.
template <class MakeProbe>
Tally measure(const Surface& s, const SamplePlan& plan, MakeProbe make_probe) {
  constexpr std::size_t kVertices = 4096, kEdges = 2048, kTriangles = 1024;
  struct Chunk {
    Where where;
    std::size_t begin, end;
  };
  std::vector<Chunk> chunks;
  auto split = [&](Where where, std::size_t n, std::size_t size) {
    for (std::size_t b = 0; b < n; b += size)
      chunks.push_back({where, b, std::min(n, b + size)});
  };
  split(Where::vertex, s.vertices.size(), kVertices);
  if (plan.counts.edges > 0) split(Where::edge, s.edges.size(), kEdges);
  if (plan.counts.faces > 0) split(Where::face, s.triangle_count(), kTriangles);

  std::vector<Tally> tallies(chunks.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks.size(), 1), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const Chunk& chunk = chunks[c];
      Tally& tally = tallies[c];
      auto probe = make_probe();
      auto sample = [&](const glm::dvec3& p) { tally.record(chunk.where, p, probe(p)); };
      for (std::size_t i = chunk.begin; i < chunk.end; ++i) {
        if (chunk.where == Where::vertex) {
          sample(s.position(s.vertices[i]));
        } else if (chunk.where == Where::edge) {
          // Evenly spaced inside the edge: the midpoints of n equal pieces.
          const std::uint64_t first = plan.edge_first[i], n = plan.edge_first[i + 1] - first;
          const glm::dvec3 a = s.position(std::uint32_t(s.edges[i] >> 32));
          const glm::dvec3 ab = s.position(std::uint32_t(s.edges[i])) - a;
          for (std::uint64_t k = 0; k < n; ++k)
            sample(a + ((double(k) + 0.5) / double(n)) * ab);
        } else {
          // A low-discrepancy (Roberts' R2) sequence with a fixed per-triangle offset, folded
          // from the unit square onto the triangle.
          const std::uint64_t first = plan.face_first[i], n = plan.face_first[i + 1] - first;
          if (n == 0) continue;
          const std::uint32_t* v = &s.triangles[3 * i];
          const glm::dvec3 a = s.position(v[0]);
          const glm::dvec3 ab = s.position(v[1]) - a, ac = s.position(v[2]) - a;
          const std::uint64_t h = mix(std::uint64_t(i) ^ 0x6c64696d657368ull);
          double u = unit(h), w = unit(mix(h));
          constexpr double g = 1.32471795724474602596;  // the plastic number
          for (std::uint64_t k = 0; k < n; ++k) {
            u += 1.0 / g;
            w += 1.0 / (g * g);
            u -= std::floor(u);
            w -= std::floor(w);
            const bool fold = u + w > 1.0;
            sample(a + (fold ? 1.0 - u : u) * ab + (fold ? 1.0 - w : w) * ac);
          }
        }
      }
    }
  });
  Tally total;
  for (const Tally& t : tallies)
    total.add(t);
  return total;
}

// ---- Closest points on triangles ----

double segment_distance2(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b) {
  const glm::dvec3 ab = b - a, ap = p - a;
  const double len2 = glm::dot(ab, ab);
  const double t = len2 > 0.0 ? std::clamp(glm::dot(ap, ab) / len2, 0.0, 1.0) : 0.0;
  const glm::dvec3 d = ap - t * ab;
  return glm::dot(d, d);
}

// Squared distance from p to the triangle abc, or some value above bound2 when it is clearly
// not below bound2. Inside the prism over the triangle it is the distance to the plane (which
// bounds it from below everywhere); outside, the closest point lies on an edge that has p on its
// outer side. Needles and points (sin of the largest angle below 10⁻⁶) are measured by their edges.
double triangle_distance2(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                          const glm::dvec3& c, double bound2) {
  const glm::dvec3 ab = b - a, bc = c - b, ca = a - c;
  const glm::dvec3 n = glm::cross(ab, -ca);
  const double n2 = glm::dot(n, n);
  const double longest2 = std::max({glm::dot(ab, ab), glm::dot(bc, bc), glm::dot(ca, ca)});
  if (n2 > 1e-12 * longest2 * longest2) {
    // The margin keeps rounding from making the result depend on the order Embree visits
    // triangles in (its BVH may differ with the number of threads).
    const double h = glm::dot(p - a, n), plane2 = h * h / n2;
    if (plane2 > bound2 * (1.0 + 1e-9)) return plane2;
    const bool out_ab = glm::dot(glm::cross(ab, p - a), n) < 0.0;
    const bool out_bc = glm::dot(glm::cross(bc, p - b), n) < 0.0;
    const bool out_ca = glm::dot(glm::cross(ca, p - c), n) < 0.0;
    if (!out_ab && !out_bc && !out_ca) return plane2;
    double d2 = kInf;
    if (out_ab) d2 = std::min(d2, segment_distance2(p, a, b));
    if (out_bc) d2 = std::min(d2, segment_distance2(p, b, c));
    if (out_ca) d2 = std::min(d2, segment_distance2(p, c, a));
    return d2;
  }
  return std::min(
      {segment_distance2(p, a, b), segment_distance2(p, b, c), segment_distance2(p, c, a)});
}

// The smallest float not below x (Embree's query radius must not cut off a closer triangle).
float float_above(double x) {
  float f = float(x);
  if (double(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

class EmbreeDevice {
 public:
  EmbreeDevice() : device_(make_embree_device()) {}
  ~EmbreeDevice() { rtcReleaseDevice(device_); }
  EmbreeDevice(const EmbreeDevice&) = delete;
  EmbreeDevice& operator=(const EmbreeDevice&) = delete;
  RTCDevice get() const { return device_; }

 private:
  RTCDevice device_;
};

// A BVH over the triangles of a surface, for point queries.
class TriangleScene {
 public:
  TriangleScene(RTCDevice device, const Surface& s) : scene_(rtcNewScene(device)) {
    if (!scene_) throw std::runtime_error("Embree: cannot create a scene");
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // 16-byte vertices: Embree reads each vertex with one SSE load, so no padding is needed.
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), s.positions->size()));
    auto* t = static_cast<std::uint32_t*>(
        rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(std::uint32_t), s.triangle_count()));
    if (!v || !t) {
      rtcReleaseGeometry(g);
      rtcReleaseScene(scene_);
      throw std::runtime_error("Embree: cannot allocate the triangle buffers");
    }
    for (std::size_t i = 0; i < s.positions->size(); ++i) {
      const glm::vec3& p = (*s.positions)[i];
      // Unused vertices may be anything; Embree only reads those the triangles use.
      v[4 * i] = p.x;
      v[4 * i + 1] = p.y;
      v[4 * i + 2] = p.z;
      v[4 * i + 3] = 0.0f;
    }
    std::copy(s.triangles.begin(), s.triangles.end(), t);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene_, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene_);
    if (const std::string failure = embree_failure(device, "building the triangle BVH");
        !failure.empty()) {
      rtcReleaseScene(scene_);
      throw std::runtime_error(failure);
    }
  }
  ~TriangleScene() { rtcReleaseScene(scene_); }
  TriangleScene(const TriangleScene&) = delete;
  TriangleScene& operator=(const TriangleScene&) = delete;
  RTCScene get() const { return scene_; }

 private:
  RTCScene scene_;
};

// The distance of sample points to the closest point of a triangle scene. One per chunk: it
// starts each query with the bound d(previous) + |p − previous| (the triangle inequality), which
// only prunes triangles farther than the closest one, so results do not depend on it.
class ClosestPointProbe {
 public:
  ClosestPointProbe(RTCScene scene, const Surface& target, double slack, double zero)
      : scene_(scene), target_(target), slack_(slack), zero_(zero) {}

  Measurement operator()(const glm::dvec3& p) {
    double bound = kInf;
    if (have_previous_) bound = previous_distance_ + glm::length(p - previous_) + slack_;
    double d2 = query(p, bound);
    if (d2 == kInf) d2 = query(p, kInf);  // cannot happen unless rounding defeats the bound
    double d = std::sqrt(d2);
    previous_ = p;
    previous_distance_ = d;
    have_previous_ = true;
    if (d <= zero_) d = 0.0;
    return {d, Outcome::measured};
  }

 private:
  struct State {
    glm::dvec3 p;
    const Surface* target;
    double best2;
    double slack;
  };

  // For each triangle whose bounds Embree finds within the query radius.
  static bool visit(RTCPointQueryFunctionArguments* args) {
    auto* state = static_cast<State*>(args->userPtr);
    const std::uint32_t* t = &state->target->triangles[3 * std::size_t(args->primID)];
    const Surface& s = *state->target;
    const double d2 = triangle_distance2(state->p, s.position(t[0]), s.position(t[1]),
                                         s.position(t[2]), state->best2);
    if (!(d2 < state->best2)) return false;
    state->best2 = d2;
    // Embree culls in float around the float query point: widen by the slack.
    const float radius = float_above(std::sqrt(d2) + state->slack);
    if (radius >= args->query->radius) return false;
    args->query->radius = radius;
    return true;
  }

  double query(const glm::dvec3& p, double bound) const {
    State state{p, &target_, kInf, slack_};
    RTCPointQuery q;
    q.x = float(p.x);
    q.y = float(p.y);
    q.z = float(p.z);
    q.time = 0.0f;
    q.radius = bound == kInf ? std::numeric_limits<float>::infinity() : float_above(bound);
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(scene_, &q, &context, &ClosestPointProbe::visit, &state);
    return state.best2;
  }

  RTCScene scene_;
  const Surface& target_;
  double slack_, zero_;
  glm::dvec3 previous_{0.0};
  double previous_distance_ = 0.0;
  bool have_previous_ = false;
};

std::uint64_t default_samples(std::size_t triangles) {
  return 10 * std::uint64_t(triangles);
}

// ---- Distance to an implicit surface ----

// Projects samples onto field = iso (see surface_distance).
class SurfaceProbe {
 public:
  SurfaceProbe(const ImplicitSurface& surface, double iso)
      : field_(surface.field),
        iso_(iso),
        clip_(surface.domain),
        clip_radius_(surface.clip_radius),
        tol_(1e-12 * surface.domain.diagonal()) {}

  Measurement operator()(const glm::dvec3& x) const {
    glm::dvec3 y = x;
    if (!newton(y)) return {0.0, Outcome::not_converged};
    // The foot point (after Hartmann 1999): project x onto the tangent plane at y, back onto the
    // surface, until the offset x − y is normal to the surface. Every y lies on the surface, so
    // the smallest |x − y| seen is kept.
    glm::dvec3 best = y;
    double best_d = glm::length(x - y);
    for (int round = 0; round < kFootRounds && best_d > 0.0; ++round) {
      glm::dvec3 grad(0.0);
      if (!std::isfinite(field_(y, grad))) break;
      const double g2 = glm::dot(grad, grad);
      if (!(g2 > 0.0)) break;
      const glm::dvec3 z = x - (glm::dot(x - y, grad) / g2) * grad;
      glm::dvec3 next = z;
      if (!newton(next)) break;
      const double moved = glm::length(next - y);
      y = next;
      if (const double d = glm::length(x - y); d < best_d) {
        best_d = d;
        best = y;
      }
      if (moved <= tol_) break;
    }
    if (!inside_clip(best)) return {best_d, Outcome::outside_clip};
    return {best_d, Outcome::measured};
  }

 private:
  static constexpr int kNewtonIterations = 100;
  static constexpr int kFootRounds = 20;

  // Newton steps along the gradient, y ← y − (f(y) − iso)·∇f/|∇f|², until a step is shorter
  // than the tolerance; false for a vanishing or non-finite gradient or no convergence.
  bool newton(glm::dvec3& y) const {
    for (int it = 0; it < kNewtonIterations; ++it) {
      glm::dvec3 grad(0.0);
      const double g = field_(y, grad) - iso_;
      if (g == 0.0) return true;
      const double g2 = glm::dot(grad, grad);
      if (!(g2 > 0.0) || !std::isfinite(g2) || !std::isfinite(g)) return false;
      const glm::dvec3 step = (g / g2) * grad;
      y -= step;
      if (glm::length(step) <= tol_) return true;
    }
    return false;
  }

  bool inside_clip(const glm::dvec3& y) const {
    const double slack = 1e3 * tol_;  // 10⁻⁹ of the domain's diagonal
    for (int a = 0; a < 3; ++a)
      if (y[a] < clip_.lo[a] - slack || y[a] > clip_.hi[a] + slack) return false;
    return clip_radius_ <= 0.0 || glm::length(y) <= clip_radius_ + slack;
  }

  const std::function<double(const glm::dvec3&, glm::dvec3&)>& field_;
  double iso_;
  Box clip_;
  double clip_radius_;
  double tol_;
};

}  // namespace

MeshDistance mesh_distance(const Mesh& a, const Mesh& b, const DistanceOptions& options) {
  const Surface sa = make_surface(a, "A"), sb = make_surface(b, "B");
  const std::uint64_t target =
      options.samples > 0 ? options.samples
                          : default_samples(std::max(sa.triangle_count(), sb.triangle_count()));
  const SamplePlan plan_a = plan_samples(sa, target), plan_b = plan_samples(sb, target);

  MeshDistance result;
  const Box box{glm::min(sa.bounds.lo, sb.bounds.lo), glm::max(sa.bounds.hi, sb.bounds.hi)};
  result.diagonal = box.diagonal();
  const double largest = std::max(sa.max_coordinate, sb.max_coordinate);
  // Float query points and float box distances inside Embree: 16 float ulps of the largest
  // coordinate cover both. Below 2⁻⁴⁰ of it a distance is rounding noise of the double
  // point–triangle computation (float positions resolve 2⁻²⁴).
  const double slack = 0x1.0p-20 * largest, zero = 0x1.0p-40 * largest;

  const EmbreeDevice device;
  const TriangleScene scene_a(device.get(), sa), scene_b(device.get(), sb);
  result.forward = measure(sa, plan_a, [&] {
                     return ClosestPointProbe(scene_b.get(), sb, slack, zero);
                   }).stats();
  result.backward = measure(sb, plan_b, [&] {
                      return ClosestPointProbe(scene_a.get(), sa, slack, zero);
                    }).stats();
  return result;
}

SurfaceDistance surface_distance(const Mesh& mesh, const SurfaceInfo& surface, double isovalue,
                                 const DistanceOptions& options) {
  if (!surface.field)
    throw std::invalid_argument("distance: surface " + surface.name + " has no field");
  return surface_distance(
      mesh, ImplicitSurface{surface.name, surface.field, surface.domain, surface.clip_radius},
      isovalue, options);
}

SurfaceDistance surface_distance(const Mesh& mesh, const ImplicitSurface& surface, double isovalue,
                                 const DistanceOptions& options) {
  if (!surface.field)
    throw std::invalid_argument("distance: surface " + surface.name + " has no field");
  const Surface s = make_surface(mesh, "A");
  const std::uint64_t target =
      options.samples > 0 ? options.samples : default_samples(s.triangle_count());
  const SamplePlan plan = plan_samples(s, target);
  const Tally tally = measure(s, plan, [&] { return SurfaceProbe(surface, isovalue); });
  SurfaceDistance result;
  result.forward = tally.stats();
  result.not_converged = tally.not_converged;
  result.outside_clip = tally.outside_clip;
  result.diagonal = s.bounds.diagonal();
  return result;
}

}  // namespace ldimesh
