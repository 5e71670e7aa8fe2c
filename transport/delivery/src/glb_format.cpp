#include "glb_format.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

namespace ldimesh::glb_format {

static_assert(std::endian::native == std::endian::little, "GLB is little-endian");

std::uint32_t read_u32(const std::uint8_t* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

Status parse_glb(std::span<const std::uint8_t> glb, GlbChunks& chunks) {
  if (glb.size() < kGlbHeader + kChunkHeader)
    return Status::corrupt_input("glb: too short for a GLB");
  if (read_u32(glb.data()) != kGlbMagic) return Status::corrupt_input("glb: no glTF magic");
  if (read_u32(glb.data() + 4) != kGlbVersion)
    return Status::corrupt_input("glb: not glTF version 2");
  const std::uint32_t length = read_u32(glb.data() + 8);
  if (length != glb.size())
    return Status::corrupt_input("glb: header length " + std::to_string(length) + " but " +
                                 std::to_string(glb.size()) + " bytes (truncated or padded)");
  std::size_t pos = kGlbHeader;
  bool first = true, have_bin = false;
  while (pos < glb.size()) {
    if (glb.size() - pos < kChunkHeader)
      return Status::corrupt_input("glb: truncated chunk header");
    const std::uint32_t chunk_len = read_u32(glb.data() + pos);
    const std::uint32_t type = read_u32(glb.data() + pos + 4);
    pos += kChunkHeader;
    if (chunk_len > glb.size() - pos) return Status::corrupt_input("glb: chunk runs past the end");
    const std::span<const std::uint8_t> data = glb.subspan(pos, chunk_len);
    pos += chunk_len;
    if (first) {
      if (type != kChunkJson) return Status::corrupt_input("glb: first chunk is not JSON");
      chunks.json = Json::parse(data.begin(), data.end(), nullptr, /*allow_exceptions=*/false);
      if (chunks.json.is_discarded() || !chunks.json.is_object())
        return Status::corrupt_input("glb: JSON chunk is not a JSON object");
      first = false;
    } else if (type == kChunkBin && !have_bin) {
      chunks.bin = data;
      have_bin = true;
    }  // chunks of unknown types are ignored, as the GLB format asks
  }
  if (first) return Status::corrupt_input("glb: no JSON chunk");
  return Status::ok();
}

Status get_index(const Json& object, const char* key, std::size_t limit, std::size_t& value,
                 const std::string& what) {
  const auto it = object.find(key);
  if (it == object.end() || !it->is_number_integer() || it->get<std::int64_t>() < 0 ||
      std::uint64_t(it->get<std::int64_t>()) >= limit)
    return Status::corrupt_input("glb: " + what + " '" + key + "' missing or out of range");
  value = std::size_t(it->get<std::int64_t>());
  return Status::ok();
}

const Json* array_member(const Json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_array() ? &*it : nullptr;
}

BoundingBox bounding_box(const std::vector<glm::vec3>& positions) {
  BoundingBox b;
  for (const glm::vec3& p : positions) {
    const glm::dvec3 d(p);
    if (b.empty) {
      b.lo = b.hi = d;
      b.empty = false;
    } else {
      b.lo = glm::min(b.lo, d);
      b.hi = glm::max(b.hi, d);
    }
  }
  return b;
}

bool extent_fits_float(const std::vector<glm::vec3>& positions) {
  const BoundingBox b = bounding_box(positions);
  const glm::dvec3 e = b.hi - b.lo;
  const double limit = 0.5 * double(std::numeric_limits<float>::max());
  return b.empty || (e.x <= limit && e.y <= limit && e.z <= limit);
}

}  // namespace ldimesh::glb_format
