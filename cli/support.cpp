#include "support.hpp"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <sys/stat.h>
#include <unistd.h>

namespace ldimesh::cli {

namespace {

namespace fs = std::filesystem;

// The file a write of `path` lands in: a symbolic link's target (the link stays a link).
fs::path write_target(const std::string& path) {
  std::error_code ec;
  const fs::path p(path);
  if (fs::is_symlink(p, ec)) {
    const fs::path target = fs::weakly_canonical(p, ec);
    if (!ec) return target;
  }
  return p;
}

// The nearest folder at or above `folder` that exists ("." for a relative path's start).
fs::path existing_folder(fs::path folder) {
  std::error_code ec;
  if (folder.empty()) return ".";
  while (!fs::exists(folder, ec)) {
    if (!folder.has_parent_path() || folder == folder.parent_path()) return ".";
    folder = folder.parent_path();
    if (folder.empty()) return ".";
  }
  return folder;
}

// Throws `what` and why unless `folder` is a folder this process can write in.
void require_writable_folder(const std::string& what, const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw std::runtime_error(what + ": '" + folder.string() + "' is not a folder");
  if (::access(folder.c_str(), W_OK | X_OK) != 0)
    throw std::runtime_error(what + ": folder '" + folder.string() + "': " + std::strerror(errno));
}

}  // namespace

void check_writable(const std::string& path) {
  std::error_code ec;
  const fs::path p = write_target(path);
  if (fs::exists(p, ec)) {
    if (fs::is_directory(p, ec)) throw std::runtime_error("cannot write '" + path + "': a folder");
    if (::access(p.c_str(), W_OK) != 0)
      throw std::runtime_error("cannot write '" + path + "': " + std::strerror(errno));
  }
  // The file is written beside itself and renamed into place: its folder (or the nearest one
  // that exists, where the missing ones will be made) must be writable too.
  require_writable_folder("cannot write '" + path + "'", existing_folder(p.parent_path()));
}

void check_writable_folder(const std::string& path) {
  std::error_code ec;
  const fs::path p(path);
  if (fs::exists(p, ec) && !fs::is_directory(p, ec))
    throw std::runtime_error("cannot write into '" + path + "': not a folder");
  require_writable_folder("cannot write into '" + path + "'", existing_folder(p));
}

void write_atomically(const std::string& path,
                      const std::function<Status(const std::string& temporary)>& write,
                      const std::function<void()>& before_rename) {
  const fs::path p = write_target(path);
  std::error_code ec;
  // The folders this write makes, removed again (those still empty) if it fails.
  const fs::path made_from = existing_folder(p.parent_path());
  const auto remove_made = [&] {
    std::error_code ignored;
    for (fs::path f = p.parent_path(); !f.empty() && f != made_from && f != f.parent_path();
         f = f.parent_path())
      if (!fs::remove(f, ignored)) break;  // not empty, or not ours
  };
  if (p.has_parent_path()) fs::create_directories(p.parent_path(), ec);
  if (ec) {
    remove_made();
    throw std::runtime_error("cannot create folder '" + p.parent_path().string() +
                             "': " + ec.message());
  }
  // Hidden, beside it, with its extension (write_mesh tells the format by it), made with a
  // unique name by mkstemps (the name's stem capped so that it stays within a file name's limit).
  const std::string extension = p.extension().string();
  std::string name = ".";
  name += p.stem().string().substr(0, 100);
  name += ".partXXXXXX";
  name += extension;
  std::string temporary = (p.parent_path() / name).string();
  const int fd = ::mkstemps(temporary.data(), int(extension.size()));
  if (fd < 0) {
    const std::string why = std::strerror(errno);
    remove_made();
    throw std::runtime_error("cannot write '" + path + "': " + why);
  }
  ::close(fd);
  Status s = Status::ok();
  try {
    s = write(temporary);
    if (s && before_rename) before_rename();
  } catch (const std::exception& e) {
    s = Status::io(e.what());
  }
  if (s) {
    // An existing file's permissions carry over to its replacement; a new file gets those of
    // any new file (0666 less the umask), not mkstemps' 0600.
    const fs::file_status old = fs::status(p, ec);
    if (!ec && fs::exists(old)) {
      fs::permissions(temporary, old.permissions(), ec);
    } else {
      const mode_t mask = ::umask(0);
      ::umask(mask);
      fs::permissions(temporary, fs::perms(0666 & ~mask), ec);
    }
    ec.clear();
    fs::rename(temporary, p, ec);
    if (ec) s = Status::io("cannot write '" + path + "': " + ec.message());
  }
  if (!s) {
    fs::remove(temporary, ec);
    remove_made();
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
