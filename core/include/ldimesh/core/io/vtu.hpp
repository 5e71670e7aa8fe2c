// Finite-element cells from VTK XML unstructured grids (.vtu, or a .pvtu record and its pieces),
// read by VTK's own readers (vtkXMLUnstructuredGridReader, vtkXMLPUnstructuredGridReader):
// hexahedra, tetrahedra, wedges and pyramids, linear, quadratic and Lagrange (order 1–8) — what
// deal.II's DataOut with write_higher_order_cells, dolfinx's VTKFile, meshio (gmsh meshes), MFEM
// and ParaView write. Built into the library `ldimesh::vtu` where VTK 9 is installed.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/hex_lookup.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {

// A file's cells, one group per cell type and order (each cell may have its own; a file may mix
// types). Geometry and field share the cell's nodes (VTK's cells are isoparametric), numbered as
// VTK numbers them (cell_source.hpp). A linear hexahedron is the Lagrange hexahedron of order 1,
// VTK_TRIQUADRATIC_HEXAHEDRON the one of order 2.
struct VtuElements {
  struct Group {
    CellType type = CellType::hexahedron;
    int order = 1;
    std::size_t cells = 0;
    std::vector<double> geometry;  // the cell's nodes × (x, y, z) per cell
    std::vector<double> values;    // a field value per node, per cell
    std::vector<double> colour;    // the same of the field to colour by, when one was read
    // Hexahedra (type hexahedron only: make_vtu_source chooses) as a block of high-order hexahedra
    // in VTK's order, equispaced, geometry of the cells' order (valid while the group lives and is
    // not resized).
    HexBlock block() const;
    // Any group as a block of cells.
    CellBlock cell_block() const;
  };
  std::vector<Group> groups;                // by type (CellType's order), then increasing order
  std::size_t cells = 0;                    // over all groups
  std::size_t ghost_cells = 0;              // cells flagged as duplicates and skipped
  Box bounds;                               // of every cell's points
  double min_value = 0.0, max_value = 0.0;  // of the field at the cells' points
};

// The source of one group: a HexElementSource for hexahedra, a CellElementSource for the others.
// Errors as the sources' constructors (std::invalid_argument naming the cell).
std::unique_ptr<FieldSource> make_vtu_source(const VtuElements::Group& group);

// Reads the point array `field` (one component) of every cell of `path` (.vtu or .pvtu): the cell
// types VTK_HEXAHEDRON, VTK_TRIQUADRATIC_HEXAHEDRON, VTK_LAGRANGE_HEXAHEDRON (hexahedron),
// VTK_QUADRATIC_HEXAHEDRON (serendipity_hexahedron), VTK_TETRA, VTK_QUADRATIC_TETRA,
// VTK_LAGRANGE_TETRAHEDRON (tetrahedron), VTK_WEDGE, VTK_BIQUADRATIC_QUADRATIC_WEDGE,
// VTK_LAGRANGE_WEDGE (wedge), VTK_QUADRATIC_WEDGE (serendipity_wedge), VTK_PYRAMID and
// VTK_QUADRATIC_PYRAMID (pyramid), mixed in one file. A Lagrange cell's order comes from the cell
// data array "HigherOrderDegrees" where the file has it (a hexahedron's equal along the three
// axes, a wedge's in its triangle and along its height), else from its point count. Cells whose
// "vtkGhostType" flags them as duplicates (bit 1, what parallel writers such as dolfinx mark) are
// skipped. Errors (one line, naming the file, and the cell or the field): a file VTK cannot read,
// another cell type, an order outside 1–8 or different along the axes or not matching the point
// count (VTK's 15-node tetrahedron and 21-node wedge are refused), a
// missing or multi-component field, non-finite points; for a .vtu, before VTK reads its data,
// sizes the file's bytes cannot hold, a component or tuple count that is not a number, two cell
// data arrays of one name (VTK 9.1 crashes on it) and two point arrays named as the field. With
// `colour_field`, that point array too, as each group's colour (HexBlock::colour: the
// isosurface coloured by it); the same errors.
Status read_vtu(const std::string& path, const std::string& field, VtuElements& out,
                const std::string& colour_field = "");

// read_vtu in a child process (run_isolated, core/base/isolated.hpp), for the tools that read
// files from anywhere (`ldimesh mesh --vtu`, `ldimesh distance --vtu`): VTK 9.1's XML reader
// trusts the sizes inside compressed data, so that a damaged file can crash it (a block size of
// 0: SIGFPE) or write through an allocation it does not check, and crashes on some damaged
// structures read_vtu does not foresee (docs/reliability.md). Here that
// is a corrupt_input error naming the file ("VTK's reader process died of signal 8 …"), as is a
// read that takes more than 60 s + 10 s per MiB of the file (and a .pvtu's pieces) of CPU; the
// rest as read_vtu, whose
// elements come back through a pipe, every count checked. `out` changes only on success.
Status read_vtu_isolated(const std::string& path, const std::string& field, VtuElements& out,
                         const std::string& colour_field = "");

// A file's field at world points: its cells, their sources and the lookup over them (for
// distances to, and projections onto, the cells' exact isosurface).
struct VtuField {
  VtuElements elements;
  std::vector<std::unique_ptr<FieldSource>> sources;  // one per group
  // What the lookup reads of the groups that are not hexahedra: their sub-hexahedra.
  std::vector<std::shared_ptr<const CellElementSource::Snapshot>> snapshots;
  std::unique_ptr<HexFieldLookup> lookup;
};

// read_vtu_isolated, then a source per group and the lookup over them. Errors as
// read_vtu_isolated's, and a source's refusal of a cell (one line naming it).
Status read_vtu_field(const std::string& path, const std::string& field, VtuField& out);

// Turns VTK's own logging to stderr off for the whole process: its XML parser and pipeline
// report a bad file there besides the error read_vtu returns. For programs that print their
// errors themselves (the command line).
void quiet_vtk_logging();

}  // namespace ldimesh
