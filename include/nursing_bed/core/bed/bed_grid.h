// The bed's cell grid as the ROS-free core sees it: rows along the bed (row 0 at the head,
// +x), columns across (col 0 on the patient's right, -y), bed_link at the centre of the bed
// surface (REP-103), cell id = row * cols + col. Matches scripts/make_bed_urdf.py.
#pragma once

#include <cstdint>

namespace nursing_bed {

struct BedGrid {
  int rows = 20;
  int cols = 9;
  double pitch_m = 0.1;        ///< cell pitch [m]; a cell's face is pitch x pitch
  double min_height_m = 0.0;   ///< lowest cell height [m]
  double max_height_m = 0.15;  ///< highest cell height [m]

  int cells() const { return rows * cols; }
  std::uint32_t id(int row, int col) const { return static_cast<std::uint32_t>(row * cols + col); }
  int row(std::uint32_t id) const { return static_cast<int>(id) / cols; }
  int col(std::uint32_t id) const { return static_cast<int>(id) % cols; }
  /// Cell centre towards the head [m].
  double x(int row) const { return (0.5 * rows - row - 0.5) * pitch_m; }
  /// Cell centre to the patient's left [m].
  double y(int col) const { return (col + 0.5 - 0.5 * cols) * pitch_m; }
  double lengthM() const { return rows * pitch_m; }
  double widthM() const { return cols * pitch_m; }
  double cellAreaM2() const { return pitch_m * pitch_m; }
};

}  // namespace nursing_bed
