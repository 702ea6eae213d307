// A simulated rig as the real-bed tests drive it: no height sensor, the pressure input's noise
// and quantisation, an optional valve dead time.
#pragma once

#include <memory>

#include "nursing_bed/core/control/airbag_cell.h"

namespace nursing_bed::test {

inline std::shared_ptr<SimulatedCellHardware> rigWithoutHeightSensor(const AirbagCellParams& p, double height_m,
                                                                     double load_n, double valve_dead_time_s = 0.0) {
  RigImperfections rig;
  rig.height_sensor = false;
  rig.adc_step_pa = 12.2;
  rig.valve_dead_time_s = valve_dead_time_s;
  auto hw = std::make_shared<SimulatedCellHardware>(rig);
  HardwareConfig c;
  c.control_period_s = p.control_period_s;
  c.cell = p.cell;
  c.pressure_noise_pa = 10.0;
  c.initial_height_m = height_m;
  c.load_n = load_n;
  hw->configure(c);
  return hw;
}

}  // namespace nursing_bed::test
