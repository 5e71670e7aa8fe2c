#include "ldimesh/core/io/mesh_io.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <string_view>

namespace ldimesh {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

Status open_for_writing(const std::string& path, File& file) {
  file.reset(std::fopen(path.c_str(), "wb"));
  if (!file) return Status::io("cannot write '" + path + "': " + std::strerror(errno));
  return Status::ok();
}

Status finish(const std::string& path, File& file) {
  const bool failed = std::ferror(file.get()) != 0;
  const int closed = std::fclose(file.release());
  if (failed || closed != 0)
    return Status::io("writing '" + path + "' failed: " + std::strerror(errno));
  return Status::ok();
}

// A growing byte buffer flushed to the file in large blocks.
class Writer {
 public:
  explicit Writer(std::FILE* f) : file_(f) { buffer_.reserve(kBlock + 256); }
  ~Writer() { flush(); }
  void bytes(const void* data, std::size_t n) {
    const char* p = static_cast<const char*>(data);
    buffer_.insert(buffer_.end(), p, p + n);
    if (buffer_.size() >= kBlock) flush();
  }
  template <class T>
  void pod(const T& value) {
    bytes(&value, sizeof(T));
  }
  void text(std::string_view s) { bytes(s.data(), s.size()); }
  void number(float v) {
    char tmp[32];
    auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
    bytes(tmp, std::size_t(r.ptr - tmp));
  }
  void number(std::uint64_t v) {
    char tmp[32];
    auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
    bytes(tmp, std::size_t(r.ptr - tmp));
  }
  void flush() {
    if (!buffer_.empty()) std::fwrite(buffer_.data(), 1, buffer_.size(), file_);
    buffer_.clear();
  }

 private:
  static constexpr std::size_t kBlock = 1 << 20;
  std::FILE* file_;
  std::vector<char> buffer_;
};

// Face f's view: 0 for a mesh without views (check_mesh allows empty view arrays).
std::uint8_t view_at(const std::vector<std::uint8_t>& views, std::size_t f) {
  return views.empty() ? 0 : views[f];
}

std::string view_comment(const glm::dvec3& d, std::size_t k) {
  char line[160];
  std::snprintf(line, sizeof(line), "comment view %zu dir %.17g %.17g %.17g\n", k, d.x, d.y, d.z);
  return line;
}

// ---- Reading PLY ----

enum class PlyFormat { ascii, binary_little_endian, binary_big_endian };
enum class PlyType { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

std::optional<PlyType> ply_type(std::string_view name) {
  static constexpr std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::int8},      {"int8", PlyType::int8},       {"uchar", PlyType::uint8},
      {"uint8", PlyType::uint8},    {"short", PlyType::int16},     {"int16", PlyType::int16},
      {"ushort", PlyType::uint16},  {"uint16", PlyType::uint16},   {"int", PlyType::int32},
      {"int32", PlyType::int32},    {"uint", PlyType::uint32},     {"uint32", PlyType::uint32},
      {"float", PlyType::float32},  {"float32", PlyType::float32}, {"double", PlyType::float64},
      {"float64", PlyType::float64}};
  for (const auto& [n, t] : kNames)
    if (n == name) return t;
  return std::nullopt;
}

std::size_t type_size(PlyType t) {
  switch (t) {
    case PlyType::int8:
    case PlyType::uint8:
      return 1;
    case PlyType::int16:
    case PlyType::uint16:
      return 2;
    case PlyType::int32:
    case PlyType::uint32:
    case PlyType::float32:
      return 4;
    case PlyType::float64:
      return 8;
  }
  return 8;
}

bool is_integer(PlyType t) {
  return t != PlyType::float32 && t != PlyType::float64;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::float32;  // of the values (of the entries, for a list)
  bool list = false;
  PlyType count_type = PlyType::uint8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;

  int find(std::string_view property) const {
    for (std::size_t k = 0; k < properties.size(); ++k)
      if (properties[k].name == property) return int(k);
    return -1;
  }
};

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t'))
      ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t')
      ++j;
    if (j > i) words.push_back(line.substr(i, j - i));
    i = j;
  }
  return words;
}

template <class T>
bool parse_number(std::string_view word, T& value) {
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  return ec == std::errc() && end == word.data() + word.size();
}

// "comment view k dir x y z" as write_ply writes it: the direction of view k.
void read_view_comment(const std::vector<std::string_view>& w, std::vector<glm::dvec3>& dirs) {
  std::size_t k = 0;
  glm::dvec3 d;
  if (w.size() == 7 && w[1] == "view" && w[3] == "dir" && parse_number(w[2], k) &&
      k == dirs.size() && parse_number(w[4], d.x) && parse_number(w[5], d.y) &&
      parse_number(w[6], d.z))
    dirs.push_back(d);
}

// Values of the body one at a time, every read bounded by the bytes left.
class PlyValues {
 public:
  PlyValues(std::string_view bytes, PlyFormat format) : bytes_(bytes), format_(format) {}

  std::size_t bytes_left() const { return bytes_.size() - pos_; }
  bool ascii() const { return format_ == PlyFormat::ascii; }

  // The next value of type t as a double (exact for every PLY type); false at the end of the
  // data, for malformed text or, in text, a value outside the type's range.
  bool read(PlyType t, double& value) {
    return ascii() ? read_text(t, value) : read_binary(t, value);
  }

  // Whether only whitespace (text) or nothing (binary) is left.
  bool at_end() const {
    if (!ascii()) return pos_ == bytes_.size();
    for (std::size_t i = pos_; i < bytes_.size(); ++i)
      if (!std::isspace(static_cast<unsigned char>(bytes_[i]))) return false;
    return true;
  }

 private:
  bool read_binary(PlyType t, double& value) {
    const std::size_t n = type_size(t);
    if (bytes_left() < n) return false;
    unsigned char b[8];
    std::memcpy(b, bytes_.data() + pos_, n);
    pos_ += n;
    if ((format_ == PlyFormat::binary_big_endian) == (std::endian::native == std::endian::little))
      std::reverse(b, b + n);
    switch (t) {
      case PlyType::int8:
        value = double(std::int8_t(b[0]));
        break;
      case PlyType::uint8:
        value = double(b[0]);
        break;
      case PlyType::int16:
        value = double(load<std::int16_t>(b));
        break;
      case PlyType::uint16:
        value = double(load<std::uint16_t>(b));
        break;
      case PlyType::int32:
        value = double(load<std::int32_t>(b));
        break;
      case PlyType::uint32:
        value = double(load<std::uint32_t>(b));
        break;
      case PlyType::float32:
        value = double(load<float>(b));
        break;
      case PlyType::float64:
        value = load<double>(b);
        break;
    }
    return true;
  }

  template <class T>
  static T load(const unsigned char* b) {
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
  }

  bool read_text(PlyType t, double& value) {
    while (pos_ < bytes_.size() && std::isspace(static_cast<unsigned char>(bytes_[pos_])))
      ++pos_;
    std::size_t end = pos_;
    while (end < bytes_.size() && !std::isspace(static_cast<unsigned char>(bytes_[end])))
      ++end;
    const std::string_view word = bytes_.substr(pos_, end - pos_);
    pos_ = end;
    if (word.empty()) return false;
    if (!is_integer(t)) {
      if (!parse_number(word, value)) return false;
      if (t == PlyType::float32 && std::isfinite(value)) value = double(float(value));
      return true;
    }
    std::int64_t i = 0;
    if (!parse_number(word, i)) return false;
    const std::size_t bits = 8 * type_size(t);
    const bool is_signed = t == PlyType::int8 || t == PlyType::int16 || t == PlyType::int32;
    const std::int64_t lo = is_signed ? -(std::int64_t(1) << (bits - 1)) : 0;
    const std::int64_t hi =
        is_signed ? (std::int64_t(1) << (bits - 1)) - 1 : (std::int64_t(1) << bits) - 1;
    if (i < lo || i > hi) return false;
    value = double(i);
    return true;
  }

  std::string_view bytes_;
  PlyFormat format_;
  std::size_t pos_ = 0;
};

Status ply_error(const std::string& what) {
  return Status::corrupt_input("PLY: " + what);
}

struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
  std::vector<glm::dvec3> view_dirs;
  std::size_t body = 0;  // offset of the first byte after end_header
};

Status parse_ply_header(std::string_view bytes, PlyHeader& h) {
  std::size_t pos = 0;
  bool have_format = false;
  for (int line_no = 1;; ++line_no) {
    const std::size_t nl = bytes.find('\n', pos);
    if (nl == std::string_view::npos)
      return ply_error(line_no == 1 ? "not a PLY file" : "the header has no end_header line");
    std::string_view line = bytes.substr(pos, nl - pos);
    pos = nl + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_no == 1) {
      if (line != "ply") return ply_error("not a PLY file (no 'ply' line)");
      continue;
    }
    const std::vector<std::string_view> w = split_words(line);
    const std::string where = "header line " + std::to_string(line_no);
    if (w.empty()) continue;
    if (w[0] == "end_header") break;
    if (w[0] == "comment") {
      read_view_comment(w, h.view_dirs);
    } else if (w[0] == "obj_info") {
      continue;
    } else if (w[0] == "format") {
      if (w.size() != 3 || w[2] != "1.0") return ply_error(where + ": bad format line");
      if (w[1] == "ascii")
        h.format = PlyFormat::ascii;
      else if (w[1] == "binary_little_endian")
        h.format = PlyFormat::binary_little_endian;
      else if (w[1] == "binary_big_endian")
        h.format = PlyFormat::binary_big_endian;
      else
        return ply_error(where + ": unknown format '" + std::string(w[1]) + "'");
      have_format = true;
    } else if (w[0] == "element") {
      PlyElement e;
      if (w.size() != 3 || !parse_number(w[2], e.count))
        return ply_error(where + ": bad element line");
      e.name = std::string(w[1]);
      for (const PlyElement& other : h.elements)
        if (other.name == e.name) return ply_error(where + ": element " + e.name + " twice");
      h.elements.push_back(std::move(e));
    } else if (w[0] == "property") {
      if (h.elements.empty()) return ply_error(where + ": property before any element");
      PlyProperty p;
      std::optional<PlyType> type, count;
      if (w.size() == 3 && w[1] != "list") {
        type = ply_type(w[1]);
        p.name = std::string(w[2]);
      } else if (w.size() == 5 && w[1] == "list") {
        p.list = true;
        count = ply_type(w[2]);
        type = ply_type(w[3]);
        p.name = std::string(w[4]);
        if (count && !is_integer(*count))
          return ply_error(where + ": a list count must be of an integer type");
        if (count) p.count_type = *count;
      } else {
        return ply_error(where + ": bad property line");
      }
      if (!type || (p.list && !count)) return ply_error(where + ": unknown property type");
      p.type = *type;
      if (h.elements.back().find(p.name) >= 0)
        return ply_error(where + ": property " + p.name + " twice");
      h.elements.back().properties.push_back(std::move(p));
    } else {
      return ply_error(where + ": unknown keyword '" + std::string(w[0]) + "'");
    }
  }
  if (!have_format) return ply_error("the header has no format line");
  h.body = pos;
  return Status::ok();
}

// Area-weighted vertex normals (for files without nx, ny, nz).
void compute_normals(Mesh& m) {
  std::vector<glm::dvec3> sum(m.positions.size(), glm::dvec3(0.0));
  auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    const glm::dvec3 pa(m.positions[a]), pb(m.positions[b]), pc(m.positions[c]);
    const glm::dvec3 n = glm::cross(pb - pa, pc - pa);
    sum[a] += n;
    sum[b] += n;
    sum[c] += n;
  };
  for (std::size_t t = 0; t < m.triangle_count(); ++t)
    add(m.triangles[3 * t], m.triangles[3 * t + 1], m.triangles[3 * t + 2]);
  for (std::size_t q = 0; q < m.quad_count(); ++q) {
    const std::uint32_t* v = &m.quads[4 * q];
    add(v[0], v[1], v[2]);
    add(v[0], v[2], v[3]);
  }
  m.normals.resize(m.positions.size());
  for (std::size_t i = 0; i < sum.size(); ++i) {
    const double len = glm::length(sum[i]);
    m.normals[i] = len > 0.0 ? glm::vec3(sum[i] / len) : glm::vec3(0.0f);
  }
}

Status parse_ply_body(const PlyHeader& h, std::string_view body, Mesh& m) {
  PlyValues values(body, h.format);
  const PlyElement* vertex_element = nullptr;
  for (const PlyElement& e : h.elements)
    if (e.name == "vertex") vertex_element = &e;
  if (!vertex_element) return ply_error("no vertex element");
  if (vertex_element->count > std::numeric_limits<std::uint32_t>::max())
    return ply_error("more than 2^32 - 1 vertices");
  for (const char* axis : {"x", "y", "z"}) {
    const int k = vertex_element->find(axis);
    if (k < 0 || vertex_element->properties[k].list)
      return ply_error(std::string("the vertex element has no property ") + axis);
  }
  const std::uint64_t vertex_count = vertex_element->count;

  std::vector<std::uint32_t> face;  // the indices of one face
  for (const PlyElement& e : h.elements) {
    if (e.properties.empty() || e.count == 0) continue;
    // Every item takes at least this many bytes: a check before anything is allocated.
    std::uint64_t min_bytes = 0;
    for (const PlyProperty& p : e.properties)
      min_bytes += values.ascii() ? 2 : type_size(p.list ? p.count_type : p.type);
    if (e.count > (values.bytes_left() + 1) / min_bytes)
      return ply_error("the file is too short for its " + std::to_string(e.count) + " " + e.name +
                       " elements");

    const bool is_vertex = &e == vertex_element;
    const bool is_face = e.name == "face";
    int xyz[3] = {-1, -1, -1}, nxyz[3] = {-1, -1, -1}, indices = -1, view = -1, value = -1;
    if (is_vertex) {
      value = e.find("value");
      if (value >= 0 && e.properties[value].list) value = -1;
      if (value >= 0) m.scalars.resize(e.count);
      for (int a = 0; a < 3; ++a) {
        xyz[a] = e.find(std::string(1, char('x' + a)));
        nxyz[a] = e.find(std::string("n") + char('x' + a));
        if (nxyz[a] >= 0 && e.properties[nxyz[a]].list) nxyz[a] = -1;
      }
      if (nxyz[0] < 0 || nxyz[1] < 0 || nxyz[2] < 0) nxyz[0] = nxyz[1] = nxyz[2] = -1;
      m.positions.resize(e.count);
      if (nxyz[0] >= 0) m.normals.resize(e.count);
    }
    if (is_face) {
      indices = e.find("vertex_indices");
      if (indices < 0) indices = e.find("vertex_index");
      if (indices < 0 || !e.properties[indices].list)
        return ply_error("the face element has no list property vertex_indices");
      if (!is_integer(e.properties[indices].type))
        return ply_error("vertex indices must be of an integer type");
      view = e.find("view");
      if (view >= 0 && e.properties[view].list) view = -1;
    }

    for (std::uint64_t item = 0; item < e.count; ++item) {
      double face_view = 0.0;
      face.clear();
      for (int k = 0; k < int(e.properties.size()); ++k) {
        const PlyProperty& p = e.properties[k];
        double v = 0.0;
        const auto truncated = [&] {
          return ply_error(e.name + " " + std::to_string(item) + ": property " + p.name +
                           (values.bytes_left() == 0 ? ": the file ends early"
                                                     : ": malformed or out-of-range value"));
        };
        if (!p.list) {
          if (!values.read(p.type, v)) return truncated();
          if (is_vertex) {
            for (int a = 0; a < 3; ++a) {
              if (k == xyz[a]) m.positions[item][a] = float(v);
              if (k == nxyz[a]) m.normals[item][a] = float(v);
            }
            if (k == value) {
              if (!std::isfinite(float(v)))
                return ply_error("vertex " + std::to_string(item) + ": value is not finite");
              m.scalars[item] = float(v);
            }
          }
          if (k == view) face_view = v;
          continue;
        }
        double count = 0.0;
        if (!values.read(p.count_type, count)) return truncated();
        if (count < 0.0) return ply_error(e.name + " " + std::to_string(item) + ": negative count");
        const std::size_t entry_bytes = values.ascii() ? 1 : type_size(p.type);
        if (count > double(values.bytes_left() / entry_bytes))
          return ply_error(e.name + " " + std::to_string(item) + ": the file ends early");
        for (std::uint64_t j = 0; j < std::uint64_t(count); ++j) {
          if (!values.read(p.type, v)) return truncated();
          if (k != indices) continue;
          if (v < 0.0 || v >= double(vertex_count))
            return ply_error("face " + std::to_string(item) + ": vertex index " +
                             std::to_string(std::int64_t(v)) + " out of range (" +
                             std::to_string(vertex_count) + " vertices)");
          face.push_back(std::uint32_t(v));
        }
      }
      if (is_vertex) {
        const glm::vec3& pos = m.positions[item];
        if (!std::isfinite(pos.x) || !std::isfinite(pos.y) || !std::isfinite(pos.z))
          return ply_error("vertex " + std::to_string(item) + " has a non-finite coordinate");
        if (!m.normals.empty()) {
          const glm::vec3& n = m.normals[item];
          if (!std::isfinite(n.x) || !std::isfinite(n.y) || !std::isfinite(n.z))
            return ply_error("vertex " + std::to_string(item) + " has a non-finite normal");
        }
      }
      if (!is_face) continue;
      if (face.size() < 3)
        return ply_error("face " + std::to_string(item) + " has " + std::to_string(face.size()) +
                         " vertices (at least 3 needed)");
      if (!(face_view >= 0.0 && face_view <= 255.0) || face_view != std::floor(face_view))
        return ply_error("face " + std::to_string(item) + ": view is not an integer in 0..255");
      const std::uint8_t fv = std::uint8_t(face_view);
      if (face.size() == 4) {
        m.quads.insert(m.quads.end(), face.begin(), face.end());
        m.quad_view.push_back(fv);
      } else {
        for (std::size_t j = 1; j + 1 < face.size(); ++j) {
          m.triangles.insert(m.triangles.end(), {face[0], face[j], face[j + 1]});
          m.triangle_view.push_back(fv);
        }
      }
    }
  }
  if (!values.at_end()) return ply_error("data after the last element");
  if (m.normals.empty()) compute_normals(m);
  m.view_dirs = h.view_dirs;
  return Status::ok();
}

}  // namespace

Status write_ply(const std::string& path, const Mesh& mesh) {
  if (const Status s = check_mesh(mesh); !s)
    return Status::invalid_argument("write_ply: " + s.message());
  File file;
  if (Status s = open_for_writing(path, file); !s) return s;
  {
    Writer w(file.get());
    std::string header = "ply\nformat binary_little_endian 1.0\ncomment written by ldimesh\n";
    for (std::size_t k = 0; k < mesh.view_dirs.size(); ++k)
      header += view_comment(mesh.view_dirs[k], k);
    header += "element vertex " + std::to_string(mesh.vertex_count()) + "\n";
    header += "property float x\nproperty float y\nproperty float z\n";
    header += "property float nx\nproperty float ny\nproperty float nz\n";
    if (!mesh.scalars.empty()) header += "property float value\n";
    header += "element face " + std::to_string(mesh.face_count()) + "\n";
    header += "property list uchar uint vertex_indices\nproperty uchar view\nend_header\n";
    w.text(header);
    for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
      w.pod(mesh.positions[i]);
      w.pod(mesh.normals[i]);
      if (!mesh.scalars.empty()) w.pod(mesh.scalars[i]);
    }
    for (std::size_t f = 0; f < mesh.quad_count(); ++f) {
      w.pod(std::uint8_t(4));
      w.bytes(&mesh.quads[4 * f], 4 * sizeof(std::uint32_t));
      w.pod(view_at(mesh.quad_view, f));
    }
    for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
      w.pod(std::uint8_t(3));
      w.bytes(&mesh.triangles[3 * f], 3 * sizeof(std::uint32_t));
      w.pod(view_at(mesh.triangle_view, f));
    }
  }
  return finish(path, file);
}

Status write_obj(const std::string& path, const Mesh& mesh) {
  if (const Status s = check_mesh(mesh); !s)
    return Status::invalid_argument("write_obj: " + s.message());
  File file;
  if (Status s = open_for_writing(path, file); !s) return s;
  {
    Writer w(file.get());
    w.text("# written by ldimesh\n");
    for (std::size_t k = 0; k < mesh.view_dirs.size(); ++k)
      w.text("# " + view_comment(mesh.view_dirs[k], k).substr(8));
    auto vec = [&](std::string_view tag, const glm::vec3& p) {
      w.text(tag);
      for (int a = 0; a < 3; ++a) {
        w.text(" ");
        w.number(p[a]);
      }
      w.text("\n");
    };
    for (const glm::vec3& p : mesh.positions)
      vec("v", p);
    for (const glm::vec3& n : mesh.normals)
      vec("vn", n);
    int group = -1;
    auto face = [&](const std::uint32_t* idx, int n, std::uint8_t view) {
      if (view != group) {
        group = view;
        w.text("g view_");
        w.number(std::uint64_t(view));
        w.text("\n");
      }
      w.text("f");
      for (int k = 0; k < n; ++k) {
        w.text(" ");
        w.number(std::uint64_t(idx[k]) + 1);
        w.text("//");
        w.number(std::uint64_t(idx[k]) + 1);
      }
      w.text("\n");
    };
    for (std::size_t f = 0; f < mesh.quad_count(); ++f)
      face(&mesh.quads[4 * f], 4, view_at(mesh.quad_view, f));
    for (std::size_t f = 0; f < mesh.triangle_count(); ++f)
      face(&mesh.triangles[3 * f], 3, view_at(mesh.triangle_view, f));
  }
  return finish(path, file);
}

Status write_mesh(const std::string& path, const Mesh& mesh) {
  std::string ext = path.substr(std::min(path.size(), path.find_last_of('.')));
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".ply") return write_ply(path, mesh);
  if (ext == ".obj") return write_obj(path, mesh);
  return Status::invalid_argument("cannot tell the format of '" + path +
                                  "': use a .ply or .obj file name");
}

Status parse_ply(std::string_view bytes, Mesh& mesh) {
  mesh = Mesh{};
  PlyHeader header;
  Status status = parse_ply_header(bytes, header);
  if (status) status = parse_ply_body(header, bytes.substr(header.body), mesh);
  if (!status) mesh = Mesh{};
  return status;
}

Status read_ply(const std::string& path, Mesh& mesh) {
  mesh = Mesh{};
  File file(std::fopen(path.c_str(), "rb"));
  if (!file) return Status::io("cannot read '" + path + "': " + std::strerror(errno));
  std::string bytes;
  char block[1 << 16];
  for (std::size_t n; (n = std::fread(block, 1, sizeof(block), file.get())) > 0;)
    bytes.append(block, n);
  if (std::ferror(file.get()))
    return Status::io("cannot read '" + path + "': " + std::strerror(errno));
  const Status status = parse_ply(bytes, mesh);
  if (!status) return status.prefixed("'" + path + "': ");
  return status;
}

}  // namespace ldimesh
