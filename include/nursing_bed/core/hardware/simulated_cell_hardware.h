// The `simulated` cell hardware: the cell model as the plant and its sensors (noise, optional
// ADC quantisation), with the valve dead time of a real terminal when asked. The default of
// sim.launch, and what the rig emulator serves behind its Modbus registers.
#pragma once

#include <deque>
#include <memory>
#include <random>

#include "nursing_bed/core/hardware/cell_hardware.h"

namespace nursing_bed {

/// What a rig adds to the ideal sensors and valves (all off by default: today's simulation).
struct RigImperfections {
  double adc_step_pa = 0.0;        ///< pressure input quantisation step [Pa]; 0 = none
  double valve_dead_time_s = 0.0;  ///< a command reaches the valve this late [s]
  bool height_sensor = true;       ///< the simulated cell reports its height
};

// size: the hardware boundary plus the simulated plant's own inputs, views and fault reset
class SimulatedCellHardware : public CellHardware {
 public:
  explicit SimulatedCellHardware(const RigImperfections& rig = RigImperfections{}) : rig_(rig) {}

  void configure(const HardwareConfig& config) override;
  HardwareCapabilities capabilities() const override;
  /// Advances the plant in control periods (valves held over each) up to `now_s`, then reads.
  CellReadings read(double now_s) override;
  void write(const ValveOpenings& valves, double now_s) override;
  std::string describe() const override;

  // The simulation's own inputs and views (not part of the hardware boundary).
  /// Flat cell, valves shut, time 0.
  void reset(double load_n);
  /// Plate at rest at `height_m`, time 0.
  void resetToHeight(double height_m, double load_n);
  void setLoad(double load_n) { load_n_ = load_n; }
  double load() const { return load_n_; }
  void setSupplyPressure(double pressure_pa) { supply_pressure_pa_ = pressure_pa; }
  double supplyPressure() const { return supply_pressure_pa_; }
  /// Test hook: the sensors read NaN while set.
  void setSensorFailure(bool failed);
  /// Runs one control period with the valves commanded now (what read() does in a loop).
  /// A solve that throws or leaves an invalid state (plantValid() false) resets the plant flat
  /// at rest at the period's end, valves shut; the next read() reports device_reset.
  void stepPeriod();
  double time() const { return model_->time(); }
  const CellModel& model() const { return *model_; }
  const CellVariables& variables() const { return model_->variables(); }
  /// Last sensor readings (noise and quantisation applied; NaN after a sensor failure).
  const Readings& measurement() const { return measurement_; }
  /// Valve openings acting on the plant now (after the dead time).
  const ValveOpenings& actingValves() const { return acting_; }
  /// Flow totaliser and valve-opening integrals since reset [kg], [s].
  double meteredInletMassKg() const { return metered_inlet_mass_kg_; }
  double inletOpeningSeconds() const { return inlet_opening_s_; }
  double ventOpeningSeconds() const { return vent_opening_s_; }

 private:
  void sense();
  CellInputs plantInputs() const;
  /// The plant's state is usable: finite, volume > 0, mass > 0, T > 10 K, finite p and h.
  bool plantValid() const;
  /// After a failed solve: the plant flat at rest at `time_s` (the failed period's end, not
  /// trusted from a solve that threw midway), valves shut.
  void resetAfterFault(double time_s);

  RigImperfections rig_;
  HardwareConfig config_;
  std::unique_ptr<CellModel> model_;
  double load_n_ = 0.6;
  double supply_pressure_pa_ = 0.0;
  ValveOpenings commanded_, acting_;
  std::deque<ValveOpenings> valve_line_;      ///< commands on their way (dead time)
  Readings measurement_{0.0, 0.0, 0.0, 0.0};  ///< zeros until the first reading
  bool sensor_failed_ = false;
  bool device_reset_ = false;  ///< reported by (and cleared by) the next read()
  double metered_inlet_mass_kg_ = 0.0, inlet_opening_s_ = 0.0, vent_opening_s_ = 0.0;
  std::mt19937 rng_;
  std::normal_distribution<double> unit_noise_{0.0, 1.0};
};

}  // namespace nursing_bed
