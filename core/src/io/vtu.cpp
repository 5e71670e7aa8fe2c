#include "ldimesh/core/io/vtu.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <new>
#include <stdexcept>

#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkLogger.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLPUnstructuredGridReader.h>
#include <vtkXMLUnstructuredDataReader.h>
#include <vtkXMLUnstructuredGridReader.h>

namespace ldimesh {
namespace {

// Collects the reader's error messages instead of VTK's output window.
class ErrorCollector : public vtkCommand {
 public:
  static ErrorCollector* New() { return new ErrorCollector; }
  void Execute(vtkObject*, unsigned long, void* data) override {
    if (message.empty() && data) message = static_cast<const char*>(data);
  }
  std::string message;
};

// The first line of a VTK message, without the "ERROR: In file, line N" prefix VTK puts first.
std::string first_line(std::string text) {
  const std::size_t newline = text.find('\n');
  if (newline != std::string::npos && newline + 1 < text.size() && text.rfind("ERROR", 0) == 0)
    text = text.substr(newline + 1);
  text = text.substr(0, text.find('\n'));
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back())))
    text.pop_back();
  return text;
}

const char* type_name(int type) {
  switch (type) {
    case VTK_TETRA:
      return "VTK_TETRA";
    case VTK_WEDGE:
      return "VTK_WEDGE";
    case VTK_PYRAMID:
      return "VTK_PYRAMID";
    case VTK_QUADRATIC_HEXAHEDRON:
      return "VTK_QUADRATIC_HEXAHEDRON";
    case VTK_TRIQUADRATIC_HEXAHEDRON:
      return "VTK_TRIQUADRATIC_HEXAHEDRON";
    case VTK_LAGRANGE_TETRAHEDRON:
      return "VTK_LAGRANGE_TETRAHEDRON";
    case VTK_LAGRANGE_WEDGE:
      return "VTK_LAGRANGE_WEDGE";
    case VTK_BEZIER_HEXAHEDRON:
      return "VTK_BEZIER_HEXAHEDRON";
    case VTK_VOXEL:
      return "VTK_VOXEL";
    case VTK_TRIANGLE:
      return "VTK_TRIANGLE";
    case VTK_QUAD:
      return "VTK_QUAD";
    default:
      return "a cell";
  }
}

}  // namespace

void quiet_vtk_logging() {
  vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);
}

HexBlock VtuElements::Group::block() const {
  HexBlock b;
  b.order = order;
  b.nodes = NodeSet::equispaced;
  b.ordering = NodeOrdering::vtk_lagrange;
  b.element_count = cells;
  b.values = values.data();
  b.type = ScalarType::float64;
  b.geometry_order = order;
  b.geometry = geometry.data();
  if (!colour.empty()) {
    b.colour = colour.data();
    b.colour_type = ScalarType::float64;
  }
  return b;
}

namespace {

// The one-component point array `name` of `grid`; an error naming the file's point arrays where
// there is none of that name.
Status scalar_point_array(vtkUnstructuredGrid* grid, const std::string& path,
                          const std::string& name, vtkDataArray*& out) {
  out = grid->GetPointData()->GetArray(name.c_str());
  if (!out) {
    std::string names;
    for (int a = 0; a < grid->GetPointData()->GetNumberOfArrays(); ++a) {
      const char* n = grid->GetPointData()->GetArrayName(a);
      names += std::string(names.empty() ? "" : ", ") + (n ? n : "(unnamed)");
    }
    return Status::invalid_argument("'" + path + "': no point array '" + name +
                                    "' (point arrays: " + (names.empty() ? "none" : names) + ")");
  }
  if (out->GetNumberOfComponents() != 1)
    return Status::invalid_argument("'" + path + "': point array '" + name + "' has " +
                                    std::to_string(out->GetNumberOfComponents()) +
                                    " components; give a scalar one");
  return Status::ok();
}

// A point takes at least 3 coordinates of 4 bytes (Float32), a cell at least its type (1
// byte), one offset and one connectivity entry (1 byte each in Int8 arrays), and no compressor
// VTK writes (zlib, LZ4, LZMA) shrinks data by more than 10 000 : 1 (zlib at most 1 032 : 1;
// LZMA reaches ≈ 7 000 : 1 on zeros). Counts above that cannot be the file's.
Status check_declared_counts(const std::string& path, std::uintmax_t bytes, vtkIdType points,
                             vtkIdType cells) {
  constexpr double kMaxCompression = 10000.0;
  const double room = double(bytes) * kMaxCompression;
  if (points < 0 || cells < 0 || 12.0 * double(points) > room || 3.0 * double(cells) > room)
    return Status::corrupt_input("'" + path + "': it declares " + std::to_string(points) +
                                 " points and " + std::to_string(cells) + " cells, more than its " +
                                 std::to_string(bytes) + " bytes can hold (a damaged file?)");
  return Status::ok();
}

Status read_vtu_unguarded(const std::string& path, const std::string& field, VtuElements& out,
                          const std::string& colour_field) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return Status::io("'" + path + "': no such file");
  if (field.empty()) return Status::invalid_argument("give the point array to mesh (--field NAME)");
  const std::string ext = std::filesystem::path(path).extension().string();
  vtkSmartPointer<vtkXMLReader> reader;
  if (ext == ".pvtu")
    reader = vtkSmartPointer<vtkXMLPUnstructuredGridReader>::New();
  else
    reader = vtkSmartPointer<vtkXMLUnstructuredGridReader>::New();
  vtkNew<ErrorCollector> errors;
  reader->AddObserver(vtkCommand::ErrorEvent, errors);
  reader->SetFileName(path.c_str());
  // VTK allocates (and fills) its arrays at the sizes the file declares before it reads them: a
  // damaged or hostile file of a few KB can ask for gigabytes (found by fuzzing). The XML
  // structure first, then the declared counts against what the file's bytes can hold at all.
  if (auto* data = vtkXMLUnstructuredDataReader::SafeDownCast(reader)) {
    data->UpdateInformation();
    data->SetupUpdateExtent(0, 1, 0);  // the whole file, as Update reads it
    if (!errors->message.empty())
      return Status::corrupt_input("'" + path +
                                   "': VTK cannot read it: " + first_line(errors->message));
    const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
    if (Status st = check_declared_counts(path, ec ? 0 : bytes, data->GetNumberOfPoints(),
                                          data->GetNumberOfCells());
        !st)
      return st;
  }
  reader->Update();
  vtkUnstructuredGrid* grid = vtkUnstructuredGrid::SafeDownCast(reader->GetOutputDataObject(0));
  if (!errors->message.empty())
    return Status::corrupt_input("'" + path +
                                 "': VTK cannot read it: " + first_line(errors->message));
  if (!grid || grid->GetNumberOfCells() == 0)
    return Status::corrupt_input("'" + path + "': no cells (not a VTK XML unstructured grid?)");

  vtkDataArray* values = nullptr;
  if (Status st = scalar_point_array(grid, path, field, values); !st) return st;
  vtkDataArray* colour = nullptr;
  if (!colour_field.empty())
    if (Status st = scalar_point_array(grid, path, colour_field, colour); !st) return st;
  vtkDataArray* degrees = grid->GetCellData()->GetArray("HigherOrderDegrees");
  if (degrees && (degrees->GetNumberOfComponents() != 3 ||
                  degrees->GetNumberOfTuples() < grid->GetNumberOfCells()))
    degrees = nullptr;

  // What VTK returns is as the file says: a cell may name a point the file does not have, and
  // an array may be shorter than the points (VTK checks neither).
  vtkPoints* points = grid->GetPoints();
  const vtkIdType point_count = points ? points->GetNumberOfPoints() : 0;
  if (point_count == 0) return Status::corrupt_input("'" + path + "': no points");
  for (const auto& [array, name] : {std::pair{values, field}, std::pair{colour, colour_field}})
    if (array && array->GetNumberOfTuples() < point_count)
      return Status::corrupt_input("'" + path + "': point array '" + name + "' has " +
                                   std::to_string(array->GetNumberOfTuples()) + " values for " +
                                   std::to_string(point_count) + " points");

  std::map<int, VtuElements::Group> groups;
  vtkNew<vtkIdList> ids;
  out.bounds = {glm::dvec3(std::numeric_limits<double>::infinity()),
                glm::dvec3(-std::numeric_limits<double>::infinity())};
  out.min_value = std::numeric_limits<double>::infinity();
  out.max_value = -out.min_value;
  const vtkIdType n = grid->GetNumberOfCells();
  for (vtkIdType c = 0; c < n; ++c) {
    const int type = grid->GetCellType(c);
    const std::string cell = "'" + path + "': cell " + std::to_string(c);
    if (type != VTK_LAGRANGE_HEXAHEDRON && type != VTK_HEXAHEDRON)
      return Status::corrupt_input(cell + " is " + type_name(type) + " (VTK type " +
                                   std::to_string(type) +
                                   "): only VTK_LAGRANGE_HEXAHEDRON and VTK_HEXAHEDRON are read");
    grid->GetCellPoints(c, ids);
    const vtkIdType count = ids->GetNumberOfIds();
    int order = 1;
    if (type == VTK_LAGRANGE_HEXAHEDRON) {
      order = int(std::lround(std::cbrt(double(count)))) - 1;
      if (degrees) {
        double d[3];
        degrees->GetTuple(c, d);
        // Any double (the array may be a float one, with NaN or 1e300): compared as doubles and
        // printed with %g, never converted to int.
        const auto text = [](double x) {
          char b[32];
          std::snprintf(b, sizeof b, "%g", x);
          return std::string(b);
        };
        if (d[0] != d[1] || d[1] != d[2])
          return Status::corrupt_input(cell + ": orders " + text(d[0]) + ", " + text(d[1]) + ", " +
                                       text(d[2]) + " differ along the axes (not supported)");
        if (d[0] != double(order))
          return Status::corrupt_input(cell + ": HigherOrderDegrees says order " + text(d[0]) +
                                       " but it has " + std::to_string(count) + " points");
      }
    }
    if (order < 1 || order > kMaxHexOrder ||
        vtkIdType(order + 1) * (order + 1) * (order + 1) != count)
      return Status::corrupt_input(cell + " has " + std::to_string(count) +
                                   " points: not (p + 1)³ for an order p of 1–" +
                                   std::to_string(kMaxHexOrder));
    VtuElements::Group& g = groups[order];
    g.order = order;
    ++g.cells;
    for (vtkIdType k = 0; k < count; ++k)
      if (ids->GetId(k) < 0 || ids->GetId(k) >= point_count)
        return Status::corrupt_input(cell + " names point " + std::to_string(ids->GetId(k)) +
                                     " of " + std::to_string(point_count));
    for (vtkIdType k = 0; k < count; ++k) {
      double x[3];
      points->GetPoint(ids->GetId(k), x);
      if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
        return Status::corrupt_input(cell + ": a point is not finite");
      g.geometry.insert(g.geometry.end(), {x[0], x[1], x[2]});
      out.bounds.lo = glm::min(out.bounds.lo, glm::dvec3(x[0], x[1], x[2]));
      out.bounds.hi = glm::max(out.bounds.hi, glm::dvec3(x[0], x[1], x[2]));
      const double v = values->GetTuple1(ids->GetId(k));
      g.values.push_back(v);
      if (colour) g.colour.push_back(colour->GetTuple1(ids->GetId(k)));
      if (std::isfinite(v))
        out.min_value = std::min(out.min_value, v), out.max_value = std::max(out.max_value, v);
    }
    ++out.cells;
  }
  for (auto& [order, g] : groups)
    out.groups.push_back(std::move(g));
  return Status::ok();
}

}  // namespace

// VTK allocates each array at the size the file declares and throws std::bad_alloc where that
// cannot be had (found by fuzzing: a mutated NumberOfPoints); that, like any exception from VTK
// or our containers, is an error Status here.
Status read_vtu(const std::string& path, const std::string& field, VtuElements& out,
                const std::string& colour_field) {
  out = {};
  try {
    return read_vtu_unguarded(path, field, out, colour_field);
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory("'" + path +
                                 "': out of memory while reading it (a damaged size?)");
  } catch (const std::exception& e) {
    return Status::corrupt_input("'" + path + "': reading it failed: " + e.what());
  }
}

}  // namespace ldimesh
