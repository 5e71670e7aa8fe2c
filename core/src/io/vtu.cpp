#include "ldimesh/core/io/vtu.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
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

}  // namespace

Status read_vtu(const std::string& path, const std::string& field, VtuElements& out,
                const std::string& colour_field) {
  out = {};
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
  if (degrees && degrees->GetNumberOfComponents() != 3) degrees = nullptr;

  std::map<int, VtuElements::Group> groups;
  vtkPoints* points = grid->GetPoints();
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
        if (d[0] != d[1] || d[1] != d[2])
          return Status::corrupt_input(
              cell + ": orders " + std::to_string(int(d[0])) + ", " + std::to_string(int(d[1])) +
              ", " + std::to_string(int(d[2])) + " differ along the axes (not supported)");
        if (int(d[0]) != order)
          return Status::corrupt_input(cell + ": HigherOrderDegrees says order " +
                                       std::to_string(int(d[0])) + " but it has " +
                                       std::to_string(count) + " points");
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

Status read_vtu_field(const std::string& path, const std::string& field, VtuField& out) {
  out = {};
  if (Status st = read_vtu(path, field, out.elements); !st) return st;
  try {
    std::vector<const HexElementSource*> list;
    for (const VtuElements::Group& g : out.elements.groups) {
      out.sources.push_back(std::make_unique<HexElementSource>(g.block()));
      list.push_back(out.sources.back().get());
    }
    out.lookup = std::make_unique<HexFieldLookup>(list);
  } catch (const std::invalid_argument& e) {
    return Status::invalid_argument(path + ": " + e.what());
  }
  return Status::ok();
}

}  // namespace ldimesh
