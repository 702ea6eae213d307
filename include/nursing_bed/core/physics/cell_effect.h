// Plug-in physical effects on top of the nominal cell model (heat exchange, extra leaks,
// film viscoelasticity, sensor dynamics, ...). An effect adds terms to the balance equations
// and may carry states of its own; the core equations are never edited to add one.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <string>

#include "nursing_bed/core/physics/cell_structure.h"
#include "nursing_bed/core/physics/gas.h"
#include "nursing_bed/core/physics/readings.h"

namespace nursing_bed {

struct CellParams;

/// Everything known about the cell at one instant (SI units). Built by CellModel, read by
/// effects, controllers and publishers.
// size: a plain record of the cell at one instant, one field per physical quantity
struct CellVariables {
  double time_s = 0.0;
  double mass_kg = 0.0;                       ///< gas mass
  double internal_energy_j = 0.0;             ///< gas internal energy m cv T
  double height_m = 0.0;                      ///< plate height above the bed surface
  double velocity_m_s = 0.0;                  ///< plate velocity, + up
  double regulator_pressure_pa = 0.0;         ///< gauge pressure at the pressure-reducing valve outlet
  std::array<double, kMaxShapeDofs> shape{};  ///< film shape coordinates
  StructureEval structure;                    ///< volume, areas, film forces
  double pressure_pa = 0.0;                   ///< absolute gas pressure
  double gauge_pressure_pa = 0.0;             ///< pressure above ambient
  double temperature_k = 0.0;                 ///< gas temperature
  double load_n = 0.0;                        ///< external load on the plate (plate weight included)
  double moving_mass_kg = 0.0;                ///< plate plus load mass
  double inflow_kg_s = 0.0;                   ///< true mass flow entering through the inlet (+ in)
  double metered_inflow_kg_s = 0.0;           ///< inlet flow as given/metered before effects correct it
  double inflow_prescribed = 0.0;             ///< 1 when the inflow is imposed from a series, 0 valve-driven
  double inlet_closed = 0.0;                  ///< 1 when the inputs declare the inlet closed (CellInputs)
  double vent_flow_kg_s = 0.0;                ///< mass flow out through the vent valve
  double leak_flow_kg_s = 0.0;                ///< mass flow out through the nominal leak
  double bed_contact_force_n = 0.0;           ///< force of the bed on a bottomed-out plate
  double volume_rate_m3_s = 0.0;              ///< dV/dt
};

/// What an effect adds to the balance equations (all default to zero: no change).
struct EffectTerms {
  double mass_flow_kg_s = 0.0;                      ///< added to dm/dt (negative: gas leaves)
  double enthalpy_flow_w = 0.0;                     ///< energy carried by mass_flow_kg_s [W]
  double heat_flow_w = 0.0;                         ///< heat into the gas [W]
  double plate_force_n = 0.0;                       ///< upward force on the plate [N]
  std::array<double, kMaxShapeDofs> shape_force{};  ///< added to dW/dq (film overstress) [J]
};

class CellEffect {
 public:
  virtual ~CellEffect() = default;
  /// Canonical name (e.g. "heat_transfer").
  virtual std::string name() const = 0;
  /// Current parameter values by name (SI units in the names).
  virtual std::map<std::string, double> parameters() const = 0;
  /// Number of states the effect carries (appended to the cell state).
  virtual int stateSize() const { return 0; }
  /// Initial states given the initial cell variables.
  virtual void initialState(const CellParams& /*params*/, const CellVariables& /*cell*/, double* /*state*/) const {}
  /// Terms added to the balances and the derivative of the effect's own states.
  virtual void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                          double* state_rate) const = 0;
  /// Whether contribute() reads the valves' and leak's flows (inflow, vent, leak): the
  /// Jacobian's effect part computes those flows only when some effect does. True is always safe.
  virtual bool readsValveFlows() const { return true; }
  /// Lets the effect change what the sensors report.
  virtual void measure(const CellParams& /*params*/, const CellVariables& /*cell*/, const double* /*state*/,
                       Readings* /*measurement*/) const {}
};

using CellEffectPtr = std::shared_ptr<const CellEffect>;

}  // namespace nursing_bed
