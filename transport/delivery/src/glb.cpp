// Mesh ⇄ glTF 2.0 binary with KHR_draco_mesh_compression (docs/method.md, "Mesh encoding").
//
// References: the glTF 2.0 specification, "GLB File Format Specification" (12-byte header,
// JSON chunk first, optional BIN chunk, chunks 4-byte aligned, unknown chunks ignored),
// KHR_draco_mesh_compression (the extension's bufferView holds one Draco mesh; its "attributes" map
// glTF attribute names to Draco unique ids; accessor counts must equal the decoded ones),
// Draco 1.5.5 sources (gltf_encoder.cc, attribute_quantization_transform.cc,
// normal_compression_utils.h).
#include "ldimesh/transport/glb.hpp"

#include "glb_format.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <system_error>
#include <thread>
#include <unordered_map>

#include <sched.h>

#include <draco/compression/decode.h>
#include <draco/compression/draco_compression_options.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/io/gltf_encoder.h>
#include <draco/mesh/mesh.h>
#include <draco/metadata/geometry_metadata.h>
#include <nlohmann/json.hpp>

namespace ldimesh {
namespace {

using namespace glb_format;

void append_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
  out.insert(out.end(), p, p + 4);
}

// The GLB container around `json` and (when non-empty) `bin`, both padded to 4 bytes as
// the GLB format asks: JSON with spaces, BIN with zeros.
std::vector<std::uint8_t> assemble_glb(const std::string& json, std::span<const std::uint8_t> bin) {
  const std::size_t json_len = (json.size() + 3) & ~std::size_t(3);
  const std::size_t bin_len = (bin.size() + 3) & ~std::size_t(3);
  const std::size_t total =
      kGlbHeader + kChunkHeader + json_len + (bin.empty() ? 0 : kChunkHeader + bin_len);
  std::vector<std::uint8_t> out;
  out.reserve(total);
  append_u32(out, kGlbMagic);
  append_u32(out, kGlbVersion);
  append_u32(out, std::uint32_t(total));
  append_u32(out, std::uint32_t(json_len));
  append_u32(out, kChunkJson);
  out.insert(out.end(), json.begin(), json.end());
  out.resize(out.size() + (json_len - json.size()), ' ');
  if (!bin.empty()) {
    append_u32(out, std::uint32_t(bin_len));
    append_u32(out, kChunkBin);
    out.insert(out.end(), bin.begin(), bin.end());
    out.resize(out.size() + (bin_len - bin.size()), 0);
  }
  return out;
}

// Draco's quantization range: the largest side of the bounding box, 1 for a point
// (AttributeQuantizationTransform::ComputeParameters).
double quantization_range(const BoundingBox& b) {
  const glm::dvec3 e = b.hi - b.lo;
  const double r = std::max({e.x, e.y, e.z});
  return r > 0.0 ? r : 1.0;
}

Status check_options(const GlbOptions& o) {
  if (o.position_bits < 0 || o.position_bits > 30)
    return Status::invalid_argument("glb: position_bits must be 0 (automatic) or 1..30");
  if (!std::isfinite(o.pixel_size) || o.pixel_size < 0.0)
    return Status::invalid_argument("glb: pixel_size must be finite and ≥ 0");
  if (o.normal_bits < 2 || o.normal_bits > 30)
    return Status::invalid_argument("glb: normal_bits must be 2..30");
  if (o.scalar_bits < 1 || o.scalar_bits > 30)
    return Status::invalid_argument("glb: scalar_bits must be 1..30");
  if (o.threads < 0) return Status::invalid_argument("glb: threads must be ≥ 0");
  if (o.compression_level < 0 || o.compression_level > 10)
    return Status::invalid_argument("glb: compression_level must be 0..10");
  if (o.scalar_range) {
    const auto [lo, hi] = *o.scalar_range;
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi))
      return Status::invalid_argument("glb: scalar_range must be finite with min < max");
  }
  return Status::ok();
}

// What the encoder needs beyond check_mesh: glTF's 31-bit index counts, a box Draco can quantize.
Status check_encodable(const Mesh& m) {
  const std::size_t n = m.vertex_count();
  if (n > kMaxIndex) return Status::invalid_argument("glb: more than 2^31 - 1 vertices");
  LDIMESH_RETURN_IF_ERROR(
      check_mesh(m, {.views_per_face = true, .finite = true}).prefixed("glb: "));
  if (!extent_fits_float(m.positions))
    return Status::invalid_argument("glb: the positions span more than half of float's range");
  if (2 * m.quad_count() + m.triangle_count() > kMaxIndex)
    return Status::invalid_argument("glb: more than 2^31 - 1 triangles");
  return Status::ok();
}

// glTF has no quads (primitive modes are points, lines and triangles): quads are split by
// append_quad_triangles, the rule mesh_ldis uses for FaceType::triangles, so the GLB of a quad
// mesh holds the same triangles as that of the triangle mesh.
void triangulate(const Mesh& m, std::vector<std::uint32_t>& tris, std::vector<std::uint8_t>& view) {
  tris.clear();
  view.clear();
  tris.reserve(6 * m.quad_count() + m.triangles.size());
  view.reserve(2 * m.quad_count() + m.triangle_count());
  for (std::size_t q = 0; q < m.quad_count(); ++q) {
    append_quad_triangles(m.positions, &m.quads[4 * q], tris);
    view.insert(view.end(), {m.quad_view[q], m.quad_view[q]});
  }
  tris.insert(tris.end(), m.triangles.begin(), m.triangles.end());
  view.insert(view.end(), m.triangle_view.begin(), m.triangle_view.end());
}

glm::dvec3 view_dir(const Mesh& m, std::size_t k) {
  return k < m.view_dirs.size() ? m.view_dirs[k] : glm::dvec3(0.0);
}

// The minimal valid glTF for a mesh without faces: an asset and an empty scene (a scene's
// "nodes", when present, must have at least one entry, so it is left out).
std::vector<std::uint8_t> empty_glb() {
  return assemble_glb(
      R"({"asset":{"generator":"ldimesh","version":"2.0"},"scene":0,"scenes":[{}]})", {});
}

// Builds the Draco mesh GltfEncoder writes: one point per vertex, identity-mapped attributes.
Status build_draco_mesh(const Mesh& m, const std::vector<std::uint32_t>& tris,
                        const std::vector<std::uint8_t>& tri_view, const GlbOptions& options,
                        int position_bits, float scalar_lo, float scalar_hi, draco::Mesh& dm) {
  const std::size_t n = m.vertex_count();
  dm.set_num_points(std::uint32_t(n));
  const auto add = [&](draco::GeometryAttribute::Type type, int components, draco::DataType dt,
                       bool normalized) -> draco::PointAttribute* {
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, std::uint8_t(components), dt, normalized,
            std::int64_t(draco::DataTypeLength(dt)) * components, 0);
    const int id = dm.AddAttribute(ga, /*identity_mapping=*/true, std::uint32_t(n));
    return id >= 0 ? dm.attribute(id) : nullptr;
  };
  draco::PointAttribute* pos = add(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false);
  draco::PointAttribute* nrm = add(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false);
  draco::PointAttribute* col = add(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true);
  if (!pos || !nrm || !col) return Status::internal("glb: Draco could not add an attribute");
  static_assert(sizeof(glm::vec3) == 3 * sizeof(float));
  pos->buffer()->Write(0, m.positions.data(), n * sizeof(glm::vec3));
  nrm->buffer()->Write(0, m.normals.data(), n * sizeof(glm::vec3));

  // A vertex takes the colour of the first face that uses it; unused vertices (which Draco's
  // Edgebreaker drops) white.
  std::vector<std::array<std::uint8_t, 3>> colour(n, {255, 255, 255});
  std::vector<bool> coloured(n, false);
  std::array<std::array<std::uint8_t, 3>, 256> view_colours;
  for (std::size_t k = 0; k < view_colours.size(); ++k)
    view_colours[k] = view_colour(k, view_dir(m, k));
  for (std::size_t f = 0; f < tri_view.size(); ++f)
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t v = tris[3 * f + c];
      if (!coloured[v]) {
        coloured[v] = true;
        colour[v] = view_colours[tri_view[f]];
      }
    }
  col->buffer()->Write(0, colour.data(), n * 3);

  if (!m.scalars.empty()) {
    // The scalar as the custom attribute _SCALAR, one float per vertex (GltfEncoder writes a
    // GENERIC attribute under the name its metadata gives). Draco predicts a GENERIC attribute
    // from its neighbours (parallelogram): as TEXCOORD_0 it took the texture-coordinate
    // predictor, made for 2-D maps, and cost more bytes (docs/history/benchmarks-log.md, "The
    // colour field as a generic attribute").
    draco::PointAttribute* scalar =
        add(draco::GeometryAttribute::GENERIC, 1, draco::DT_FLOAT32, false);
    if (!scalar) return Status::internal("glb: Draco could not add an attribute");
    auto metadata = std::make_unique<draco::AttributeMetadata>();
    metadata->AddEntryString(draco::GltfEncoder::kDracoMetadataGltfAttributeName, kScalarAttribute);
    dm.AddAttributeMetadata(dm.num_attributes() - 1, std::move(metadata));  // the one just added
    std::vector<float> u(n);
    const double scale = scalar_hi > scalar_lo ? 1.0 / (double(scalar_hi) - scalar_lo) : 0.0;
    for (std::size_t i = 0; i < n; ++i)
      u[i] = float(std::clamp((double(m.scalars[i]) - scalar_lo) * scale, 0.0, 1.0));
    scalar->buffer()->Write(0, u.data(), n * sizeof(float));
  }

  const std::size_t t = tri_view.size();
  dm.SetNumFaces(t);
  for (std::size_t f = 0; f < t; ++f)
    dm.SetFace(draco::FaceIndex(std::uint32_t(f)),
               {draco::PointIndex(tris[3 * f]), draco::PointIndex(tris[3 * f + 1]),
                draco::PointIndex(tris[3 * f + 2])});

  draco::DracoCompressionOptions compression;
  compression.compression_level = options.compression_level;
  compression.quantization_position.SetQuantizationBits(position_bits);
  compression.quantization_bits_normal = options.normal_bits;
  compression.quantization_bits_generic = options.scalar_bits;
  // COLOR needs no setting: GltfEncoder does not quantize colours (no COLOR case in
  // GltfAsset::CompressMeshWithDraco), so 8-bit colours travel exactly.
  dm.SetCompressionEnabled(true);
  dm.SetCompressionOptions(compression);
  return Status::ok();
}

// Counts (vertices, triangles) of the primitives encode_glb wrote, from their accessors.
void primitive_counts(const Json& json, GlbInfo& info) {
  const Json& accessors = json.at("accessors");
  info.vertices = info.triangles = 0;
  for (const Json& mesh : json.at("meshes"))
    for (const Json& primitive : mesh.at("primitives")) {
      info.vertices += accessors.at(primitive.at("attributes").at("POSITION").get<std::size_t>())
                           .at("count")
                           .get<std::size_t>();
      info.triangles +=
          accessors.at(primitive.at("indices").get<std::size_t>()).at("count").get<std::size_t>() /
          3;
    }
}

// Triangles per part above which a mesh is encoded in parts, concurrently (a part per spatial
// slab): Draco's encoder runs on one thread, and a root that encodes a million triangles on one
// core falls behind its job. The count depends on the mesh only, never on the threads, so the
// GLB is the same on any machine.
constexpr std::size_t kPartTriangles = 200000;
constexpr std::size_t kMaxParts = 8;

// The cores this process may run on (its affinity mask, which a job's launcher sets), at least 1.
int usable_cores() {
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof set, &set) == 0) return std::max(1, CPU_COUNT(&set));
  return int(std::max(1u, std::thread::hardware_concurrency()));
}

// Each triangle's part: slabs along the longest axis of the box, about equal in triangles (by
// the triangles' centroids, in 4096 bins).
std::vector<std::uint8_t> split_into_parts(const Mesh& m, const std::vector<std::uint32_t>& tris,
                                           std::size_t parts) {
  const std::size_t t = tris.size() / 3;
  const BoundingBox box = bounding_box(m.positions);
  const glm::dvec3 extent = box.hi - box.lo;
  const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : extent.y >= extent.z ? 1 : 2;
  constexpr std::size_t kBins = 4096;
  const double scale = extent[axis] > 0.0 ? double(kBins) / extent[axis] : 0.0;
  std::vector<std::uint16_t> bin(t);
  std::vector<std::size_t> count(kBins, 0);
  for (std::size_t f = 0; f < t; ++f) {
    const double c = (double(m.positions[tris[3 * f]][axis]) + m.positions[tris[3 * f + 1]][axis] +
                      m.positions[tris[3 * f + 2]][axis]) /
                     3.0;
    bin[f] = std::uint16_t(std::clamp((c - box.lo[axis]) * scale, 0.0, double(kBins - 1)));
    ++count[bin[f]];
  }
  // Bin b goes to the part its first triangle's rank falls in.
  std::vector<std::uint8_t> part_of_bin(kBins);
  std::size_t before = 0;
  for (std::size_t b = 0; b < kBins; ++b) {
    part_of_bin[b] = std::uint8_t(std::min(parts - 1, before * parts / t));
    before += count[b];
  }
  std::vector<std::uint8_t> part(t);
  for (std::size_t f = 0; f < t; ++f)
    part[f] = part_of_bin[bin[f]];
  return part;
}

// The triangles of part `k` as a mesh of their own (the vertices they use, renumbered in order
// of first use), with their views.
void extract_part(const Mesh& m, const std::vector<std::uint32_t>& tris,
                  const std::vector<std::uint8_t>& tri_view, const std::vector<std::uint8_t>& part,
                  std::uint8_t k, Mesh& sub, std::vector<std::uint32_t>& sub_tris,
                  std::vector<std::uint8_t>& sub_view) {
  constexpr std::uint32_t kUnused = ~std::uint32_t(0);
  std::vector<std::uint32_t> index(m.vertex_count(), kUnused);
  sub.view_dirs = m.view_dirs;
  for (std::size_t f = 0; f < part.size(); ++f) {
    if (part[f] != k) continue;
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t v = tris[3 * f + c];
      if (index[v] == kUnused) {
        index[v] = std::uint32_t(sub.positions.size());
        sub.positions.push_back(m.positions[v]);
        sub.normals.push_back(m.normals[v]);
        if (!m.scalars.empty()) sub.scalars.push_back(m.scalars[v]);
      }
      sub_tris.push_back(index[v]);
    }
    sub_view.push_back(tri_view[f]);
  }
}

// Moves the accessors and bufferViews of GLB `part` (as GltfEncoder writes one: one mesh) into
// `base`'s JSON, its BIN into `bin` (4-byte aligned), and returns its mesh's primitives with
// their accessor and bufferView indices renumbered.
Json take_primitives(Json& base, std::vector<std::uint8_t>& bin, const Json& part,
                     std::span<const std::uint8_t> part_bin) {
  const std::size_t accessors = base["accessors"].size(), views = base["bufferViews"].size();
  bin.resize((bin.size() + 3) & ~std::size_t(3), 0);
  const std::size_t offset = bin.size();
  bin.insert(bin.end(), part_bin.begin(), part_bin.end());
  for (const Json& a : part.at("accessors"))
    base["accessors"].push_back(a);
  for (Json v : part.at("bufferViews")) {
    v["byteOffset"] = v.value("byteOffset", std::size_t(0)) + offset;
    base["bufferViews"].push_back(std::move(v));
  }
  Json primitives = Json::array();
  for (Json p : part.at("meshes").at(0).at("primitives")) {
    for (auto& [name, id] : p["attributes"].items())
      id = id.get<std::size_t>() + accessors;
    p["indices"] = p["indices"].get<std::size_t>() + accessors;
    Json& draco = p["extensions"][kDraco];
    draco["bufferView"] = draco["bufferView"].get<std::size_t>() + views;
    primitives.push_back(std::move(p));
  }
  base["buffers"][0]["byteLength"] = bin.size();
  return primitives;
}

// Appends GLB `part` to `base` as further primitives of its first mesh.
void append_part(Json& base, std::vector<std::uint8_t>& bin, const Json& part,
                 std::span<const std::uint8_t> part_bin) {
  for (Json& p : take_primitives(base, bin, part, part_bin))
    base["meshes"][0]["primitives"].push_back(std::move(p));
}

// The extras that name a node's surface (GlbOptions::surfaces). A key of its own, not inside
// "ldimesh": three.js gives a node of a one-primitive mesh and that mesh one object, and the
// node's extras would replace the mesh's extras.ldimesh (the view directions, the range).
Json surface_extras(std::size_t surface) {
  Json extras;
  extras["ldimesh_surface"] = surface;
  return extras;
}

// Appends GLB `part` to `base` as a mesh of its own, on a node of the scene whose extras name
// surface `surface`.
void append_surface(Json& base, std::vector<std::uint8_t>& bin, const Json& part,
                    std::span<const std::uint8_t> part_bin, std::size_t surface) {
  Json mesh = part.at("meshes").at(0);
  mesh["primitives"] = take_primitives(base, bin, part, part_bin);
  const std::size_t mesh_index = base["meshes"].size(), node_index = base["nodes"].size();
  base["meshes"].push_back(std::move(mesh));
  Json node;
  node["mesh"] = mesh_index;
  node["extras"] = surface_extras(surface);
  base["nodes"].push_back(std::move(node));
  base["scenes"][base.value("scene", std::size_t(0))]["nodes"].push_back(node_index);
}

// One Draco primitive's GLB from GltfEncoder, parsed into `json` and `bin` (copied).
Status encode_primitive(draco::Mesh& dm, Json& json, std::vector<std::uint8_t>& bin) {
  draco::GltfEncoder encoder;
  draco::EncoderBuffer buffer;
  if (const draco::Status s = encoder.EncodeToBuffer(dm, &buffer); !s.ok())
    return Status::internal("glb: Draco's glTF encoder failed: " + s.error_msg_string());
  GlbChunks chunks;
  const std::span<const std::uint8_t> encoded(reinterpret_cast<const std::uint8_t*>(buffer.data()),
                                              buffer.size());
  if (Status s = parse_glb(encoded, chunks); !s)
    return Status::internal("glb: Draco's glTF encoder wrote an unreadable GLB: " + s.message());
  json = std::move(chunks.json);
  bin.assign(chunks.bin.begin(), chunks.bin.end());
  return Status::ok();
}

// One surface of a GLB (the whole mesh, or GlbOptions::surfaces' part of it): its faces, and
// the slabs they are encoded in when there are more than kPartTriangles (each slab a primitive
// of the surface's glTF mesh). Each part takes the whole mesh's position bits over its own
// (smaller) box: its step is at most the whole mesh's, so every vertex keeps the stated bound (a
// vertex two parts share is written by both, each copy within the bound).
struct Surface {
  std::size_t index = 0;  // in GlbOptions::surfaces
  // Its scalars as _SCALAR over [scalar_lo, scalar_hi], where its mesh has scalars (the mesh's
  // own, or `owned`'s, which holds none where the surface has no colour field).
  float scalar_lo = 0.0f, scalar_hi = 0.0f;
  // Its faces: the mesh's own, or `owned`'s (a surface extracted from the mesh).
  const Mesh* mesh = nullptr;
  const std::vector<std::uint32_t>* tris = nullptr;
  const std::vector<std::uint8_t>* tri_view = nullptr;
  Mesh owned;
  std::vector<std::uint32_t> owned_tris;
  std::vector<std::uint8_t> owned_view;
  std::size_t parts = 1;
  std::vector<std::uint8_t> part;  // each face's slab, where parts > 1
  BoundingBox box;                 // where parts > 1
  // Per part: its GLB (GltfEncoder's JSON and BIN; null JSON for an empty slab) or its error.
  std::vector<Json> jsons;
  std::vector<std::vector<std::uint8_t>> bins;
  std::vector<Status> status;
};

// Part `k` of `s` as a GLB of one Draco primitive (in s.jsons[k], s.bins[k]).
Status encode_part(Surface& s, std::size_t k, const GlbOptions& options, int position_bits) {
  const float scalar_lo = s.scalar_lo, scalar_hi = s.scalar_hi;
  draco::Mesh dm;
  if (s.parts == 1) {
    LDIMESH_RETURN_IF_ERROR(build_draco_mesh(*s.mesh, *s.tris, *s.tri_view, options, position_bits,
                                             scalar_lo, scalar_hi, dm));
    return encode_primitive(dm, s.jsons[k], s.bins[k]);
  }
  Mesh sub;
  std::vector<std::uint32_t> sub_tris;
  std::vector<std::uint8_t> sub_view;
  extract_part(*s.mesh, *s.tris, *s.tri_view, s.part, std::uint8_t(k), sub, sub_tris, sub_view);
  if (sub_view.empty()) return Status::ok();  // an empty slab (all in one bin elsewhere)
  // Two points no face uses, at the surface's box corners and the scalar range: every part
  // quantizes the same box (and range) on the same grid, so a vertex two parts share decodes to
  // the same point in both (Draco's Edgebreaker keeps no unused point in its output).
  sub.positions.insert(sub.positions.end(), {glm::vec3(s.box.lo), glm::vec3(s.box.hi)});
  sub.normals.insert(sub.normals.end(), 2, glm::vec3(0.0f, 0.0f, 1.0f));
  if (!sub.scalars.empty()) sub.scalars.insert(sub.scalars.end(), {scalar_lo, scalar_hi});
  LDIMESH_RETURN_IF_ERROR(
      build_draco_mesh(sub, sub_tris, sub_view, options, position_bits, scalar_lo, scalar_hi, dm));
  return encode_primitive(dm, s.jsons[k], s.bins[k]);
}

// Encodes every part of every surface, concurrently: Draco's encoder runs on one thread, and a
// root that encodes a million triangles on one core falls behind its job. Threads of its own
// (this library needs no TBB), each taking the next part; the result does not depend on them.
Status encode_parts(std::deque<Surface>& surfaces, const GlbOptions& options, int position_bits) {
  std::vector<std::pair<Surface*, std::size_t>> jobs;
  for (Surface& s : surfaces) {
    s.jsons.resize(s.parts);
    s.bins.resize(s.parts);
    s.status.assign(s.parts, Status::ok());
    for (std::size_t k = 0; k < s.parts; ++k)
      jobs.emplace_back(&s, k);
  }
  std::atomic<std::size_t> next{0};
  const auto work = [&] {
    for (std::size_t j = next++; j < jobs.size(); j = next++) {
      Surface* s = jobs[j].first;
      const std::size_t k = jobs[j].second;
      s->status[k] = guard("glb: part " + std::to_string(k) + ": ",
                           [&] { return encode_part(*s, k, options, position_bits); });
    }
  };
  const std::size_t threads =
      std::min(jobs.size(), std::size_t(options.threads > 0 ? options.threads : usable_cores()));
  {
    // Joined however this block is left; a thread that cannot be started (no memory, no
    // thread) leaves its parts to the others.
    std::vector<std::jthread> pool;
    pool.reserve(threads);
    try {
      for (std::size_t t = 1; t < threads; ++t)
        pool.emplace_back(work);
    } catch (...) {
    }
    work();
  }
  for (const Surface& s : surfaces)
    for (const Status& st : s.status)
      LDIMESH_RETURN_IF_ERROR(st);
  return Status::ok();
}

// The faces of the surface whose vertices are [first, last) as a mesh of its own: those
// vertices in their order, the faces renumbered, their views. A face whose first vertex lies
// in the range and another outside it is an error.
Status extract_surface(const Mesh& m, const std::vector<std::uint32_t>& tris,
                       const std::vector<std::uint8_t>& tri_view, std::uint32_t first,
                       std::uint32_t last, Mesh& sub, std::vector<std::uint32_t>& sub_tris,
                       std::vector<std::uint8_t>& sub_view) {
  sub.view_dirs = m.view_dirs;
  sub.positions.assign(m.positions.begin() + first, m.positions.begin() + last);
  sub.normals.assign(m.normals.begin() + first, m.normals.begin() + last);
  if (!m.scalars.empty()) sub.scalars.assign(m.scalars.begin() + first, m.scalars.begin() + last);
  for (std::size_t f = 0; f < tri_view.size(); ++f) {
    const std::uint32_t* t = &tris[3 * f];
    if (t[0] < first || t[0] >= last) continue;
    for (int c = 0; c < 3; ++c) {
      if (t[c] < first || t[c] >= last)
        return Status::invalid_argument("glb: a face uses vertices of two surfaces");
      sub_tris.push_back(t[c] - first);
    }
    sub_view.push_back(tri_view[f]);
  }
  return Status::ok();
}

// GlbOptions::surfaces and scalar_groups against the mesh.
Status check_surfaces(const Mesh& mesh, const GlbOptions& options) {
  for (std::size_t k = 0; k < options.surfaces.size(); ++k)
    if ((k == 0 && options.surfaces[0] != 0) ||
        (k > 0 && options.surfaces[k] < options.surfaces[k - 1]) ||
        options.surfaces[k] > mesh.vertex_count())
      return Status::invalid_argument(
          "glb: surfaces must start at vertex 0 and increase within the vertices");
  const std::size_t surface_count = std::max<std::size_t>(1, options.surfaces.size());
  if (!options.scalar_groups.empty() && options.scalar_groups.size() != surface_count)
    return Status::invalid_argument("glb: scalar_groups must have one entry per surface (" +
                                    std::to_string(surface_count) + ")");
  for (int g : options.scalar_groups)
    if (g < -1 || g >= int(surface_count) || (g >= 0 && mesh.scalars.empty()))
      return Status::invalid_argument(
          "glb: a scalar group must be −1 or below the number of surfaces, and the mesh must "
          "have scalars where one is not −1");
  return Status::ok();
}

// The encoded surfaces joined into `json` and `bin`: each surface's parts as primitives of its
// mesh, the surfaces as meshes and nodes.
void join_surfaces(std::deque<Surface>& surfaces, const GlbOptions& options, Json& json,
                   std::vector<std::uint8_t>& bin) {
  for (Surface& s : surfaces) {
    Json surface;
    std::vector<std::uint8_t> surface_bin;
    for (std::size_t k = 0; k < s.parts; ++k) {
      if (s.jsons[k].is_null()) continue;
      if (surface.is_null()) {
        surface = std::move(s.jsons[k]);
        surface_bin = std::move(s.bins[k]);
      } else {
        append_part(surface, surface_bin, s.jsons[k], s.bins[k]);
      }
    }
    if (json.is_null()) {
      json = std::move(surface);
      bin = std::move(surface_bin);
      if (options.surfaces.size() > 1) json["nodes"][0]["extras"] = surface_extras(s.index);
    } else {
      append_surface(json, bin, surface, surface_bin, s.index);
    }
  }
}

Status encode_glb_unguarded(const Mesh& mesh, const GlbOptions& options,
                            std::vector<std::uint8_t>& out, GlbInfo* info) {
  if (Status s = check_options(options); !s) return s;
  if (Status s = check_encodable(mesh); !s) return s;
  LDIMESH_RETURN_IF_ERROR(check_surfaces(mesh, options));
  GlbInfo result;
  result.position_bits = glb_position_bits(mesh, options);
  result.position_error_bound = glb_position_error_bound(mesh, options);

  std::vector<std::uint32_t> tris;
  std::vector<std::uint8_t> tri_view;
  triangulate(mesh, tris, tri_view);
  if (tri_view.empty()) {
    out = empty_glb();
    if (info) *info = result;
    return Status::ok();
  }

  // Each surface's vertices [starts[s], starts[s + 1]) and scalar group (−1: no _SCALAR), and
  // each group's range: fixed, or its surfaces' min and max (none where they have no vertex).
  std::vector<std::uint32_t> starts(options.surfaces.begin(), options.surfaces.end());
  if (starts.empty()) starts.push_back(0);
  starts.push_back(std::uint32_t(mesh.vertex_count()));
  std::vector<int> groups = options.scalar_groups;
  if (groups.empty()) groups.assign(starts.size() - 1, mesh.scalars.empty() ? -1 : 0);
  std::vector<std::optional<std::array<float, 2>>> group_range(
      std::size_t(std::max(0, *std::max_element(groups.begin(), groups.end()) + 1)));
  for (std::size_t s = 0; s < groups.size(); ++s) {
    if (groups[s] < 0 || starts[s] == starts[s + 1]) continue;
    const auto [lo, hi] =
        std::minmax_element(mesh.scalars.begin() + starts[s], mesh.scalars.begin() + starts[s + 1]);
    auto& range = group_range[std::size_t(groups[s])];
    // The first least and the last greatest, as std::minmax_element over all of them.
    range = range ? std::array<float, 2>{*lo < (*range)[0] ? *lo : (*range)[0],
                                         (*range)[1] <= *hi ? *hi : (*range)[1]}
                  : std::array<float, 2>{*lo, *hi};
  }
  std::size_t ranged = 0;
  for (auto& range : group_range) {
    if (!range) continue;
    if (options.scalar_range) range = *options.scalar_range;
    result.has_scalar = true;
    result.scalar_min = ++ranged == 1 ? (*range)[0] : 0.0f;
    result.scalar_max = ranged == 1 ? (*range)[1] : 0.0f;
  }
  if (!options.scalar_groups.empty())
    for (int g : groups)
      result.surface_scalar_ranges.push_back(g >= 0 ? group_range[std::size_t(g)] : std::nullopt);
  const auto set_scalars = [&](Surface& s) {
    const int g = groups[s.index];
    if (g >= 0 && group_range[std::size_t(g)]) {
      s.scalar_lo = (*group_range[std::size_t(g)])[0];
      s.scalar_hi = (*group_range[std::size_t(g)])[1];
    }
    if (g < 0 && !s.mesh->scalars.empty()) {  // a copy without them
      if (s.mesh != &s.owned) s.owned = *s.mesh;
      s.owned.scalars.clear();
      s.mesh = &s.owned;
    }
  };

  // The surfaces: the whole mesh, or each of GlbOptions::surfaces (its vertices as they are, in
  // their order) as a mesh on a node of its own; large ones in slabs.
  std::deque<Surface> surfaces;
  if (options.surfaces.size() <= 1) {
    Surface& s = surfaces.emplace_back();
    s.mesh = &mesh;
    s.tris = &tris;
    s.tri_view = &tri_view;
    set_scalars(s);
  } else {
    for (std::size_t k = 0; k + 1 < starts.size(); ++k) {
      Surface& s = surfaces.emplace_back();
      s.index = k;
      LDIMESH_RETURN_IF_ERROR(extract_surface(mesh, tris, tri_view, starts[k], starts[k + 1],
                                              s.owned, s.owned_tris, s.owned_view));
      if (s.owned_view.empty()) {  // no faces: no node
        surfaces.pop_back();
        continue;
      }
      s.mesh = &s.owned;
      s.tris = &s.owned_tris;
      s.tri_view = &s.owned_view;
      set_scalars(s);
    }
  }
  for (Surface& s : surfaces) {
    s.parts = std::min(kMaxParts, (s.tri_view->size() + kPartTriangles - 1) / kPartTriangles);
    if (s.parts > 1) {
      s.part = split_into_parts(*s.mesh, *s.tris, s.parts);
      s.box = bounding_box(s.mesh->positions);
    }
  }
  LDIMESH_RETURN_IF_ERROR(encode_parts(surfaces, options, result.position_bits));

  Json json;
  std::vector<std::uint8_t> bin;
  join_surfaces(surfaces, options, json, bin);

  // Add what a client needs beyond glTF's attributes, in the place glTF reserves for
  // application data ("extras"), and name the writer (Draco writes "draco_decoder").
  json["asset"]["generator"] = "ldimesh (Draco glTF encoder)";
  Json extras;
  extras["view_dirs"] = Json::array();
  for (const glm::dvec3& d : mesh.view_dirs)
    extras["view_dirs"].push_back({d.x, d.y, d.z});
  if (result.has_scalar && ranged == 1)
    extras["scalar_range"] = {result.scalar_min, result.scalar_max};
  if (!options.scalar_groups.empty()) {
    extras["surface_scalar_ranges"] = Json::array();
    for (const auto& range : result.surface_scalar_ranges)
      extras["surface_scalar_ranges"].push_back(range ? Json{(*range)[0], (*range)[1]} : Json());
  }
  json["meshes"][0]["extras"]["ldimesh"] = std::move(extras);
  primitive_counts(json, result);
  const std::string text = json.dump();
  if (text.size() + bin.size() > std::numeric_limits<std::uint32_t>::max() - 64)
    return Status::invalid_argument("glb: the GLB would exceed 4 GiB (glTF's 32-bit length)");
  out = assemble_glb(text, bin);
  if (info) *info = result;
  return Status::ok();
}

}  // namespace

int glb_position_bits(const Mesh& mesh, const GlbOptions& options) {
  if (options.position_bits > 0) return options.position_bits;
  const BoundingBox box = bounding_box(mesh.positions);
  if (box.empty) return kMaxAutoPositionBits;
  const double diagonal = glm::length(box.hi - box.lo);
  const double step = options.pixel_size > 0.0 ? 0.1 * options.pixel_size : 1e-4 * diagonal;
  if (!(step > 0.0)) return 1;  // a single point: any step holds it exactly
  // Draco's step is r / (2^b − 1) (attribute_quantization_transform.cc).
  const double r = quantization_range(box);
  for (int b = 1; b < kMaxAutoPositionBits; ++b)
    if (r / double((std::uint64_t(1) << b) - 1) <= step) return b;
  return kMaxAutoPositionBits;
}

double glb_position_error_bound(const Mesh& mesh, const GlbOptions& options) {
  const BoundingBox box = bounding_box(mesh.positions);
  if (box.empty) return 0.0;
  const int b = glb_position_bits(mesh, options);
  const double r = quantization_range(box);
  const double magnitude = std::max({r, glm::length(glm::max(glm::abs(box.lo), glm::abs(box.hi)))});
  const double per_coordinate =
      r / (2.0 * double((std::uint64_t(1) << b) - 1)) + 8.0 * std::ldexp(magnitude, -23);
  return std::sqrt(3.0) * per_coordinate;
}

double glb_normal_error_bound(const GlbOptions& options) {
  // Draco rounds the two free coordinates of the L1-normalized normal to steps of
  // 2/(2^n − 2) (OctahedronToolBox::FloatVectorToQuantizedOctahedralCoords); the third takes
  // the remainder, so the octahedron point moves by at most √6/(2^n − 2) and, lying at least
  // 1/√3 from the origin, turns by at most 3√2/(2^n − 2). 2⁻²⁰ covers float arithmetic.
  return 3.0 * std::sqrt(2.0) / double((std::uint64_t(1) << options.normal_bits) - 2) +
         std::ldexp(1.0, -20);
}

double glb_scalar_error_bound(const GlbOptions& options) {
  return 1.0 / (2.0 * double((std::uint64_t(1) << options.scalar_bits) - 1)) + std::ldexp(1.0, -20);
}

std::array<std::uint8_t, 3> view_colour(std::size_t k, const glm::dvec3& dir) {
  static constexpr std::array<std::array<std::uint8_t, 3>, 3> kAxis = {
      {{255, 0, 0}, {255, 215, 0}, {0, 170, 0}}};
  static constexpr std::array<std::array<std::uint8_t, 3>, 8> kPalette = {{{40, 100, 255},
                                                                           {220, 0, 220},
                                                                           {0, 200, 220},
                                                                           {255, 130, 0},
                                                                           {130, 60, 200},
                                                                           {0, 128, 128},
                                                                           {255, 120, 170},
                                                                           {128, 128, 128}}};
  const double len2 = glm::dot(dir, dir);
  for (int a = 0; a < 3; ++a)
    if (len2 > 0.0 && dir[a] * dir[a] >= (1.0 - 1e-12) * len2) return kAxis[a];
  return kPalette[k % kPalette.size()];
}

Status encode_glb(const Mesh& mesh, const GlbOptions& options, std::vector<std::uint8_t>& out,
                  GlbInfo* info) {
  try {
    return encode_glb_unguarded(mesh, options, out, info);
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory("glb: out of memory while encoding");
  } catch (const std::exception& e) {
    return Status::internal(std::string("glb: encoding failed: ") + e.what());
  }
}

}  // namespace ldimesh
