// High-order hexahedra from VTK XML unstructured grids (.vtu, or a .pvtu record and its pieces),
// read by VTK's own readers (vtkXMLUnstructuredGridReader, vtkXMLPUnstructuredGridReader):
// VTK_LAGRANGE_HEXAHEDRON cells of order 1–8 — what deal.II's DataOut with
// write_higher_order_cells, MFEM and ParaView write — and linear VTK_HEXAHEDRON cells. Built
// into the library `ldimesh::vtu` where VTK 9 is installed.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/hex_lookup.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {

// A file's cells as high-order elements, one group per order (each cell may have its own): VTK
// Lagrange cells place their (p + 1)³ nodes equispaced in the reference cube, numbered in VTK's
// order, and the geometry has the cell's order too — the group's block says so (equispaced,
// vtk_lagrange, geometry_order = order). A linear hexahedron is the Lagrange cell of order 1.
struct VtuElements {
  struct Group {
    int order = 1;
    std::size_t cells = 0;
    std::vector<double> geometry;  // (order + 1)³ points × (x, y, z) per cell
    std::vector<double> values;    // (order + 1)³ field values per cell
    std::vector<double> colour;    // the same of the field to colour by, when one was read
    // The block over this group's arrays (valid while the group lives and is not resized).
    HexBlock block() const;
  };
  std::vector<Group> groups;                // increasing order
  std::size_t cells = 0;                    // over all groups
  Box bounds;                               // of every cell's points
  double min_value = 0.0, max_value = 0.0;  // of the field at the cells' points
};

// Reads the point array `field` (one component) of every cell of `path` (.vtu or .pvtu). A
// cell's order comes from the cell data array "HigherOrderDegrees" where the file has it (equal
// along the three axes), else from its point count ((p + 1)³). Errors (one line, naming the
// file, and the cell or the field): a file VTK cannot read, a cell type other than the two
// above, an order outside 1–8 or different along the axes or not matching the point count, a
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
  std::vector<std::unique_ptr<HexElementSource>> sources;  // one per group
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
