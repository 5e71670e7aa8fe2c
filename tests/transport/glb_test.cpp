#include "ldimesh/transport/glb.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include <draco/compression/draco_compression_options.h>
#include <draco/core/draco_version.h>
#include <draco/core/encoder_buffer.h>
#include <draco/io/gltf_encoder.h>
#include <draco/mesh/mesh.h>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "support/quantization_caps.hpp"

namespace ldimesh {
namespace {

using Bytes = std::vector<std::uint8_t>;
using Json = nlohmann::json;

// ---- Meshes from the pipeline ---------------------------------------------------------------

Mesh surface_mesh(const char* name, int res, FaceType faces) {
  const SurfaceInfo* s = find_surface(name);
  const auto source = make_surface_source(name);
  const RayCaster caster(*source, s->isovalue);
  std::vector<Ldi> ldis;
  for (const View& v : make_axis_views(s->domain, res))
    ldis.push_back(caster.cast(v));
  MeshingOptions options;
  options.faces = faces;
  return mesh_ldis(ldis, options).mesh;
}

// The Barth sextic at 48² (three axis views, r = 0.5), with triangles and with quads.
const Mesh& barth_triangles() {
  static const Mesh m = surface_mesh("barth", 48, FaceType::triangles);
  return m;
}
const Mesh& barth_quads() {
  static const Mesh m = surface_mesh("barth", 48, FaceType::quads);
  return m;
}

// The triangle mesh with a scalar: the distance from the origin.
Mesh with_scalar(Mesh m) {
  m.scalars.clear();
  for (const glm::vec3& p : m.positions)
    m.scalars.push_back(glm::length(p));
  return m;
}

Bytes encode(const Mesh& mesh, const GlbOptions& options = {}, GlbInfo* info = nullptr) {
  Bytes out;
  const Status s = encode_glb(mesh, options, out, info);
  EXPECT_TRUE(s) << s.message();
  return out;
}

// ---- The GLB container, read independently of decode_glb -----------------------------------

std::uint32_t u32(const Bytes& b, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

Json json_chunk(const Bytes& glb) {
  const std::uint32_t len = u32(glb, 12);
  return Json::parse(glb.begin() + 20, glb.begin() + 20 + len);
}

// The bytes of the first primitive's Draco bufferView.
Bytes draco_payload(const Bytes& glb) {
  const Json j = json_chunk(glb);
  const std::size_t bin = 20 + u32(glb, 12) + 8;
  const int view =
      j["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"];
  const Json& bv = j["bufferViews"][view];
  const std::size_t offset = bv.value("byteOffset", 0), length = bv["byteLength"];
  return Bytes(glb.begin() + bin + offset, glb.begin() + bin + offset + length);
}

// ---- Matching decoded vertices to the originals ---------------------------------------------

using testing::angle_between;
using testing::octahedral_angle_cap;
using testing::unit_interval_cap;

// For every decoded vertex, the original vertex it came from: the nearest original within
// `bound` (a hash grid of cell `bound`), preferring one whose normal agrees. -1 when none.
std::vector<std::int64_t> match_vertices(const Mesh& original, const Mesh& decoded, double bound) {
  const auto cell = [bound](glm::vec3 p) {
    return glm::i64vec3(glm::floor(glm::dvec3(p) / bound));
  };
  const auto key = [](glm::i64vec3 c) {
    return (std::uint64_t(c.x) * 73856093u) ^ (std::uint64_t(c.y) * 19349663u) ^
           (std::uint64_t(c.z) * 83492791u);
  };
  std::unordered_multimap<std::uint64_t, std::uint32_t> grid;
  for (std::uint32_t i = 0; i < original.vertex_count(); ++i)
    grid.emplace(key(cell(original.positions[i])), i);
  std::vector<std::int64_t> match(decoded.vertex_count(), -1);
  for (std::size_t i = 0; i < decoded.vertex_count(); ++i) {
    const glm::vec3 p = decoded.positions[i];
    const glm::i64vec3 c = cell(p);
    double best = 1e300;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto [lo, hi] = grid.equal_range(key(c + glm::i64vec3(dx, dy, dz)));
          for (auto it = lo; it != hi; ++it) {
            const std::uint32_t j = it->second;
            const double d = glm::length(glm::dvec3(p) - glm::dvec3(original.positions[j]));
            // A wrong normal costs more than any distance within the bound.
            const double cost =
                d + (angle_between(original.normals[j], decoded.normals[i]) > 0.1 ? 1.0 : 0);
            if (d <= bound && cost < best) {
              best = cost;
              match[i] = j;
            }
          }
        }
  }
  return match;
}

// A triangle as its vertex indices rotated to start at the smallest (winding kept).
std::array<std::uint32_t, 3> canonical(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  if (b < a && b < c) return {b, c, a};
  if (c < a && c < b) return {c, a, b};
  return {a, b, c};
}

// Checks that `decoded` is `original` up to Draco's reordering and quantization: one decoded
// vertex per original within the position bound, normals within the normal bound, and the
// same triangles (same winding, same view) through that correspondence.
void expect_same_mesh(const Mesh& original, const Mesh& decoded, const GlbInfo& info,
                      const GlbOptions& options) {
  ASSERT_EQ(decoded.vertex_count(), original.vertex_count());
  ASSERT_EQ(decoded.triangle_count(), original.triangle_count());
  ASSERT_EQ(decoded.triangle_view.size(), decoded.triangle_count());
  EXPECT_EQ(decoded.view_dirs, original.view_dirs);
  const std::vector<std::int64_t> match =
      match_vertices(original, decoded, info.position_error_bound);
  std::vector<int> used(original.vertex_count(), 0);
  double worst_position = 0, worst_normal = 0;
  for (std::size_t i = 0; i < match.size(); ++i) {
    ASSERT_GE(match[i], 0) << "decoded vertex " << i << " is farther than the bound from all";
    ++used[match[i]];
    worst_position = std::max(
        worst_position,
        glm::length(glm::dvec3(decoded.positions[i]) - glm::dvec3(original.positions[match[i]])));
    worst_normal =
        std::max(worst_normal, angle_between(decoded.normals[i], original.normals[match[i]]));
  }
  EXPECT_TRUE(std::all_of(used.begin(), used.end(), [](int u) { return u == 1; }))
      << "the correspondence is not one to one";
  EXPECT_LE(worst_position, info.position_error_bound);
  EXPECT_LE(worst_normal, glb_normal_error_bound(options));
  EXPECT_LE(glb_normal_error_bound(options), octahedral_angle_cap(options.normal_bits));

  std::map<std::array<std::uint32_t, 3>, std::uint8_t> faces;
  for (std::size_t f = 0; f < original.triangle_count(); ++f) {
    const std::uint32_t* t = &original.triangles[3 * f];
    faces[canonical(t[0], t[1], t[2])] = original.triangle_view[f];
  }
  for (std::size_t f = 0; f < decoded.triangle_count(); ++f) {
    const std::uint32_t* t = &decoded.triangles[3 * f];
    const auto it = faces.find(canonical(std::uint32_t(match[t[0]]), std::uint32_t(match[t[1]]),
                                         std::uint32_t(match[t[2]])));
    ASSERT_NE(it, faces.end()) << "decoded triangle " << f << " is not an original triangle";
    EXPECT_EQ(decoded.triangle_view[f], it->second) << "triangle " << f << " changed view";
    faces.erase(it);
  }
}

// ---- Round trips ----------------------------------------------------------------------------

TEST(Glb, RoundTripKeepsTrianglesViewsAndPositionsWithinTheBound) {
  const Mesh& mesh = barth_triangles();
  ASSERT_GT(mesh.triangle_count(), 1000u);
  const GlbOptions options;
  GlbInfo info;
  const Bytes glb = encode(mesh, options, &info);
  EXPECT_EQ(info.triangles, mesh.triangle_count());
  EXPECT_EQ(info.vertices, mesh.vertex_count());
  EXPECT_EQ(info.position_bits, glb_position_bits(mesh, options));
  EXPECT_EQ(info.position_error_bound, glb_position_error_bound(mesh, options));
  EXPECT_FALSE(info.has_scalar);
  Mesh back;
  GlbInfo back_info;
  const Status s = decode_glb(glb, back, &back_info);
  ASSERT_TRUE(s) << s.message();
  EXPECT_EQ(back_info.triangles, info.triangles);
  EXPECT_EQ(back_info.vertices, info.vertices);
  EXPECT_TRUE(back.scalars.empty());
  EXPECT_TRUE(back.quads.empty());
  expect_same_mesh(mesh, back, info, options);
  for (const glm::vec3& n : back.normals)
    ASSERT_NEAR(glm::length(n), 1.0f, 1e-5f);
}

// A mesh above 200 000 triangles is encoded in parts (slabs), concurrently, as primitives of one
// mesh: the same bytes on one thread and on two; every original triangle comes back once, with
// its view; every decoded vertex within the position bound of its original (a vertex two parts
// share comes back once per part, both copies at the same point: no seam), scalars within their
// bound.
TEST(Glb, ALargeMeshIsEncodedInPartsTheSameOnAnyNumberOfThreads) {
  const Mesh mesh = with_scalar(surface_mesh("torus", 256, FaceType::triangles));
  ASSERT_GT(mesh.triangle_count(), 200000u);
  ASSERT_LT(mesh.triangle_count(), 400000u);  // two parts
  GlbInfo info;
  GlbOptions options;
  options.threads = 1;
  const Bytes one_thread = encode(mesh, options, &info);
  options.threads = 2;
  const Bytes two_threads = encode(mesh, options);
  EXPECT_TRUE(one_thread == two_threads) << "the GLB depends on the number of threads";
  const Json json = json_chunk(one_thread);
  ASSERT_EQ(json["meshes"].size(), 1u);
  ASSERT_EQ(json["meshes"][0]["primitives"].size(), 2u);
  EXPECT_EQ(json["nodes"].size(), 1u);
  EXPECT_TRUE(json["meshes"][0]["extras"]["ldimesh"].contains("scalar_range"));
  Mesh back;
  GlbInfo back_info;
  const Status s = decode_glb(one_thread, back, &back_info);
  ASSERT_TRUE(s) << s.message();
  EXPECT_EQ(back.triangle_count(), mesh.triangle_count());
  EXPECT_EQ(info.triangles, mesh.triangle_count());
  EXPECT_EQ(back.vertex_count(), info.vertices);
  EXPECT_GT(back.vertex_count(), mesh.vertex_count());              // the shared ones twice
  EXPECT_LT(back.vertex_count(), mesh.vertex_count() * 102 / 100);  // only those
  // Every original vertex within the bound of each decoded one (the meshes' views overlap: two
  // originals may lie that close), and each decoded triangle is the original triangle of one
  // choice among them.
  const double bound = info.position_error_bound, range = info.scalar_max - info.scalar_min;
  std::vector<std::vector<std::uint32_t>> near(back.vertex_count());
  {
    std::map<std::array<std::int64_t, 3>, std::vector<std::uint32_t>> grid;
    const auto cell = [bound](glm::vec3 p) {
      const glm::i64vec3 c(glm::floor(glm::dvec3(p) / bound));
      return std::array<std::int64_t, 3>{c.x, c.y, c.z};
    };
    for (std::uint32_t j = 0; j < mesh.vertex_count(); ++j)
      grid[cell(mesh.positions[j])].push_back(j);
    for (std::size_t i = 0; i < back.vertex_count(); ++i) {
      const std::array<std::int64_t, 3> c = cell(back.positions[i]);
      for (int d = 0; d < 27; ++d) {
        const auto it = grid.find({c[0] + d % 3 - 1, c[1] + d / 3 % 3 - 1, c[2] + d / 9 - 1});
        if (it == grid.end()) continue;
        for (std::uint32_t j : it->second)
          if (glm::length(glm::dvec3(back.positions[i]) - glm::dvec3(mesh.positions[j])) <= bound)
            near[i].push_back(j);
      }
      ASSERT_FALSE(near[i].empty())
          << "decoded vertex " << i << " is farther than the bound from all";
    }
  }
  std::map<std::array<std::uint32_t, 3>, std::uint8_t> faces;
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
    const std::uint32_t* t = &mesh.triangles[3 * f];
    faces[canonical(t[0], t[1], t[2])] = mesh.triangle_view[f];
  }
  std::vector<int> used(mesh.vertex_count(), 0);
  std::unordered_map<std::uint32_t, glm::vec3> decoded_at;
  std::size_t split_copies = 0;
  double worst_scalar = 0.0;
  for (std::size_t f = 0; f < back.triangle_count(); ++f) {
    const std::uint32_t* t = &back.triangles[3 * f];
    bool found = false;
    for (std::uint32_t a : near[t[0]])
      for (std::uint32_t b : near[t[1]])
        for (std::uint32_t c : near[t[2]]) {
          const auto it = found ? faces.end() : faces.find(canonical(a, b, c));
          if (it == faces.end()) continue;
          found = true;
          EXPECT_EQ(back.triangle_view[f], it->second) << "triangle " << f << " changed view";
          faces.erase(it);
          const std::uint32_t original[3] = {a, b, c};
          for (int k = 0; k < 3; ++k) {
            // Every copy of a vertex (one per part that uses it) decodes to the same point.
            const auto [first, added] = decoded_at.try_emplace(original[k], back.positions[t[k]]);
            if (!added && first->second != back.positions[t[k]]) ++split_copies;
            ++used[original[k]];
            const double value = info.scalar_min + back.scalars[t[k]] * range;
            const double err = std::abs(value - mesh.scalars[original[k]]);
            if (!(err <= worst_scalar)) worst_scalar = err;
          }
        }
    ASSERT_TRUE(found) << "decoded triangle " << f << " is not an original triangle";
  }
  EXPECT_TRUE(faces.empty()) << faces.size() << " original triangles not decoded";
  EXPECT_EQ(split_copies, 0u) << "copies of a vertex on a slab border decode apart";
  EXPECT_TRUE(std::all_of(used.begin(), used.end(), [](int u) { return u >= 1; }));
  EXPECT_LE(worst_scalar, glb_scalar_error_bound({}) * range);
  EXPECT_LE(glb_scalar_error_bound({}), unit_interval_cap(GlbOptions{}.scalar_bits));
}

// Every compression level gives the same mesh; level 0 (sequential) keeps the vertex order,
// Edgebreaker (levels ≥ 1) reorders vertices, so the other tests match by position.
TEST(Glb, EveryCompressionLevelRoundTripsAndLevelZeroKeepsTheVertexOrder) {
  const Mesh& mesh = barth_triangles();
  std::size_t previous_size = 0;
  for (int level : {0, 1, 4, 7, 10}) {
    GlbOptions options;
    options.compression_level = level;
    GlbInfo info;
    const Bytes glb = encode(mesh, options, &info);
    Mesh back;
    ASSERT_TRUE(decode_glb(glb, back)) << "level " << level;
    expect_same_mesh(mesh, back, info, options);
    if (level == 0) {
      for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
        ASSERT_LE(glm::length(glm::dvec3(back.positions[i]) - glm::dvec3(mesh.positions[i])),
                  info.position_error_bound)
            << "vertex " << i;
      EXPECT_EQ(back.triangles, mesh.triangles);
      previous_size = glb.size();
    } else {
      EXPECT_LT(glb.size(), previous_size) << "Edgebreaker should beat sequential encoding";
    }
  }
}

TEST(Glb, SameMeshSameBytes) {
  EXPECT_EQ(encode(barth_triangles()), encode(barth_triangles()));
}

// Several surfaces (a step's isovalues): a glTF mesh on a node each, the node's extras naming
// the surface, so that a viewer can show or hide each; decode_glb reads them all as one mesh.
TEST(Glb, SeveralSurfacesAreAMeshOnANodeEach) {
  const Mesh& a = barth_triangles();
  const Mesh b = surface_mesh("torus", 40, FaceType::triangles);
  Mesh both = a;
  const std::uint32_t base = std::uint32_t(a.vertex_count());
  append_mesh(both, b);
  GlbOptions options;
  options.surfaces = {0, base};
  GlbInfo info;
  const Bytes glb = encode(both, options, &info);
  EXPECT_EQ(info.triangles, both.triangle_count());
  const Json j = json_chunk(glb);
  ASSERT_EQ(j["meshes"].size(), 2u);
  ASSERT_EQ(j["nodes"].size(), 2u);
  EXPECT_EQ(j["scenes"][j.value("scene", 0)]["nodes"], Json::array({0, 1}));
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(j["nodes"][k]["mesh"], k);
    EXPECT_EQ(j["nodes"][k]["extras"]["ldimesh_surface"], k);
  }
  // Each surface's mesh holds that surface's triangles.
  GlbInfo alone;
  encode(b, {}, &alone);
  const Json& accessors = j["accessors"];
  const auto triangles_of = [&](std::size_t mesh) {
    std::size_t n = 0;
    for (const Json& p : j["meshes"][mesh]["primitives"])
      n += accessors[p["indices"].get<std::size_t>()]["count"].get<std::size_t>() / 3;
    return n;
  };
  EXPECT_EQ(triangles_of(1), alone.triangles);
  EXPECT_EQ(triangles_of(0) + triangles_of(1), info.triangles);
  Mesh back;
  ASSERT_TRUE(decode_glb(glb, back));
  EXPECT_EQ(back.triangle_count(), both.triangle_count());
  EXPECT_EQ(back.view_dirs.size(), a.view_dirs.size());

  // One surface: the bytes of none. An empty surface has no node.
  options.surfaces = {0};
  EXPECT_EQ(encode(a, options), encode(a));
  options.surfaces = {0, 0};
  const Json one = json_chunk(encode(a, options));
  ASSERT_EQ(one["nodes"].size(), 1u);
  EXPECT_EQ(one["nodes"][0]["extras"]["ldimesh_surface"], 1);
  // Offsets that do not start at 0, decrease or pass the vertices, and a face whose vertices lie
  // in two surfaces, are errors.
  for (const std::vector<std::uint32_t>& bad :
       {std::vector<std::uint32_t>{1, 5}, {0, 9, 5}, {0, base + 1}, {0, base / 2}}) {
    options.surfaces = bad;
    Bytes out;
    const Status s = encode_glb(a, options, out);
    EXPECT_EQ(s.code(), StatusCode::invalid_argument) << bad[1];
  }
}

TEST(Glb, QuadMeshesBecomeTriangles) {
  const Mesh& quads = barth_quads();
  ASSERT_GT(quads.quad_count(), 500u);
  ASSERT_EQ(quads.triangle_count(), 0u);
  GlbInfo info;
  const Bytes glb = encode(quads, {}, &info);
  EXPECT_EQ(info.triangles, 2 * quads.quad_count());
  Mesh back;
  ASSERT_TRUE(decode_glb(glb, back));
  EXPECT_EQ(back.triangle_count(), 2 * quads.quad_count());
  EXPECT_TRUE(back.quads.empty());
  // The pipeline splits quads along the shorter diagonal too, with the same winding: the
  // GLB of the quad mesh holds exactly the triangles of the triangle mesh.
  expect_same_mesh(barth_triangles(), back, info, GlbOptions{});
}

TEST(Glb, AQuadIsSplitAlongItsShorterDiagonal) {
  for (const bool ac_shorter : {true, false}) {
    Mesh m;
    // A rhombus in z = 0, counter-clockwise seen from +z; a–c is 1 long, b–d 3 (or reversed).
    const float s = ac_shorter ? 1.0f : 3.0f, l = ac_shorter ? 3.0f : 1.0f;
    m.positions = {{-s / 2, 0, 0}, {0, -l / 2, 0}, {s / 2, 0, 0}, {0, l / 2, 0}};
    m.normals.assign(4, {0, 0, 1});
    m.quads = {0, 1, 2, 3};
    m.quad_view = {0};
    m.view_dirs = {{0, 0, 1}};
    GlbOptions options;
    options.compression_level = 0;  // keeps vertex order
    Mesh back;
    ASSERT_TRUE(decode_glb(encode(m, options), back));
    ASSERT_EQ(back.triangle_count(), 2u);
    std::vector<std::array<std::uint32_t, 3>> faces;
    for (int f = 0; f < 2; ++f)
      faces.push_back(
          canonical(back.triangles[3 * f], back.triangles[3 * f + 1], back.triangles[3 * f + 2]));
    std::sort(faces.begin(), faces.end());
    using Faces = std::vector<std::array<std::uint32_t, 3>>;
    const Faces expected = ac_shorter ? Faces{{0, 1, 2}, {0, 2, 3}} : Faces{{0, 1, 3}, {1, 2, 3}};
    EXPECT_EQ(faces, expected);
  }
}

// ---- The contract of docs/api.md ------------------------------------------------------------

TEST(Glb, TheGlbIsDracoCompressedGltfWithTheContractsAttributes) {
  const Bytes glb = encode(barth_triangles());
  ASSERT_GE(glb.size(), 28u);
  EXPECT_EQ(std::memcmp(glb.data(), "glTF", 4), 0);
  EXPECT_EQ(u32(glb, 4), 2u);
  EXPECT_EQ(u32(glb, 8), glb.size());
  EXPECT_EQ(u32(glb, 16), 0x4E4F534Au);  // JSON chunk first
  EXPECT_EQ(glb.size() % 4, 0u);
  const Json j = json_chunk(glb);
  EXPECT_EQ(j["asset"]["version"], "2.0");
  for (const char* list : {"extensionsUsed", "extensionsRequired"}) {
    ASSERT_TRUE(j.contains(list)) << list;
    EXPECT_NE(std::find(j[list].begin(), j[list].end(), "KHR_draco_mesh_compression"),
              j[list].end())
        << list;
  }
  ASSERT_EQ(j["meshes"].size(), 1u);
  ASSERT_EQ(j["meshes"][0]["primitives"].size(), 1u);
  const Json& p = j["meshes"][0]["primitives"][0];
  EXPECT_EQ(p.value("mode", 4), 4);  // triangles
  const Json& draco = p["extensions"]["KHR_draco_mesh_compression"];
  for (const char* name : {"POSITION", "NORMAL", "COLOR_0"}) {
    EXPECT_TRUE(p["attributes"].contains(name)) << name;
    EXPECT_TRUE(draco["attributes"].contains(name)) << name;
  }
  EXPECT_FALSE(p["attributes"].contains("_SCALAR"));
  EXPECT_FALSE(p["attributes"].contains("TEXCOORD_0"));
  const Json& colour = j["accessors"][p["attributes"]["COLOR_0"].get<int>()];
  EXPECT_EQ(colour["type"], "VEC3");
  EXPECT_EQ(colour["componentType"], 5121);  // UNSIGNED_BYTE
  EXPECT_EQ(colour["normalized"], true);
  const Json& position = j["accessors"][p["attributes"]["POSITION"].get<int>()];
  EXPECT_EQ(position["count"], barth_triangles().vertex_count());
  EXPECT_EQ(position["min"].size(), 3u);  // glTF requires min and max on POSITION
  const Json& ours = j["meshes"][0]["extras"]["ldimesh"];
  EXPECT_EQ(ours["view_dirs"], Json::parse("[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]]"));
}

TEST(Glb, ViewColoursAreRedYellowGreenForTheAxesThenAPalette) {
  using C = std::array<std::uint8_t, 3>;
  EXPECT_EQ(view_colour(0, {1, 0, 0}), (C{255, 0, 0}));
  EXPECT_EQ(view_colour(1, {0, 1, 0}), (C{255, 215, 0}));
  EXPECT_EQ(view_colour(2, {0, 0, 1}), (C{0, 170, 0}));
  // By direction, not by index: a view along −x in third place is still red.
  EXPECT_EQ(view_colour(2, {-3, 0, 0}), (C{255, 0, 0}));
  const C oblique = view_colour(3, glm::normalize(glm::dvec3(1, 1, 0)));
  for (const C axis : {C{255, 0, 0}, C{255, 215, 0}, C{0, 170, 0}})
    EXPECT_NE(oblique, axis);
  EXPECT_NE(view_colour(3, {1, 1, 0}), view_colour(4, {1, 1, 0}));
}

// Debian's draco_decoder tool (an independent reader of the bitstream) run on the GLB's Draco
// data: the file it writes (`extension` .ply or .obj), or "" when the tool fails.
std::string draco_decoder_output(const Bytes& glb, const std::string& extension) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("ldimesh_glb_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string drc = (dir / "mesh.drc").string(), out = (dir / ("mesh" + extension)).string();
  const Bytes payload = draco_payload(glb);
  std::ofstream(drc, std::ios::binary)
      .write(reinterpret_cast<const char*>(payload.data()), std::streamsize(payload.size()));
  std::string text;
  if (std::system(("draco_decoder -i " + drc + " -o " + out + " > /dev/null").c_str()) == 0) {
    std::ifstream in(out, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::filesystem::remove_all(dir);
  return text;
}

bool have_draco_decoder() {
  return std::system("command -v draco_decoder > /dev/null 2>&1") == 0;
}

// The PLY header draco_decoder writes for `mesh`'s GLB, checked for its vertex and face counts.
std::string expect_draco_decoder_counts(const Mesh& mesh) {
  const std::string ply = draco_decoder_output(encode(mesh), ".ply");
  const std::string header = ply.substr(0, ply.find("end_header"));
  EXPECT_NE(header.find("element vertex " + std::to_string(mesh.vertex_count()) + "\n"),
            std::string::npos)
      << header;
  EXPECT_NE(header.find("element face " + std::to_string(mesh.triangle_count()) + "\n"),
            std::string::npos)
      << header;
  return header;
}

TEST(Glb, DracosOwnDecoderToolReadsCountsAndColours) {
  if (!have_draco_decoder()) GTEST_SKIP() << "draco_decoder not installed (Debian: draco)";
  const std::string header = expect_draco_decoder_counts(barth_triangles());
  EXPECT_NE(header.find("property uchar red"), std::string::npos) << header;
}

// The scalar is a GENERIC attribute in the Draco data: a decoder that knows nothing of it (the
// tool writes no such property) still reads the mesh.
TEST(Glb, DracosOwnDecoderToolReadsAMeshWithTheScalar) {
  if (!have_draco_decoder()) GTEST_SKIP() << "draco_decoder not installed (Debian: draco)";
  expect_draco_decoder_counts(with_scalar(barth_triangles()));
}

// A GLB as ldimesh wrote them before _SCALAR: the scalar as TEXCOORD_0 = (u, 0), by Draco's glTF
// encoder itself (so v = 1 here, flipped on the way out). decode_glb reads u as the scalar.
TEST(Glb, AnOlderGlbWithTheScalarAsTexcoordStillDecodes) {
  const Mesh& mesh = barth_triangles();
  const std::size_t n = mesh.vertex_count();
  draco::Mesh dm;
  dm.set_num_points(std::uint32_t(n));
  const auto add = [&](draco::GeometryAttribute::Type type, int components, const void* data) {
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, std::uint8_t(components), draco::DT_FLOAT32, false,
            std::int64_t(sizeof(float)) * components, 0);
    const int id = dm.AddAttribute(ga, true, std::uint32_t(n));
    dm.attribute(id)->buffer()->Write(0, data, n * sizeof(float) * components);
  };
  std::vector<std::array<float, 2>> uv(n);
  for (std::size_t i = 0; i < n; ++i)
    uv[i] = {float(i % 101) / 100.0f, 1.0f};
  add(draco::GeometryAttribute::POSITION, 3, mesh.positions.data());
  add(draco::GeometryAttribute::NORMAL, 3, mesh.normals.data());
  add(draco::GeometryAttribute::TEX_COORD, 2, uv.data());
  dm.SetNumFaces(mesh.triangle_count());
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f)
    dm.SetFace(draco::FaceIndex(std::uint32_t(f)), {draco::PointIndex(mesh.triangles[3 * f]),
                                                    draco::PointIndex(mesh.triangles[3 * f + 1]),
                                                    draco::PointIndex(mesh.triangles[3 * f + 2])});
  draco::DracoCompressionOptions compression;
  compression.compression_level = 0;  // sequential: keeps the vertex order
  compression.quantization_position.SetQuantizationBits(16);
  compression.quantization_bits_tex_coord = 12;
  dm.SetCompressionEnabled(true);
  dm.SetCompressionOptions(compression);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(draco::GltfEncoder().EncodeToBuffer(dm, &buffer).ok());
  const Bytes glb(buffer.data(), buffer.data() + buffer.size());
  ASSERT_TRUE(json_chunk(glb)["meshes"][0]["primitives"][0]["attributes"].contains("TEXCOORD_0"));

  Mesh back;
  GlbInfo info;
  const Status s = decode_glb(glb, back, &info);
  ASSERT_TRUE(s) << s.message();
  EXPECT_TRUE(info.has_scalar);
  ASSERT_EQ(back.scalars.size(), n);
  for (std::size_t i = 0; i < n; ++i)
    ASSERT_NEAR(back.scalars[i], uv[i][0], 1.0 / 4095) << i;
}

// decode_glb_isolated gives decode_glb's mesh, info and errors, from a child process.
TEST(Glb, AnIsolatedDecodeGivesWhatDecodeGlbGives) {
  const Bytes glb = encode(with_scalar(barth_triangles()));
  Mesh a, b;
  GlbInfo ia, ib;
  ASSERT_TRUE(decode_glb(glb, a, &ia));
  const Status s = decode_glb_isolated(glb, b, &ib);
  ASSERT_TRUE(s) << s.message();
  EXPECT_GT(b.triangle_count(), 1000u);
  EXPECT_EQ(b.positions, a.positions);
  EXPECT_EQ(b.normals, a.normals);
  EXPECT_EQ(b.scalars, a.scalars);
  EXPECT_EQ(b.quads, a.quads);
  EXPECT_EQ(b.triangles, a.triangles);
  EXPECT_EQ(b.quad_view, a.quad_view);
  EXPECT_EQ(b.triangle_view, a.triangle_view);
  EXPECT_EQ(b.view_dirs, a.view_dirs);
  EXPECT_EQ(ib.triangles, ia.triangles);
  EXPECT_EQ(ib.vertices, ia.vertices);
  EXPECT_EQ(ib.has_scalar, ia.has_scalar);
  EXPECT_TRUE(ib.has_scalar);
  EXPECT_EQ(ib.scalar_min, ia.scalar_min);
  EXPECT_EQ(ib.scalar_max, ia.scalar_max);
  // An error comes back as decode_glb's, and `out` stays as it was.
  const Bytes cut(glb.begin(), glb.begin() + std::ptrdiff_t(glb.size() / 2));
  const Status direct = decode_glb(cut, a);
  ASSERT_FALSE(direct);
  const Status isolated = decode_glb_isolated(cut, b);
  EXPECT_EQ(isolated.code(), direct.code());
  EXPECT_EQ(isolated.message(), direct.message());
  EXPECT_EQ(b.positions, a.positions);
  EXPECT_EQ(decode_glb_isolated(glb, b, nullptr, 0.5).code(), StatusCode::invalid_argument);
}

// A GLB whose Draco stream makes Debian's Draco 1.5.5 spend seconds (7.7 s here in the Release
// build): made from `ldimesh mesh --surface sphere --res 8 --out s.glb`, re-encoded by
// draco::GltfEncoder at level 7 with a TEXCOORD_0 (as ldimesh wrote the colour field before
// _SCALAR), then the texture-coordinate predictor's orientation count (the int32 at offset 1017
// of the BIN chunk, 114) set to 2^31 − 1: the decoder decodes that many orientation bits from
// the stream's few bytes (docs/reliability.md). decode_glb_isolated stops it at its CPU limit.
TEST(Glb, AnIsolatedDecodeStopsDracoAtItsCpuLimit) {
  // The stream aims at Draco 1.5's unchecked count (Debian 12's libdraco 1.5.5); a Draco that
  // checks it refuses the file at once, which says nothing about the limit.
  if (!std::string_view(draco::kDracoVersion).starts_with("1.5."))
    GTEST_SKIP() << "Draco " << draco::kDracoVersion << ", not 1.5";
  std::ifstream in(LDIMESH_TRANSPORT_TEST_DATA "/slow_texcoord_predictor.glb", std::ios::binary);
  const Bytes glb((std::istreambuf_iterator<char>(in)), {});
  ASSERT_EQ(glb.size(), 2064u);
  EXPECT_EQ(glb_decode_cpu_limit(glb.size()), 2.0);
  EXPECT_EQ(glb_decode_cpu_limit(std::size_t(3) << 20), 17.0);
  Mesh out;
  out.positions = {{1, 2, 3}};
  const Status s = decode_glb_isolated(glb, out, nullptr, 1.0);
  EXPECT_EQ(s.code(), StatusCode::corrupt_input);
  EXPECT_NE(s.message().find("took more than 1 s of CPU"), std::string::npos) << s.message();
  EXPECT_EQ(out.positions.size(), 1u);
}

TEST(Glb, ScalarsTravelAsAnAttributeNormalizedToTheirRange) {
  const Mesh mesh = with_scalar(barth_triangles());
  const auto [lo, hi] = std::minmax_element(mesh.scalars.begin(), mesh.scalars.end());
  GlbOptions options;
  options.compression_level = 0;  // keeps vertex order: compare by index
  GlbInfo info;
  const Bytes glb = encode(mesh, options, &info);
  EXPECT_TRUE(info.has_scalar);
  EXPECT_EQ(info.scalar_min, *lo);
  EXPECT_EQ(info.scalar_max, *hi);
  const Json j = json_chunk(glb);
  const Json& p = j["meshes"][0]["primitives"][0];
  ASSERT_TRUE(p["attributes"].contains("_SCALAR"));
  EXPECT_TRUE(p["extensions"]["KHR_draco_mesh_compression"]["attributes"].contains("_SCALAR"));
  EXPECT_FALSE(p["attributes"].contains("TEXCOORD_0"));
  const Json& accessor = j["accessors"][p["attributes"]["_SCALAR"].get<int>()];
  EXPECT_EQ(accessor["type"], "SCALAR");
  EXPECT_EQ(accessor["componentType"], 5126);  // FLOAT
  EXPECT_EQ(accessor["count"], mesh.vertex_count());
  EXPECT_EQ(j["meshes"][0]["extras"]["ldimesh"]["scalar_range"],
            Json::array({double(*lo), double(*hi)}));

  Mesh back;
  GlbInfo back_info;
  ASSERT_TRUE(decode_glb(glb, back, &back_info));
  EXPECT_TRUE(back_info.has_scalar);
  EXPECT_EQ(back_info.scalar_min, *lo);
  EXPECT_EQ(back_info.scalar_max, *hi);
  ASSERT_EQ(back.scalars.size(), mesh.vertex_count());
  double worst = 0;
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    const double u = (double(mesh.scalars[i]) - *lo) / (double(*hi) - *lo);
    worst = std::max(worst, std::abs(double(back.scalars[i]) - u));
  }
  EXPECT_LE(worst, glb_scalar_error_bound(options));
  EXPECT_LE(glb_scalar_error_bound(options), unit_interval_cap(options.scalar_bits));
  EXPECT_GT(worst, 0.0);  // quantized, as documented
  EXPECT_EQ(*std::min_element(back.scalars.begin(), back.scalars.end()), 0.0f);
  EXPECT_EQ(*std::max_element(back.scalars.begin(), back.scalars.end()), 1.0f);
}

TEST(Glb, AGivenScalarRangeIsUsedAndClampsToIt) {
  Mesh mesh = with_scalar(barth_triangles());
  const auto [lo, hi] = std::minmax_element(mesh.scalars.begin(), mesh.scalars.end());
  const float mid = 0.5f * (*lo + *hi);
  GlbOptions options;
  options.compression_level = 0;
  options.scalar_range = std::array<float, 2>{mid, *hi + (*hi - *lo)};
  GlbInfo info;
  Mesh back;
  ASSERT_TRUE(decode_glb(encode(mesh, options, &info), back));
  EXPECT_EQ(info.scalar_min, mid);
  const auto [range_lo, range_hi] = *options.scalar_range;
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    const double u =
        std::clamp((double(mesh.scalars[i]) - range_lo) / (double(range_hi) - range_lo), 0.0, 1.0);
    ASSERT_NEAR(back.scalars[i], u, glb_scalar_error_bound(options)) << i;
  }
}

// ---- Bounds ---------------------------------------------------------------------------------

// Surfaces coloured by different fields, or not at all (the adaptor's "colour_by" per
// isovalue, GlbOptions::scalar_groups): each group's surfaces are normalized to the group's own
// range, a surface of group −1 has no _SCALAR (NaN once decoded), and the extras and GlbInfo give
// each surface's range.
TEST(Glb, SurfacesColouredByDifferentFieldsKeepARangeEach) {
  Mesh parts[3] = {with_scalar(barth_triangles()),
                   with_scalar(surface_mesh("torus", 40, FaceType::triangles)),
                   with_scalar(surface_mesh("torus", 24, FaceType::triangles))};
  for (float& x : parts[2].scalars)  // another field, in other units
    x = 1000.0f - 50.0f * x;
  Mesh all;
  std::vector<std::uint32_t> starts;
  for (const Mesh& m : parts) {
    starts.push_back(std::uint32_t(all.vertex_count()));
    append_mesh(all, m);
  }
  std::array<float, 2> range[3];
  for (int k = 0; k < 3; ++k) {
    const auto [lo, hi] = std::minmax_element(parts[k].scalars.begin(), parts[k].scalars.end());
    range[k] = {*lo, *hi};
  }
  GlbOptions options;
  options.compression_level = 0;  // keeps each surface's vertex order: compare by index
  options.surfaces = starts;

  for (const std::vector<int>& groups : {std::vector<int>{0, -1, 1}, std::vector<int>{0, -1, 0}}) {
    SCOPED_TRACE(groups[2]);
    options.scalar_groups = groups;
    // Surfaces 0 and 2 in one group share the range over both.
    const std::array<float, 2> range2 =
        groups[2] == 1 ? range[2]
                       : std::array<float, 2>{std::min(range[0][0], range[2][0]),
                                              std::max(range[0][1], range[2][1])};
    const std::array<float, 2> range0 = groups[2] == 1 ? range[0] : range2;
    GlbInfo info;
    const Bytes glb = encode(all, options, &info);
    const Json j = json_chunk(glb);
    ASSERT_EQ(j["meshes"].size(), 3u);
    for (std::size_t k = 0; k < 3; ++k)
      EXPECT_EQ(j["meshes"][k]["primitives"][0]["attributes"].contains("_SCALAR"), k != 1) << k;
    const Json& extras = j["meshes"][0]["extras"]["ldimesh"];
    EXPECT_EQ(extras["surface_scalar_ranges"],
              Json::array({Json::array({range0[0], range0[1]}), Json(),
                           Json::array({range2[0], range2[1]})}));
    EXPECT_TRUE(info.has_scalar);
    ASSERT_EQ(info.surface_scalar_ranges.size(), 3u);
    EXPECT_EQ(info.surface_scalar_ranges[0], range0);
    EXPECT_FALSE(info.surface_scalar_ranges[1].has_value());
    EXPECT_EQ(info.surface_scalar_ranges[2], range2);
    if (groups[2] == 1) {  // two ranges: no one scalar_range
      EXPECT_FALSE(extras.contains("scalar_range"));
      EXPECT_EQ(info.scalar_min, 0.0f);
      EXPECT_EQ(info.scalar_max, 0.0f);
    } else {
      EXPECT_EQ(extras["scalar_range"], Json::array({range0[0], range0[1]}));
      EXPECT_EQ(info.scalar_min, range0[0]);
      EXPECT_EQ(info.scalar_max, range0[1]);
    }

    Mesh back;
    GlbInfo back_info;
    ASSERT_TRUE(decode_glb(glb, back, &back_info));
    EXPECT_TRUE(back_info.has_scalar);
    EXPECT_EQ(back_info.surface_scalar_ranges, info.surface_scalar_ranges);
    // The isolated decoder gives the same, NaN included (bit for bit).
    Mesh isolated;
    GlbInfo isolated_info;
    ASSERT_TRUE(decode_glb_isolated(glb, isolated, &isolated_info));
    EXPECT_EQ(isolated_info.surface_scalar_ranges, back_info.surface_scalar_ranges);
    ASSERT_EQ(isolated.scalars.size(), back.scalars.size());
    EXPECT_EQ(std::memcmp(isolated.scalars.data(), back.scalars.data(),
                          back.scalars.size() * sizeof(float)),
              0);
    ASSERT_EQ(back.vertex_count(), all.vertex_count());
    ASSERT_EQ(back.scalars.size(), all.vertex_count());
    for (std::size_t k = 0; k < 3; ++k) {
      const std::size_t first = starts[k], last = k + 1 < 3 ? starts[k + 1] : all.vertex_count();
      const std::array<float, 2> r = k == 0 ? range0 : range2;
      double worst = 0.0;
      for (std::size_t v = first; v < last; ++v) {
        if (k == 1) {
          ASSERT_TRUE(std::isnan(back.scalars[v])) << v;
          continue;
        }
        const double u = (double(all.scalars[v]) - r[0]) / (double(r[1]) - r[0]);
        const double err = std::abs(double(back.scalars[v]) - u);
        if (!(err <= worst)) worst = err;
      }
      EXPECT_LE(worst, glb_scalar_error_bound(options)) << "surface " << k;
    }
  }

  // One entry per surface, each −1 or a group below the surfaces' count, and scalars where a
  // surface is coloured.
  for (const std::vector<int>& bad :
       {std::vector<int>{0, -1}, std::vector<int>{0, -2, 0}, std::vector<int>{0, 3, 0}}) {
    options.scalar_groups = bad;
    Bytes out;
    EXPECT_EQ(encode_glb(all, options, out).code(), StatusCode::invalid_argument);
  }
  Mesh plain = all;
  plain.scalars.clear();
  options.scalar_groups = {0, -1, 0};
  Bytes out;
  EXPECT_EQ(encode_glb(plain, options, out).code(), StatusCode::invalid_argument);
  options.scalar_groups = {-1, -1, -1};
  ASSERT_TRUE(encode_glb(plain, options, out));
  Mesh back;
  ASSERT_TRUE(decode_glb(out, back));
  EXPECT_TRUE(back.scalars.empty());

  // One surface: group −1 leaves the mesh's scalars out, group 0 is the plain encoding with the
  // surface's range in the extras.
  GlbOptions one;
  one.scalar_groups = {-1};
  GlbInfo info;
  const Json none = json_chunk(encode(parts[0], one, &info));
  EXPECT_FALSE(none["meshes"][0]["primitives"][0]["attributes"].contains("_SCALAR"));
  EXPECT_FALSE(info.has_scalar);
  EXPECT_EQ(none["meshes"][0]["extras"]["ldimesh"]["surface_scalar_ranges"], Json::array({Json()}));
  one.scalar_groups = {0};
  const Bytes coloured = encode(parts[0], one, &info);
  const Json j = json_chunk(coloured);
  EXPECT_TRUE(j["meshes"][0]["primitives"][0]["attributes"].contains("_SCALAR"));
  EXPECT_EQ(j["meshes"][0]["extras"]["ldimesh"]["surface_scalar_ranges"],
            Json::array({Json::array({range[0][0], range[0][1]})}));
  EXPECT_EQ(draco_payload(coloured), draco_payload(encode(parts[0])));
}

TEST(Glb, AutomaticPositionBitsKeepTheStepBelowATenthOfAPixel) {
  const Mesh& mesh = barth_triangles();
  const SurfaceInfo* s = find_surface("barth");
  for (const int res : {48, 512, 4096}) {
    GlbOptions options;
    options.pixel_size = make_axis_views(s->domain, res)[0].spacing;
    const int bits = glb_position_bits(mesh, options);
    glm::vec3 lo = mesh.positions[0], hi = lo;
    for (const glm::vec3& p : mesh.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    const double range = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    const double step = range / double((1u << bits) - 1);
    EXPECT_LE(step, 0.1 * options.pixel_size) << res;
    EXPECT_GT(range / double((1u << (bits - 1)) - 1), 0.1 * options.pixel_size) << "fewest";
    // The bound: half a step per coordinate, √3 of it in space (plus float rounding).
    EXPECT_LT(glb_position_error_bound(mesh, options), 0.1 * options.pixel_size);
  }
  GlbOptions fixed;
  fixed.position_bits = 17;
  EXPECT_EQ(glb_position_bits(mesh, fixed), 17);
}

TEST(Glb, FewerPositionBitsStillMeetTheirBound) {
  const Mesh& mesh = barth_triangles();
  for (const int bits : {8, 11, 20}) {
    GlbOptions options;
    options.position_bits = bits;
    GlbInfo info;
    Mesh back;
    ASSERT_TRUE(decode_glb(encode(mesh, options, &info), back));
    EXPECT_EQ(info.position_bits, bits);
    if (bits >= 11) {
      expect_same_mesh(mesh, back, info, options);
    } else {
      // 8 bits merge nearby vertices' cells; counts and the bound still hold by index order.
      GlbOptions sequential = options;
      sequential.compression_level = 0;
      GlbInfo sequential_info;
      ASSERT_TRUE(decode_glb(encode(mesh, sequential, &sequential_info), back));
      for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
        ASSERT_LE(glm::length(glm::dvec3(back.positions[i]) - glm::dvec3(mesh.positions[i])),
                  sequential_info.position_error_bound);
    }
  }
}

// ---- Empty and invalid input ----------------------------------------------------------------

TEST(Glb, AMeshWithoutFacesGivesAValidGlbWithoutMeshes) {
  Mesh empty;
  GlbInfo info;
  const Bytes glb = encode(empty, {}, &info);
  EXPECT_EQ(info.triangles, 0u);
  EXPECT_EQ(std::memcmp(glb.data(), "glTF", 4), 0);
  EXPECT_EQ(u32(glb, 8), glb.size());
  const Json j = json_chunk(glb);
  EXPECT_EQ(j["asset"]["version"], "2.0");
  EXPECT_FALSE(j.contains("meshes"));
  Mesh back = barth_triangles();
  ASSERT_TRUE(decode_glb(glb, back));
  EXPECT_EQ(back.vertex_count(), 0u);
  EXPECT_EQ(back.triangle_count(), 0u);

  Mesh points;  // vertices, no faces
  points.positions = {{0, 0, 0}, {1, 0, 0}};
  points.normals = {{0, 0, 1}, {0, 0, 1}};
  EXPECT_EQ(encode(points), glb);
}

TEST(Glb, InvalidMeshesAndOptionsAreRejected) {
  const Mesh& good = barth_triangles();
  Bytes out = {1, 2, 3};
  const auto rejects = [&](const Mesh& m, const GlbOptions& o) {
    const Status s = encode_glb(m, o, out);
    return !s && !s.message().empty() && out == Bytes{1, 2, 3};
  };
  Mesh m = good;
  m.normals.pop_back();
  EXPECT_TRUE(rejects(m, {}));
  m = good;
  m.triangles[5] = std::uint32_t(m.vertex_count());
  EXPECT_TRUE(rejects(m, {}));
  m = good;
  m.triangle_view.pop_back();
  EXPECT_TRUE(rejects(m, {}));
  m = good;
  m.positions[3].y = std::nanf("");
  EXPECT_TRUE(rejects(m, {}));
  m = with_scalar(good);
  m.scalars[7] = INFINITY;
  EXPECT_TRUE(rejects(m, {}));
  m = with_scalar(good);
  m.scalars.pop_back();
  EXPECT_TRUE(rejects(m, {}));
  // Finite, but a box wider than float's range / 2 (Draco's quantization overflows, and its
  // encoder crashed: found by fuzzing); one just inside is encoded.
  m = good;
  m.positions[0] = glm::vec3(-1.7e38f, 0.0f, 0.0f);
  m.positions[1] = glm::vec3(1.7e38f, 0.0f, 0.0f);
  EXPECT_TRUE(rejects(m, {}));
  m.positions[1] = glm::vec3(0.0f);
  m.positions[0] = glm::vec3(-1.6e38f, 0.0f, 0.0f);
  Bytes wide;
  EXPECT_TRUE(encode_glb(m, {}, wide));
  for (const auto& change : std::vector<void (*)(GlbOptions&)>{
           [](GlbOptions& o) { o.position_bits = 31; }, [](GlbOptions& o) { o.position_bits = -1; },
           [](GlbOptions& o) { o.normal_bits = 1; }, [](GlbOptions& o) { o.scalar_bits = 0; },
           [](GlbOptions& o) { o.compression_level = 11; },
           [](GlbOptions& o) { o.pixel_size = -1; },
           [](GlbOptions& o) {
             o.scalar_range = std::array<float, 2>{1, 1};
           }}) {
    GlbOptions o;
    change(o);
    EXPECT_TRUE(rejects(good, o));
  }
}

TEST(Glb, GarbageTruncatedAndEmptyBuffersAreRejected) {
  const Bytes glb = encode(barth_triangles());
  const Mesh sentinel = barth_quads();
  Mesh out = sentinel;
  const auto rejected = [&](std::span<const std::uint8_t> bytes) {
    const Status s = decode_glb(bytes, out);
    return !s && !s.message().empty() && out.quads == sentinel.quads;
  };
  EXPECT_TRUE(rejected({}));
  EXPECT_TRUE(rejected(std::span(glb).first(11)));
  // Every truncation, at a spread of lengths (and the header's length left as it was).
  for (std::size_t n = 0; n < glb.size(); n += 1 + n / 8)
    EXPECT_TRUE(rejected(std::span(glb).first(n))) << n;
  // The header's length made to match a truncated buffer: chunks then run past the end.
  for (const std::size_t n : {std::size_t(24), glb.size() / 2, glb.size() - 4}) {
    Bytes cut(glb.begin(), glb.begin() + std::ptrdiff_t(n));
    const std::uint32_t len = std::uint32_t(n);
    std::memcpy(cut.data() + 8, &len, 4);
    EXPECT_TRUE(rejected(cut)) << n;
  }
  std::mt19937 rng(7);
  for (const std::size_t n : {1, 12, 100, 5000}) {
    Bytes noise(n);
    for (auto& b : noise)
      b = std::uint8_t(rng());
    EXPECT_TRUE(rejected(noise));
    std::memcpy(noise.data(), "glTF", std::min<std::size_t>(n, 4));
    EXPECT_TRUE(rejected(noise));
  }
  Bytes bad = glb;
  bad[0] = 'x';
  EXPECT_TRUE(rejected(bad));
  bad = glb;
  bad[4] = 1;  // glTF 1
  EXPECT_TRUE(rejected(bad));
  bad = glb;
  bad[20] = '[';  // the JSON's opening brace
  EXPECT_TRUE(rejected(bad));
  // Draco bytes replaced by noise.
  bad = glb;
  const std::size_t bin = 20 + u32(glb, 12) + 8;
  for (std::size_t i = bin; i < bad.size(); ++i)
    bad[i] = std::uint8_t(rng());
  EXPECT_TRUE(rejected(bad));
}

// Hostile JSON around valid Draco data: references out of range, wrong types, accessor counts
// that disagree with the Draco mesh, an uncompressed primitive.
TEST(Glb, HostileJsonIsRejected) {
  const Bytes glb = encode(barth_triangles());
  const Json j = json_chunk(glb);
  const std::size_t bin_at = 20 + u32(glb, 12);
  const Bytes bin_chunk(glb.begin() + std::ptrdiff_t(bin_at), glb.end());
  const auto rebuild = [&](const Json& json) {
    std::string text = json.dump();
    text.resize((text.size() + 3) / 4 * 4, ' ');
    Bytes out(12);
    std::memcpy(out.data(), "glTF", 4);
    const std::uint32_t version = 2, len = std::uint32_t(text.size()), type = 0x4E4F534A;
    std::memcpy(out.data() + 4, &version, 4);
    out.resize(20);
    std::memcpy(out.data() + 12, &len, 4);
    std::memcpy(out.data() + 16, &type, 4);
    out.insert(out.end(), text.begin(), text.end());
    out.insert(out.end(), bin_chunk.begin(), bin_chunk.end());
    const std::uint32_t total = std::uint32_t(out.size());
    std::memcpy(out.data() + 8, &total, 4);
    return out;
  };
  Mesh out;
  ASSERT_TRUE(decode_glb(rebuild(j), out)) << "the rebuilt GLB itself is fine";
  const std::string draco = "/meshes/0/primitives/0/extensions/KHR_draco_mesh_compression";
  const std::vector<std::pair<std::string, Json>> edits = {
      {draco + "/bufferView", 99},
      {draco + "/bufferView", -1},
      {draco + "/bufferView", "0"},
      {draco + "/attributes/POSITION", 77},
      {draco + "/attributes/NORMAL", -3},
      {"/bufferViews/0/byteLength", 1u << 30},
      {"/bufferViews/0/byteOffset", 1u << 30},
      {"/bufferViews/0/buffer", 1},
      {"/accessors/0/count", 5},
      {"/accessors/1/count", "many"},
      {"/meshes/0/primitives/0/mode", 0},
      {"/meshes/0/primitives/0/extensions", Json::object()},
      {"/meshes/0/primitives/0", 3},
      {"/meshes/0/primitives", Json::object()},
      {"/meshes", 1},
      {"/asset/version", "1.0"},
      {"/meshes/0/extras/ldimesh/view_dirs/0", "x"},
  };
  for (const auto& [pointer, value] : edits) {
    Json edited = j;
    edited[Json::json_pointer(pointer)] = value;
    EXPECT_FALSE(decode_glb(rebuild(edited), out)) << pointer << " = " << value.dump();
  }
  // Ranges in the extras beyond float's (converting them would be undefined behaviour, which
  // the UBSan build reports) or not pairs of numbers: not read, the mesh decodes.
  for (const Json& range : {Json::array({1e300, 0.0}), Json::array({0.0, -1e39}), Json("wide"),
                            Json::array({0.0, 1.0, 2.0})}) {
    Json edited = j;
    edited["meshes"][0]["extras"]["ldimesh"]["scalar_range"] = range;
    edited["meshes"][0]["extras"]["ldimesh"]["surface_scalar_ranges"] = Json::array({range});
    GlbInfo info;
    ASSERT_TRUE(decode_glb(rebuild(edited), out, &info)) << range.dump();
    EXPECT_EQ(info.scalar_min, 0.0f);
    EXPECT_EQ(info.scalar_max, 0.0f);
    EXPECT_TRUE(info.surface_scalar_ranges.empty()) << range.dump();
  }
}

// Flipped bytes anywhere in the Draco data: decoding either fails with a Status or yields a
// mesh whose indices are in range; it never crashes (run under the sanitizers to be sure).
TEST(Glb, CorruptedDracoDataNeverCrashes) {
  const Bytes glb = encode(barth_triangles());
  const std::size_t bin = 20 + u32(glb, 12) + 8;
  std::mt19937 rng(11);
  int rejected = 0;
  for (int trial = 0; trial < 400; ++trial) {
    Bytes bad = glb;
    const int flips = 1 + int(rng() % 4);
    for (int k = 0; k < flips; ++k) {
      // Mostly the first bytes (header, counts, connectivity), where damage matters most.
      const std::size_t span = trial % 2 ? 64 : bad.size() - bin;
      bad[bin + rng() % std::min(span, bad.size() - bin)] ^= std::uint8_t(1u << (rng() % 8));
    }
    Mesh out;
    if (!decode_glb(bad, out)) {
      ++rejected;
      continue;
    }
    for (const std::uint32_t i : out.triangles)
      ASSERT_LT(i, out.vertex_count());
    ASSERT_EQ(out.normals.size(), out.vertex_count());
    ASSERT_EQ(out.triangle_view.size(), out.triangle_count());
  }
  EXPECT_GT(rejected, 0);
}

}  // namespace
}  // namespace ldimesh
