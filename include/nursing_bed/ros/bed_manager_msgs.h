// Conversions between the bed supervisor's plain types (core bed_supervisor.h) and the bed
// manager's messages: the bed layout in, cell states in, ~state, /diagnostics, /joint_states
// and ~heights out. Pure functions, no NodeHandle.
#pragma once

#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/time.h>
#include <sensor_msgs/JointState.h>

#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/BedHeights.h"
#include "nursing_bed/BedState.h"
#include "nursing_bed/core/bed/bed_supervisor.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

/// The grid the core sees (height range: the first cell's).
BedGrid bedGrid(const BedLayout& layout);
/// The cells the supervisor watches, by id, named airbag_<r>_<c>.
std::vector<BedCell> bedCells(const BedLayout& layout);
/// A cell's state as it arrived at `seen_s` [s].
CellSnapshot cellSnapshot(const AirbagState& state, double seen_s);
/// ~state.
BedState bedStateMsg(const BedStatus& status, const ros::Time& stamp);
/// /diagnostics: the bed summary first, then one status per cell (with the values of its last
/// state, `last` by id, where `health` has one).
diagnostic_msgs::DiagnosticArray diagnosticsMsg(const BedReport& report, const BedLayout& layout,
                                                const std::vector<AirbagState>& last, const CellHealthWatcher& health,
                                                const ros::Time& stamp);
/// /joint_states: the reported heights clamped to the joints' ranges; cells never heard of are
/// left out.
sensor_msgs::JointState jointStatesMsg(const BedLayout& layout, const std::vector<AirbagState>& last,
                                       const CellHealthWatcher& health, const ros::Time& stamp);
/// ~heights: the heights as the cells reported them (not clamped), each at its own stamp.
BedHeights bedHeightsMsg(const BedLayout& layout, const std::vector<AirbagState>& last, const CellHealthWatcher& health,
                         const ros::Time& stamp);

}  // namespace nursing_bed
