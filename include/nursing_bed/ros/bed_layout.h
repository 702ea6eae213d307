// Layout of the airbag array read from the bed's URDF (made by scripts/make_bed_urdf.py).
// Uses urdfdom only, no roscpp, so it is tested without a master.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace nursing_bed {

/// One airbag cell as the URDF describes it. Positions are in `bed_link` [m].
struct CellLayout {
  int row = 0;                ///< along the bed, 0 at the head
  int col = 0;                ///< across the bed, 0 on the patient's right (-y)
  uint32_t id = 0;            ///< row * cols + col
  std::string joint_name;     ///< prismatic joint `airbag_<row>_<col>_joint`; its position is the height
  std::string link_name;      ///< the joint's child: the cell's top plate
  double x_m = 0.0;           ///< cell centre, towards the head [m]
  double y_m = 0.0;           ///< cell centre, to the patient's left [m]
  double min_height_m = 0.0;  ///< joint lower limit [m]
  double max_height_m = 0.0;  ///< joint upper limit [m]
};

/**
 * The rows x cols grid of cells: rows run along the bed (row 0 at the head, +x), cols across
 * (col 0 at -y), on a uniform square pitch. Built only from a URDF that passes every check, so
 * a BedLayout in hand is always a full grid (or empty when default-constructed).
 */
class BedLayout {
 public:
  /// Frame of the bed surface and root of the cell joints.
  static constexpr const char* kBedLink = "bed_link";

  /// An empty layout (0 x 0); use fromUrdf() for a real one.
  BedLayout() = default;

  /**
   * Parses `urdf_xml` and checks it. Throws std::runtime_error naming the problem when the XML
   * does not parse, there is no `bed_link`, no `airbag_<r>_<c>_joint`, a cell joint is not a
   * prismatic joint on `bed_link` along +z with limits, a cell of the grid is missing, or the
   * pitch is not uniform.
   */
  static BedLayout fromUrdf(const std::string& urdf_xml);

  int rows() const { return rows_; }
  int cols() const { return cols_; }
  /// Centre-to-centre distance of neighbouring cells, the same along and across [m].
  double pitchM() const { return pitch_m_; }
  /// All cells, ordered by id (cells()[id].id == id).
  const std::vector<CellLayout>& cells() const { return cells_; }

  /// The cell at row, col, or nullptr when outside the grid.
  const CellLayout* find(int row, int col) const;
  /// The cell with this id, or nullptr when there is none.
  const CellLayout* findId(uint32_t id) const;

  /// One line for logs: grid, pitch, bed size, height range.
  std::string describe() const;

 private:
  int rows_ = 0;
  int cols_ = 0;
  double pitch_m_ = 0.0;
  std::vector<CellLayout> cells_;
};

}  // namespace nursing_bed
