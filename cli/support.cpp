#include "support.hpp"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include <unistd.h>

namespace ldimesh::cli {

void check_writable(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path p = fs::absolute(fs::path(path), ec);
  if (ec) throw std::runtime_error("cannot write '" + path + "': " + ec.message());
  if (fs::exists(p, ec)) {
    if (fs::is_directory(p, ec)) throw std::runtime_error("cannot write '" + path + "': a folder");
    if (::access(p.c_str(), W_OK) != 0)
      throw std::runtime_error("cannot write '" + path + "': " + std::strerror(errno));
    return;
  }
  fs::path folder = p.parent_path();
  while (folder.has_parent_path() && folder != folder.parent_path() && !fs::exists(folder, ec))
    folder = folder.parent_path();
  if (!fs::is_directory(folder, ec))
    throw std::runtime_error("cannot write '" + path + "': '" + folder.string() +
                             "' is not a folder");
  if (::access(folder.c_str(), W_OK | X_OK) != 0)
    throw std::runtime_error("cannot write '" + path + "': folder '" + folder.string() +
                             "': " + std::strerror(errno));
}

void write_atomically(const std::string& path,
                      const std::function<Status(const std::string& temporary)>& write) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  std::error_code ec;
  if (p.has_parent_path()) fs::create_directories(p.parent_path(), ec);
  if (ec)
    throw std::runtime_error("cannot create folder '" + p.parent_path().string() +
                             "': " + ec.message());
  // Hidden, beside it, with its extension (write_mesh tells the format by it).
  std::string name = ".";
  name += p.stem().string();
  name += ".part";
  name += std::to_string(::getpid());
  name += p.extension().string();
  const std::string temporary = (p.parent_path() / name).string();
  Status s = Status::ok();
  try {
    s = write(temporary);
  } catch (const std::exception& e) {
    s = Status::io(e.what());
  }
  if (s) {
    fs::rename(temporary, p, ec);
    if (ec) s = Status::io("cannot write '" + path + "': " + ec.message());
  }
  if (!s) {
    fs::remove(temporary, ec);
    throw std::runtime_error(s.message());
  }
}

// Whether `path` ends in `ext` (".ply"), in any letter case.
bool has_extension(const std::string& path, const std::string& ext) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e)
    c = char(std::tolower(static_cast<unsigned char>(c)));
  return e == ext;
}

}  // namespace ldimesh::cli
