// The GLB container and what glb.cpp (the encoder) and glb_decode.cpp (the decoder) share: the
// chunk layout, JSON look-ups with checked indices, the bounds Draco quantizes over. Internal to
// the client library.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh::glb_format {

using Json = nlohmann::json;

constexpr std::uint32_t kGlbMagic = 0x46546C67u;  // "glTF", little-endian
constexpr std::uint32_t kGlbVersion = 2;
constexpr std::uint32_t kChunkJson = 0x4E4F534Au;  // "JSON"
constexpr std::uint32_t kChunkBin = 0x004E4942u;   // "BIN\0"
constexpr std::size_t kGlbHeader = 12, kChunkHeader = 8;
constexpr const char* kDraco = "KHR_draco_mesh_compression";
// The scalar's attribute (glTF: an application-specific semantic starts with "_"); GLBs written
// before it carried the scalar as TEXCOORD_0.u, which decode_glb still reads.
constexpr const char* kScalarAttribute = "_SCALAR";
constexpr int kMaxAutoPositionBits = 24;  // a float has 24 significant bits
constexpr std::size_t kMaxIndex = std::numeric_limits<std::int32_t>::max();  // Draco: int32

std::uint32_t read_u32(const std::uint8_t* p);

// The JSON and BIN chunks of a GLB; every length checked against the bytes there are.
struct GlbChunks {
  Json json;
  std::span<const std::uint8_t> bin;
};
// Splits `glb` into its chunks (a 12-byte header, JSON first, BIN optional, unknown ones skipped).
Status parse_glb(std::span<const std::uint8_t> glb, GlbChunks& chunks);

// A non-negative integer member of `object` that fits `limit`, or an error naming `what`.
Status get_index(const Json& object, const char* key, std::size_t limit, std::size_t& value,
                 const std::string& what);
// The array member `key` of `object`, or null.
const Json* array_member(const Json& object, const char* key);

struct BoundingBox {
  glm::dvec3 lo{0.0}, hi{0.0};
  bool empty = true;
};
BoundingBox bounding_box(const std::vector<glm::vec3>& positions);

// Draco quantizes positions over their range in float: a box wider than half of float's largest
// value overflows there, and Draco's encoder then crashes (found by fuzzing: finite coordinates
// of ±1.7e38 decoded from a GLB and encoded again). Such meshes are refused on both ways.
bool extent_fits_float(const std::vector<glm::vec3>& positions);

}  // namespace ldimesh::glb_format
