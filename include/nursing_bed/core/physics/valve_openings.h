// The valve openings of one cell over one control period (ROS-free): what the controller
// commands, the hardware applies and the observer integrates. Below the control side, the
// hardware and the observer, which all share it.
#pragma once

namespace nursing_bed {

/// Openings 0..1: a proportional valve takes it as its opening, an on/off valve as its duty over
/// the period (PWM).
struct ValveOpenings {
  double inlet = 0.0;           ///< inlet (fill) valve opening 0..1
  double vent = 0.0;            ///< vent valve opening 0..1
  bool vent_to_vacuum = false;  ///< CPR: the vent line is switched to the vacuum source
};

}  // namespace nursing_bed
