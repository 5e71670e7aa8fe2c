// glTF 2.0 binary with KHR_draco_mesh_compression → Mesh: every count, index and length checked
// before it is used (docs/method.md, "Mesh encoding"; the references in glb.cpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <unordered_map>
#include <vector>

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/mesh/mesh.h>

#include "glb_format.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh {
namespace {

using namespace glb_format;

// The bytes of the Draco mesh that the primitive's extension `draco_ext` names: its
// bufferView's stretch of the BIN chunk, every index and length checked.
StatusOr<std::span<const std::uint8_t>> draco_bytes(const Json& json, const Json& draco_ext,
                                                    std::span<const std::uint8_t> bin) {
  const Json* views = array_member(json, "bufferViews");
  if (!views) return Status::corrupt_input("glb: no bufferViews");
  std::size_t view_index = 0, buffer_index = 0, length = 0, offset = 0;
  if (Status s = get_index(draco_ext, "bufferView", views->size(), view_index, kDraco); !s)
    return s;
  const Json& view = (*views)[view_index];
  if (!view.is_object()) return Status::corrupt_input("glb: a bufferView is not an object");
  if (Status s = get_index(view, "buffer", 1, buffer_index, "bufferView"); !s)
    return Status::corrupt_input(
        "glb: the Draco bufferView is not in the GLB's BIN chunk (buffer 0)");
  if (Status s = get_index(view, "byteLength", bin.size() + 1, length, "bufferView"); !s) return s;
  if (view.contains("byteOffset")) {
    if (Status s = get_index(view, "byteOffset", bin.size() + 1, offset, "bufferView"); !s)
      return s;
  }
  if (length > bin.size() - offset)
    return Status::corrupt_input("glb: the Draco bufferView runs past the BIN chunk");
  return bin.subspan(offset, length);
}

// The glTF accessors of the primitive's attributes and indices agree with the Draco mesh of `n`
// points and `t` triangles (KHR_draco_mesh_compression).
Status check_accessors(const Json& json, const Json& primitive, const Json& gltf_attributes,
                       std::size_t n, std::size_t t) {
  const Json* accessors = array_member(json, "accessors");
  if (!accessors) return Status::corrupt_input("glb: no accessors");
  const auto accessor_count = [&](const Json& index, std::size_t& count) {
    if (!index.is_number_integer() || index.get<std::int64_t>() < 0 ||
        std::uint64_t(index.get<std::int64_t>()) >= accessors->size())
      return false;
    const Json& a = (*accessors)[std::size_t(index.get<std::int64_t>())];
    const auto c = a.is_object() ? a.find("count") : a.end();
    if (!a.is_object() || c == a.end() || !c->is_number_unsigned()) return false;
    count = c->get<std::size_t>();
    return true;
  };
  for (const auto& [name, index] : gltf_attributes.items()) {
    std::size_t count = 0;
    if (!accessor_count(index, count) || count != n)
      return Status::corrupt_input("glb: accessor of " + name + " disagrees with the Draco data");
  }
  if (const auto indices = primitive.find("indices"); indices != primitive.end()) {
    std::size_t count = 0;
    if (!accessor_count(*indices, count) || count != 3 * t)
      return Status::corrupt_input("glb: the index accessor disagrees with the Draco data");
  }
  return Status::ok();
}

// Appends the Draco primitive `primitive` (already checked to be a JSON object) to `out`.
Status decode_primitive(const Json& json, const Json& primitive, std::span<const std::uint8_t> bin,
                        Mesh& out, GlbInfo& info,
                        const std::vector<std::array<std::uint8_t, 3>>& view_colours) {
  if (const auto mode = primitive.find("mode");
      mode != primitive.end() && !(mode->is_number_integer() && mode->get<std::int64_t>() == 4))
    return Status::corrupt_input("glb: a primitive is not made of triangles");
  const auto extensions = primitive.find("extensions");
  if (extensions == primitive.end() || !extensions->is_object() || !extensions->contains(kDraco) ||
      !(*extensions)[kDraco].is_object())
    return Status::corrupt_input("glb: a primitive is not Draco-compressed (unsupported)");
  const Json& draco_ext = (*extensions)[kDraco];
  LDIMESH_ASSIGN_OR_RETURN(const std::span<const std::uint8_t> bytes,
                           draco_bytes(json, draco_ext, bin));
  const auto attributes = draco_ext.find("attributes");
  const auto gltf_attributes = primitive.find("attributes");
  if (attributes == draco_ext.end() || !attributes->is_object() ||
      gltf_attributes == primitive.end() || !gltf_attributes->is_object())
    return Status::corrupt_input("glb: a Draco primitive has no attribute map");

  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok())
    return Status::corrupt_input("glb: Draco could not decode the mesh: " +
                                 decoded.status().error_msg_string());
  const std::unique_ptr<draco::Mesh> dm = std::move(decoded).value();
  if (!dm) return Status::corrupt_input("glb: Draco returned no mesh");
  const std::size_t n = dm->num_points(), t = dm->num_faces();

  LDIMESH_RETURN_IF_ERROR(check_accessors(json, primitive, *gltf_attributes, n, t));

  const auto attribute = [&](const char* name, int min_components) -> const draco::PointAttribute* {
    const auto it = attributes->find(name);
    if (it == attributes->end() || !it->is_number_unsigned() ||
        it->get<std::uint64_t>() > std::numeric_limits<std::uint32_t>::max())
      return nullptr;
    const draco::PointAttribute* a = dm->GetAttributeByUniqueId(it->get<std::uint32_t>());
    return a && a->num_components() >= min_components && a->size() > 0 ? a : nullptr;
  };
  const draco::PointAttribute* pos = attribute("POSITION", 3);
  const draco::PointAttribute* nrm = attribute("NORMAL", 3);
  const draco::PointAttribute* col = attribute("COLOR_0", 3);
  const draco::PointAttribute* tex = attributes->contains(kScalarAttribute)
                                         ? attribute(kScalarAttribute, 1)
                                         : attribute("TEXCOORD_0", 2);
  if (!pos || !nrm) return Status::corrupt_input("glb: a Draco primitive lacks POSITION or NORMAL");
  const std::size_t base = out.positions.size();
  if (base + n > kMaxIndex || out.triangle_count() + t > kMaxIndex)
    return Status::corrupt_input("glb: more than 2^31 - 1 vertices or triangles");
  // Primitives with and without a scalar (surfaces of which some are not coloured): NaN at the
  // vertices of those without.
  if (tex || !out.scalars.empty()) out.scalars.resize(base, NAN);

  // Values of point i; a point mapped outside its attribute, or a value Draco cannot convert,
  // is an error rather than a read out of bounds.
  const auto value = [&](const draco::PointAttribute* a, std::size_t i, auto* v) {
    const draco::AttributeValueIndex avi = a->mapped_index(draco::PointIndex(std::uint32_t(i)));
    return avi.value() < a->size() && a->ConvertValue(avi, std::int8_t(3), v);
  };
  std::unordered_map<std::uint32_t, std::uint8_t> view_of_colour;
  for (std::size_t k = view_colours.size(); k-- > 0;) {
    const auto& c = view_colours[k];
    view_of_colour[std::uint32_t(c[0]) << 16 | std::uint32_t(c[1]) << 8 | c[2]] = std::uint8_t(k);
  }
  std::vector<std::uint8_t> vertex_view(n, 0);
  out.positions.resize(base + n);
  out.normals.resize(base + n);
  if (tex || !out.scalars.empty()) out.scalars.resize(base + n, NAN);
  for (std::size_t i = 0; i < n; ++i) {
    float p[3], q[3];
    if (!value(pos, i, p) || !value(nrm, i, q))
      return Status::corrupt_input("glb: Draco point " + std::to_string(i) + " has no value");
    const glm::vec3 position(p[0], p[1], p[2]), normal(q[0], q[1], q[2]);
    const float len = glm::length(normal);
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) ||
        !std::isfinite(len) || len <= 0.0f)
      return Status::corrupt_input("glb: a decoded position or normal is not finite or zero");
    out.positions[base + i] = position;
    out.normals[base + i] = normal / len;
    if (tex) {
      float uv[3];
      if (!value(tex, i, uv) || !std::isfinite(uv[0]))
        return Status::corrupt_input("glb: a decoded scalar is missing or not finite");
      out.scalars[base + i] = uv[0];
    }
    if (col) {
      std::uint32_t key = 0;
      if (col->data_type() == draco::DT_UINT8) {
        std::uint8_t c[3];
        if (!value(col, i, c)) return Status::corrupt_input("glb: a decoded COLOR_0 is missing");
        key = std::uint32_t(c[0]) << 16 | std::uint32_t(c[1]) << 8 | c[2];
      } else {
        float c[3];
        if (!value(col, i, c)) return Status::corrupt_input("glb: a decoded COLOR_0 is missing");
        for (float x : c)
          key = key << 8 | std::uint32_t(std::lround(std::clamp(x, 0.0f, 1.0f) * 255.0f));
      }
      if (const auto it = view_of_colour.find(key); it != view_of_colour.end())
        vertex_view[i] = it->second;
    }
  }
  out.triangles.reserve(out.triangles.size() + 3 * t);
  out.triangle_view.reserve(out.triangle_view.size() + t);
  for (std::size_t f = 0; f < t; ++f) {
    const draco::Mesh::Face& face = dm->face(draco::FaceIndex(std::uint32_t(f)));
    for (int c = 0; c < 3; ++c) {
      if (face[c].value() >= n)
        return Status::corrupt_input("glb: a decoded face index is out of range");
      out.triangles.push_back(std::uint32_t(base + face[c].value()));
    }
    out.triangle_view.push_back(vertex_view[face[0].value()]);
  }

  info.has_scalar = info.has_scalar || tex != nullptr;
  return Status::ok();
}

// A JSON pair of numbers [a, b] as floats, where both are within float's range (converting a
// wider double to float is undefined behaviour).
bool float_pair(const Json& r, std::array<float, 2>& out) {
  if (!r.is_array() || r.size() != 2) return false;
  for (std::size_t k = 0; k < 2; ++k) {
    if (!r[k].is_number()) return false;
    const double x = r[k].get<double>();
    if (!(std::abs(x) <= double(std::numeric_limits<float>::max()))) return false;
    out[k] = float(x);
  }
  return true;
}

Status decode_glb_unguarded(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info) {
  GlbChunks chunks;
  if (Status s = parse_glb(glb, chunks); !s) return s;
  const Json& json = chunks.json;
  const auto asset = json.find("asset");
  if (asset == json.end() || !asset->is_object() || !asset->contains("version") ||
      (*asset)["version"] != "2.0")
    return Status::corrupt_input("glb: asset.version is not \"2.0\"");

  Mesh mesh;
  GlbInfo result;
  const Json* meshes = array_member(json, "meshes");
  if (json.contains("meshes") && !meshes)
    return Status::corrupt_input("glb: meshes is not an array");
  // View directions and scalar range from extras.ldimesh of the first mesh, when there.
  if (meshes && !meshes->empty() && (*meshes)[0].is_object()) {
    const Json& m0 = (*meshes)[0];
    const auto extras = m0.find("extras");
    if (extras != m0.end() && extras->is_object() && extras->contains("ldimesh") &&
        (*extras)["ldimesh"].is_object()) {
      const Json& ours = (*extras)["ldimesh"];
      if (const Json* dirs = array_member(ours, "view_dirs"); dirs && dirs->size() <= 256) {
        for (const Json& d : *dirs) {
          if (!d.is_array() || d.size() != 3 ||
              !std::all_of(d.begin(), d.end(), [](const Json& x) { return x.is_number(); }))
            return Status::corrupt_input("glb: extras.ldimesh.view_dirs is malformed");
          const glm::dvec3 v(d[0].get<double>(), d[1].get<double>(), d[2].get<double>());
          if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
            return Status::corrupt_input("glb: extras.ldimesh.view_dirs is not finite");
          mesh.view_dirs.push_back(v);
        }
      }
      std::array<float, 2> pair{};
      if (const Json* range = array_member(ours, "scalar_range");
          range && float_pair(*range, pair)) {
        result.scalar_min = pair[0];
        result.scalar_max = pair[1];
      }
      // Per surface: [min, max] or null (read where every entry is one of them).
      if (const Json* ranges = array_member(ours, "surface_scalar_ranges");
          ranges && ranges->size() <= 256 &&
          std::all_of(ranges->begin(), ranges->end(),
                      [&](const Json& r) { return r.is_null() || float_pair(r, pair); }))
        for (const Json& r : *ranges)
          result.surface_scalar_ranges.push_back(
              r.is_null() || !float_pair(r, pair) ? std::nullopt : std::optional(pair));
    }
  }
  std::vector<std::array<std::uint8_t, 3>> view_colours;
  for (std::size_t k = 0; k < mesh.view_dirs.size(); ++k)
    view_colours.push_back(view_colour(k, mesh.view_dirs[k]));

  if (meshes) {
    for (const Json& m : *meshes) {
      const Json* primitives = m.is_object() ? array_member(m, "primitives") : nullptr;
      if (!primitives) return Status::corrupt_input("glb: a mesh has no primitives array");
      for (const Json& p : *primitives) {
        if (!p.is_object()) return Status::corrupt_input("glb: a primitive is not an object");
        if (Status s = decode_primitive(json, p, chunks.bin, mesh, result, view_colours); !s)
          return s;
      }
    }
  }
  if (!extent_fits_float(mesh.positions))
    return Status::corrupt_input("glb: the positions span more than half of float's range");
  if (!result.has_scalar) result.scalar_min = result.scalar_max = 0.0f;
  result.vertices = mesh.vertex_count();
  result.triangles = mesh.triangle_count();
  out = std::move(mesh);
  if (info) *info = result;
  return Status::ok();
}
}  // namespace

Status decode_glb(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info) {
  try {
    return decode_glb_unguarded(glb, out, info);
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory("glb: out of memory while decoding");
  } catch (const std::exception& e) {
    return Status::internal(std::string("glb: decoding failed: ") + e.what());
  }
}

}  // namespace ldimesh
