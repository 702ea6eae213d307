#include "nursing_bed/core/control/cell_tuning.h"

namespace nursing_bed {

std::string applyTuning(AirbagCell& cell, const HeightControllerParams& controller, AirbagSafetyParams safety) {
  const HeightControllerParams old_controller = cell.params().controller;
  const AirbagSafetyParams old_safety = cell.params().safety;
  safety.command_timeout_s = old_safety.command_timeout_s;
  // A higher relief only loosens the controller's bound: then the safety part goes first.
  if (safety.relief_pressure_pa >= old_safety.relief_pressure_pa) {
    std::string error = cell.setSafetyParams(safety);
    if (!error.empty()) return error;
    error = cell.setControllerParams(controller);
    if (!error.empty()) cell.setSafetyParams(old_safety);  // the running pair was consistent
    return error;
  }
  std::string error = cell.setControllerParams(controller);
  if (!error.empty()) return error;
  error = cell.setSafetyParams(safety);
  if (!error.empty()) cell.setControllerParams(old_controller);
  return error;
}

}  // namespace nursing_bed
