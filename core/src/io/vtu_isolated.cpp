// read_vtu_isolated: read_vtu in a child process (vtu.hpp).
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "ldimesh/core/base/isolated.hpp"
#include "ldimesh/core/io/vtu.hpp"

namespace ldimesh {
namespace {

// The bytes VTK reads for `path`: the file, and for a .pvtu record the pieces it names (its
// Source attributes, relative to the record's folder) that exist.
double input_bytes(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  double bytes = double(fs::file_size(path, ec));
  if (ec) return 0.0;
  if (fs::path(path).extension() != ".pvtu") return bytes;
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  const std::string record = text.str();
  static const std::regex source("Source\\s*=\\s*\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(record.begin(), record.end(), source);
       it != std::sregex_iterator(); ++it) {
    const std::uintmax_t size = fs::file_size(fs::path(path).parent_path() / (*it)[1].str(), ec);
    if (!ec) bytes += double(size);
  }
  return bytes;
}

}  // namespace

double vtu_read_cpu_limit(double input_bytes) {
  return std::min(1e6, 60.0 + std::floor(10.0 * input_bytes / double(1 << 20)));
}

Status read_vtu_isolated(const std::string& path, const std::string& field, VtuElements& out,
                         const std::string& colour_field) {
  IsolatedTask task;
  task.prefix = "'" + path + "': ";
  task.process = "VTK's reader process";
  task.doing = "reading";
  task.over_cpu = "a damaged or hostile file";
  task.died =
      "a damaged file (VTK 9.1's XML reader does not check the sizes inside compressed data; "
      "docs/reliability.md)";
  task.cpu_seconds = vtu_read_cpu_limit(input_bytes(path));
  // The child sends the groups (order, cells, geometry, values, colour), then the totals.
  std::vector<std::uint8_t> bytes;
  LDIMESH_RETURN_IF_ERROR(run_isolated(
      task,
      [&](std::vector<std::uint8_t>& result) {
        VtuElements read;
        LDIMESH_RETURN_IF_ERROR(read_vtu(path, field, read, colour_field));
        ByteWriter w(result);
        w.put(std::uint64_t(read.groups.size()));
        for (const VtuElements::Group& g : read.groups) {
          w.put(std::int32_t(g.order));
          w.put(std::uint64_t(g.cells));
          w.put_vector(g.geometry);
          w.put_vector(g.values);
          w.put_vector(g.colour);
        }
        w.put(std::uint64_t(read.cells));
        w.put(read.bounds);
        w.put(read.min_value);
        w.put(read.max_value);
        return Status::ok();
      },
      bytes));
  const Status truncated =
      Status::internal(task.prefix + "the output of " + task.process + " is truncated");
  ByteReader r(bytes);
  VtuElements read;
  std::uint64_t groups = 0, cells = 0;
  if (!r.get(groups) || groups > bytes.size()) return truncated;
  read.groups.resize(std::size_t(groups));
  for (VtuElements::Group& g : read.groups) {
    std::int32_t order = 0;
    std::uint64_t count = 0;
    if (!r.get(order) || !r.get(count) || !r.get_vector(g.geometry) || !r.get_vector(g.values) ||
        !r.get_vector(g.colour))
      return truncated;
    g.order = order;
    g.cells = std::size_t(count);
    // What read_vtu promises of a group, checked again on this side of the pipe.
    const std::size_t nodes =
        std::size_t(order + 1) * std::size_t(order + 1) * std::size_t(order + 1);
    if (order < 1 || order > 8 || g.values.size() != g.cells * nodes ||
        g.geometry.size() != 3 * g.values.size() ||
        (!g.colour.empty() && g.colour.size() != g.values.size()))
      return truncated;
  }
  if (!r.get(cells) || !r.get(read.bounds) || !r.get(read.min_value) || !r.get(read.max_value) ||
      !r.done())
    return truncated;
  read.cells = std::size_t(cells);
  out = std::move(read);
  return Status::ok();
}

}  // namespace ldimesh
