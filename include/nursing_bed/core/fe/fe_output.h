// Output of the FE airbag: legacy VTK shapes for ParaView and the structure table that
// physics/tabulated_structure.h reads.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/fe/membrane_model.h"

namespace nursing_bed {
namespace fe {

/// Writes the current shape (triangles, per-cell stretch, state, part) and, with a plate, the
/// plate as a square; throws std::runtime_error when the file cannot be written.
void writeVtk(const std::string& path, const MembraneModel& model, const std::string& title);

/// Structure table V(h, p) and plate force F(h, p) on a grid (rows: heights, columns: pressures).
struct StructureTable {
  std::string description;
  std::vector<double> heights_m;
  std::vector<double> pressures_pa;
  std::vector<std::vector<double>> volume_m3;      ///< [height][pressure]
  std::vector<std::vector<double>> plate_force_n;  ///< [height][pressure]
};

/// YAML in the layout physics' TabulatedStructure reads (doc/fe_membrane.md).
void writeStructureTable(const std::string& path, const StructureTable& table);

}  // namespace fe
}  // namespace nursing_bed
