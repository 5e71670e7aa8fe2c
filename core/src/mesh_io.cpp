#include "ldimesh/core/mesh_io.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <memory>
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
  if (!file) return Status::error("cannot write '" + path + "': " + std::strerror(errno));
  return Status::ok();
}

Status finish(const std::string& path, File& file) {
  const bool failed = std::ferror(file.get()) != 0;
  const int closed = std::fclose(file.release());
  if (failed || closed != 0)
    return Status::error("writing '" + path + "' failed: " + std::strerror(errno));
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

std::string view_comment(const glm::dvec3& d, std::size_t k) {
  char line[160];
  std::snprintf(line, sizeof(line), "comment view %zu dir %.17g %.17g %.17g\n", k, d.x, d.y, d.z);
  return line;
}

}  // namespace

Status write_ply(const std::string& path, const Mesh& mesh) {
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
    header += "element face " + std::to_string(mesh.face_count()) + "\n";
    header += "property list uchar uint vertex_indices\nproperty uchar view\nend_header\n";
    w.text(header);
    for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
      w.pod(mesh.positions[i]);
      w.pod(mesh.normals[i]);
    }
    for (std::size_t f = 0; f < mesh.quad_count(); ++f) {
      w.pod(std::uint8_t(4));
      w.bytes(&mesh.quads[4 * f], 4 * sizeof(std::uint32_t));
      w.pod(mesh.quad_view[f]);
    }
    for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
      w.pod(std::uint8_t(3));
      w.bytes(&mesh.triangles[3 * f], 3 * sizeof(std::uint32_t));
      w.pod(mesh.triangle_view[f]);
    }
  }
  return finish(path, file);
}

Status write_obj(const std::string& path, const Mesh& mesh) {
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
      face(&mesh.quads[4 * f], 4, mesh.quad_view[f]);
    for (std::size_t f = 0; f < mesh.triangle_count(); ++f)
      face(&mesh.triangles[3 * f], 3, mesh.triangle_view[f]);
  }
  return finish(path, file);
}

Status write_mesh(const std::string& path, const Mesh& mesh) {
  std::string ext = path.substr(std::min(path.size(), path.find_last_of('.')));
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".ply") return write_ply(path, mesh);
  if (ext == ".obj") return write_obj(path, mesh);
  return Status::error("cannot tell the format of '" + path + "': use a .ply or .obj file name");
}

}  // namespace ldimesh
