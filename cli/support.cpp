#include "support.hpp"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace ldimesh::cli {

void check_writable(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  std::error_code ec;
  if (p.has_parent_path()) fs::create_directories(p.parent_path(), ec);
  if (ec)
    throw std::runtime_error("cannot create folder '" + p.parent_path().string() +
                             "': " + ec.message());
  std::FILE* f = std::fopen(path.c_str(), "ab");
  if (!f) throw std::runtime_error("cannot write '" + path + "': " + std::strerror(errno));
  std::fclose(f);
}

// Whether `path` ends in `ext` (".ply"), in any letter case.
bool has_extension(const std::string& path, const std::string& ext) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e)
    c = char(std::tolower(static_cast<unsigned char>(c)));
  return e == ext;
}

}  // namespace ldimesh::cli
