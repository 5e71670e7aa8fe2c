// read_vtu_isolated: read_vtu in a child process (vtu.hpp).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "ldimesh/core/base/isolated.hpp"
#include "ldimesh/core/io/vtu.hpp"

namespace ldimesh {
namespace {

// The bytes VTK reads for `path`: the file, and for a .pvtu record the pieces it names (its
// Source attributes, relative to the record's folder) that exist. A plain scan, in the parent:
// std::regex recurses once per character matched, and a long attribute would overflow the stack.
double input_bytes(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  double bytes = double(fs::file_size(path, ec));
  if (ec) return 0.0;
  // (A record of more than 64 MiB, no real one, gives a generous limit by itself.)
  if (fs::path(path).extension() != ".pvtu" || bytes > double(64 << 20)) return bytes;
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  const std::string record = text.str();
  for (std::size_t at = record.find("Source"); at != std::string::npos;
       at = record.find("Source", at + 1)) {
    std::size_t p = at + 6;
    const auto skip_space = [&] {
      while (p < record.size() && std::isspace(static_cast<unsigned char>(record[p])))
        ++p;
    };
    skip_space();
    if (p >= record.size() || record[p] != '=') continue;
    ++p;
    skip_space();
    if (p >= record.size() || (record[p] != '"' && record[p] != '\'')) continue;
    const std::size_t end = record.find(record[p], p + 1);
    if (end == std::string::npos) break;
    const std::uintmax_t size =
        fs::file_size(fs::path(path).parent_path() / record.substr(p + 1, end - p - 1), ec);
    if (!ec) bytes += double(size);
  }
  return bytes;
}

// The CPU limit for `input_bytes` bytes of files: 60 s + 10 s per MiB, whole seconds.
double cpu_limit(double input_bytes) {
  return std::min(1e6, 60.0 + std::floor(10.0 * input_bytes / double(1 << 20)));
}

}  // namespace

Status read_vtu_isolated(const std::string& path, const std::string& field, VtuElements& out,
                         const std::string& colour_field) {
  IsolatedTask task;
  task.prefix = "'" + path + "': ";
  task.process = "VTK's reader process";
  task.doing = "reading";
  task.over_cpu = "a damaged or hostile file";
  task.died =
      "a damaged file (VTK 9.1's XML reader trusts sizes and structure it does not check; "
      "docs/reliability.md)";
  task.cpu_seconds = cpu_limit(input_bytes(path));
  // The child sends the groups (type, order, cells, geometry, values, colour), then the totals.
  std::vector<std::uint8_t> bytes;
  LDIMESH_RETURN_IF_ERROR(run_isolated(
      task,
      [&](std::vector<std::uint8_t>& result) {
        VtuElements read;
        LDIMESH_RETURN_IF_ERROR(read_vtu(path, field, read, colour_field));
        ByteWriter w(result);
        w.put(std::uint64_t(read.groups.size()));
        for (const VtuElements::Group& g : read.groups) {
          w.put(std::int32_t(g.type));
          w.put(std::int32_t(g.order));
          w.put(std::uint64_t(g.cells));
          w.put_vector(g.geometry);
          w.put_vector(g.values);
          w.put_vector(g.colour);
        }
        w.put(std::uint64_t(read.cells));
        w.put(std::uint64_t(read.ghost_cells));
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
  // What read_vtu promises, checked again on this side of the pipe: groups of known types and
  // orders, in increasing (type, order), each cell's node count of values, points and colours,
  // cells that add up.
  constexpr std::uint64_t kMaxGroups = 6 * 8;
  if (!r.get(groups) || groups < 1 || groups > kMaxGroups) return truncated;
  read.groups.resize(std::size_t(groups));
  std::size_t total = 0;
  std::pair<int, int> previous{-1, 0};
  for (VtuElements::Group& g : read.groups) {
    std::int32_t type = 0, order = 0;
    std::uint64_t count = 0;
    if (!r.get(type) || !r.get(order) || !r.get(count) || !r.get_vector(g.geometry) ||
        !r.get_vector(g.values) || !r.get_vector(g.colour))
      return truncated;
    if (type < 0 || type > int(CellType::pyramid) || std::pair{type, order} <= previous)
      return truncated;
    previous = {type, order};
    g.type = CellType(type);
    g.order = order;
    const std::size_t nodes = cell_nodes(g.type, order);
    if (nodes == 0 || count == 0 || g.values.size() % nodes != 0 ||
        count != g.values.size() / nodes || g.geometry.size() % 3 != 0 ||
        g.geometry.size() / 3 != g.values.size() ||
        (!g.colour.empty() && g.colour.size() != g.values.size()))
      return truncated;
    g.cells = std::size_t(count);
    total += g.cells;
  }
  std::uint64_t ghosts = 0;
  if (!r.get(cells) || cells != total || !r.get(ghosts) || !r.get(read.bounds) ||
      !r.get(read.min_value) || !r.get(read.max_value) || !r.done())
    return truncated;
  read.ghost_cells = std::size_t(ghosts);
  read.cells = std::size_t(cells);
  out = std::move(read);
  return Status::ok();
}

}  // namespace ldimesh
