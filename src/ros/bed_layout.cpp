#include "nursing_bed/ros/bed_layout.h"

#include <console_bridge/console.h>
#include <urdf_parser/urdf_parser.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <utility>

namespace nursing_bed {

namespace {

// Generated URDFs print positions to 12 decimals; 1 um also covers hand-written ones.
constexpr double kPositionTolerance_m = 1e-6;
constexpr double kAxisTolerance = 1e-6;

/**
 * Collects what urdfdom logs through console_bridge while it parses, so that a parse failure
 * can say why (urdfdom itself only returns a null model). Restores the previous handler on
 * destruction. The handler is process-global: a console_bridge message from another thread
 * during the parse would land here too, which only adds a line to an error message.
 */
class ConsoleCapture : public console_bridge::OutputHandler {
 public:
  ConsoleCapture() : previous_(console_bridge::getOutputHandler()) { console_bridge::useOutputHandler(this); }
  ~ConsoleCapture() override { console_bridge::useOutputHandler(previous_); }
  ConsoleCapture(const ConsoleCapture&) = delete;
  ConsoleCapture& operator=(const ConsoleCapture&) = delete;

  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR) {
      text_ += text_.empty() ? text : "; " + text;
    }
  }
  const std::string& text() const { return text_; }

 private:
  console_bridge::OutputHandler* previous_;
  std::string text_;
};

std::string formatM(double value_m) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", value_m);
  return buffer;
}

std::string cellJointName(int row, int col) {
  return "airbag_" + std::to_string(row) + "_" + std::to_string(col) + "_joint";
}

const char* jointTypeName(int type) {
  switch (type) {
    case urdf::Joint::REVOLUTE: return "revolute";
    case urdf::Joint::CONTINUOUS: return "continuous";
    case urdf::Joint::PRISMATIC: return "prismatic";
    case urdf::Joint::FLOATING: return "floating";
    case urdf::Joint::PLANAR: return "planar";
    case urdf::Joint::FIXED: return "fixed";
    default: return "unknown";
  }
}

[[noreturn]] void fail(const std::string& what) { throw std::runtime_error("bed URDF: " + what); }

/// Pitch of a single-cell bed, which positions cannot give: from bed_link's visual box.
double pitchFromBedBox(const urdf::ModelInterface& model) {
  const urdf::LinkConstSharedPtr bed = model.getLink(BedLayout::kBedLink);
  if (bed->visual && bed->visual->geometry && bed->visual->geometry->type == urdf::Geometry::BOX) {
    const double length_m = std::static_pointer_cast<urdf::Box>(bed->visual->geometry)->dim.x;
    if (std::isfinite(length_m) && length_m > 0.0) {
      return length_m;
    }
  }
  fail("a 1 x 1 grid has no neighbours to give the pitch, and bed_link has no visual box to give it");
}

/// The parsed model; fails when the XML is not URDF or has no bed_link.
urdf::ModelInterfaceSharedPtr parseBedUrdf(const std::string& urdf_xml) {
  urdf::ModelInterfaceSharedPtr model;
  {
    ConsoleCapture capture;
    model = urdf::parseURDF(urdf_xml);
    if (!model) {
      fail("the XML does not parse as URDF" + (capture.text().empty() ? std::string() : ": " + capture.text()));
    }
  }
  if (!model->getLink(BedLayout::kBedLink)) {
    fail("there is no link '" + std::string(BedLayout::kBedLink) + "' (the bed frame) in robot '" + model->getName() +
         "'");
  }
  return model;
}

/// The cell at row, col that `joint` (named `name`) moves; fails unless the joint is a
/// prismatic joint on bed_link along +z with a travel.
CellLayout cellOfJoint(const std::string& name, const urdf::Joint& joint, int row, int col) {
  if (joint.type != urdf::Joint::PRISMATIC) {
    fail("cell joint " + name + " is " + jointTypeName(joint.type) + ", expected prismatic");
  }
  if (!joint.limits) {
    fail("cell joint " + name + " has no limits");
  }
  if (!(std::isfinite(joint.limits->lower) && std::isfinite(joint.limits->upper) &&
        joint.limits->upper > joint.limits->lower)) {
    fail("cell joint " + name + " has no travel: limits lower " + formatM(joint.limits->lower) + " m, upper " +
         formatM(joint.limits->upper) + " m");
  }
  if (joint.parent_link_name != BedLayout::kBedLink) {
    fail("cell joint " + name + " has parent " + joint.parent_link_name + ", expected " + BedLayout::kBedLink);
  }
  // Heights are along the bed's z: the axis as seen from bed_link must be +z.
  const urdf::Vector3 axis = joint.parent_to_joint_origin_transform.rotation * joint.axis;
  if (std::abs(axis.x) > kAxisTolerance || std::abs(axis.y) > kAxisTolerance ||
      std::abs(axis.z - 1.0) > kAxisTolerance) {
    fail("cell joint " + name + " moves along (" + formatM(axis.x) + ", " + formatM(axis.y) + ", " + formatM(axis.z) +
         ") in bed_link, expected +z (0 0 1)");
  }
  CellLayout cell;
  cell.row = row;
  cell.col = col;
  cell.joint_name = name;
  cell.link_name = joint.child_link_name;
  cell.x_m = joint.parent_to_joint_origin_transform.position.x;
  cell.y_m = joint.parent_to_joint_origin_transform.position.y;
  cell.min_height_m = joint.limits->lower;
  cell.max_height_m = joint.limits->upper;
  return cell;
}

using CellMap = std::map<std::pair<int, int>, CellLayout>;

/// Reads a canonical decimal index (0, or up to 6 digits without a leading zero) at `*at` and
/// the `separator` after it; false when there is none.
bool readIndex(std::string_view name, std::size_t* at, std::string_view separator, int* value) {
  std::size_t end = *at;
  while (end < name.size() && end - *at <= 6 && name[end] >= '0' && name[end] <= '9') ++end;
  const std::size_t digits = end - *at;
  if (digits == 0 || digits > 6 || (digits > 1 && name[*at] == '0')) return false;
  if (name.substr(end, separator.size()) != separator) return false;
  std::from_chars(name.data() + *at, name.data() + end, *value);  // <= 6 digits: fits an int
  *at = end + separator.size();
  return true;
}

/// (row, col) of a joint named airbag_<row>_<col>_joint; canonical decimal indices only, so
/// that a cell has exactly one possible joint name. No regex: a name of any length is read in
/// one bounded pass.
bool cellJointIndices(std::string_view name, int* row, int* col) {
  constexpr std::string_view kPrefix = "airbag_", kSuffix = "_joint";
  if (name.substr(0, kPrefix.size()) != kPrefix) return false;
  std::size_t at = kPrefix.size();
  return readIndex(name, &at, "_", row) && readIndex(name, &at, kSuffix, col) && at == name.size();
}

/// Every airbag_<row>_<col>_joint's cell by (row, col); fails when there is none.
CellMap cellsOf(const urdf::ModelInterface& model) {
  CellMap found;
  for (const auto& entry : model.joints_) {
    int row = 0, col = 0;
    if (!cellJointIndices(entry.first, &row, &col)) {
      continue;
    }
    CellLayout cell = cellOfJoint(entry.first, *entry.second, row, col);
    found.emplace(std::make_pair(cell.row, cell.col), std::move(cell));
  }
  if (found.empty()) {
    fail("there are no airbag_<row>_<col>_joint joints");
  }
  return found;
}

/// Fails unless the cells fill the rows x cols grid.
void checkFullGrid(const CellMap& found, int rows, int cols) {
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      if (found.find({r, c}) == found.end()) {
        fail("cells do not form a full " + std::to_string(rows) + " x " + std::to_string(cols) + " grid: cell row " +
             std::to_string(r) + " col " + std::to_string(c) + " (" + cellJointName(r, c) + ") is missing");
      }
    }
  }
}

/// Pitch from the first neighbours; rows must step towards -x (head first), cols towards +y.
double gridPitch(const CellMap& found, int rows, int cols, const urdf::ModelInterface& model) {
  const CellLayout& origin = found.at({0, 0});
  double pitch_m = 0.0;
  if (rows > 1) {
    pitch_m = origin.x_m - found.at({1, 0}).x_m;
  } else if (cols > 1) {
    pitch_m = found.at({0, 1}).y_m - origin.y_m;
  } else {
    pitch_m = pitchFromBedBox(model);
  }
  if (!(pitch_m > kPositionTolerance_m)) {
    fail("pitch is not positive (" + formatM(pitch_m) + " m between " + origin.joint_name + " and " +
         (rows > 1 ? cellJointName(1, 0) : cellJointName(0, 1)) +
         "): row 0 must be at the head (+x) and col 0 on the right (-y)");
  }
  return pitch_m;
}

/// Fails unless every cell sits where `pitch_m` from cell (0, 0) puts it.
void checkUniformPitch(const CellMap& found, double pitch_m) {
  const CellLayout& origin = found.at({0, 0});
  for (const auto& entry : found) {
    const CellLayout& cell = entry.second;
    const double expected_x_m = origin.x_m - cell.row * pitch_m;
    const double expected_y_m = origin.y_m + cell.col * pitch_m;
    if (std::abs(cell.x_m - expected_x_m) > kPositionTolerance_m ||
        std::abs(cell.y_m - expected_y_m) > kPositionTolerance_m) {
      fail("pitch is not uniform: " + cell.joint_name + " is at (" + formatM(cell.x_m) + ", " + formatM(cell.y_m) +
           ") m, but a pitch of " + formatM(pitch_m) + " m from " + origin.joint_name + " puts it at (" +
           formatM(expected_x_m) + ", " + formatM(expected_y_m) + ") m");
    }
  }
}

}  // namespace

BedLayout BedLayout::fromUrdf(const std::string& urdf_xml) {
  const urdf::ModelInterfaceSharedPtr model = parseBedUrdf(urdf_xml);
  CellMap found = cellsOf(*model);
  int rows = 0;
  int cols = 0;
  for (const auto& entry : found) {
    rows = std::max(rows, entry.first.first + 1);
    cols = std::max(cols, entry.first.second + 1);
  }
  checkFullGrid(found, rows, cols);
  const double pitch_m = gridPitch(found, rows, cols, *model);
  checkUniformPitch(found, pitch_m);

  BedLayout layout;
  layout.rows_ = rows;
  layout.cols_ = cols;
  layout.pitch_m_ = pitch_m;
  layout.cells_.reserve(found.size());
  for (auto& entry : found) {  // std::map order (row, col) is id order
    entry.second.id = static_cast<uint32_t>(entry.second.row * cols + entry.second.col);
    layout.cells_.push_back(std::move(entry.second));
  }
  return layout;
}

const CellLayout* BedLayout::find(int row, int col) const {
  if (row < 0 || row >= rows_ || col < 0 || col >= cols_) {
    return nullptr;
  }
  return &cells_[static_cast<size_t>(row * cols_ + col)];
}

const CellLayout* BedLayout::findId(uint32_t id) const { return id < cells_.size() ? &cells_[id] : nullptr; }

std::string BedLayout::describe() const {
  if (cells_.empty()) {
    return "bed layout: empty";
  }
  double min_height_m = cells_.front().min_height_m;
  double max_height_m = cells_.front().max_height_m;
  for (const CellLayout& cell : cells_) {
    min_height_m = std::min(min_height_m, cell.min_height_m);
    max_height_m = std::max(max_height_m, cell.max_height_m);
  }
  std::ostringstream out;
  out << "bed layout: " << rows_ << " x " << cols_ << " cells (rows along x, row 0 at the head), pitch "
      << formatM(pitch_m_) << " m, bed " << formatM(rows_ * pitch_m_) << " x " << formatM(cols_ * pitch_m_)
      << " m, heights " << formatM(min_height_m) << " .. " << formatM(max_height_m) << " m";
  return out.str();
}

}  // namespace nursing_bed
