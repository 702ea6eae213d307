// Gas-coupled inflation of the FE airbag: explicit film and plate, control-volume gas.
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/fe/airbag_fe.h"
#include "nursing_bed/core/physics/gas.h"
#include "nursing_bed/core/physics/orifice.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace fe {

Status TransientSetup::validate() const {
  std::ostringstream err;
  const std::string cell_error = cell.validate();
  if (!cell_error.empty()) err << "cell: " << cell_error;
  else if (!(load_n > 0.0)) err << "load_n must be positive, got " << load_n;
  else if (!(duration_s > 0.0)) err << "duration_s must be positive, got " << duration_s;
  else if (!(film_damping_per_s >= 0.0)) err << "film_damping_per_s must be >= 0";
  else if (!(sample_s > 0.0)) err << "sample_s must be positive";
  return Status::fromMessage(err.str());
}

namespace {

// Adiabatic control volume (paper eq. 12-17): mass m and internal energy U.
struct GasVolume {
  double mass_kg, energy_j;
  double pressure(const GasProperties& g, double volume) const { return pressureFromEnergy(g, energy_j, volume); }
  double temperature(const GasProperties& g) const { return temperatureFromEnergy(g, energy_j, mass_kg); }
};

// Inflow [kg/s] and the temperature it carries.
double inflowAt(const TransientSetup& s, double t, double p_abs, double t_gas, double* t_in) {
  const CellParams& c = s.cell;
  *t_in = c.supply_temperature_k;
  if (s.prescribed_inflow) return s.prescribed_inflow->at(t);
  if (t >= s.inflation_end_s) return 0.0;
  const OrificeFlow f = orificeFlow(c.gas, c.inlet_area_m2, c.ambient_pressure_pa + c.supply_pressure_pa,
                                    c.supply_temperature_k, p_abs, t_gas, c.orifice_linear_band_pa);
  if (f.mass_flow_kg_s < 0.0) *t_in = t_gas;
  return f.mass_flow_kg_s;
}

}  // namespace

TransientResult runTransient(AirbagFe* bag, const TransientSetup& setup, const std::function<void(double)>& progress) {
  const Status valid = setup.validate();
  if (!valid) throw std::invalid_argument("runTransient: " + valid.message());
  MembraneModel& model = bag->model();
  const CellParams& c = setup.cell;
  PlateState& plate = model.plate();
  plate.mode = PlateState::Mode::kLoaded;
  plate.load_n = setup.load_n;
  plate.mass_kg = setup.load_n / kGravity;
  plate.damping_n_s_m = c.plate_damping_n_s_m;
  double volume = model.volume();
  GasVolume gas{massFromState(c.gas, c.ambient_pressure_pa, c.ambient_temperature_k, volume), 0.0};
  gas.energy_j = gas.mass_kg * c.gas.cv() * c.ambient_temperature_k;
  const double dt = model.stableTimeStep();
  TransientResult result;
  double next_sample = 0.0;
  const long total = static_cast<long>(std::ceil(setup.duration_s / dt));
  for (long k = 0; k <= total; ++k) {
    const double t = k * dt;
    const double p_abs = gas.pressure(c.gas, volume), t_gas = gas.temperature(c.gas);
    double t_in = 0.0;
    const double inflow = inflowAt(setup, t, p_abs, t_gas, &t_in);
    const double leak = orificeFlow(c.gas, c.leak_area_m2, p_abs, t_gas, c.ambient_pressure_pa, c.ambient_temperature_k,
                                    c.orifice_linear_band_pa)
                            .mass_flow_kg_s;
    model.computeForces(p_abs - c.ambient_pressure_pa);
    if (t >= next_sample - 1e-12) {
      QuasiStaticPoint s = bag->snapshot(p_abs - c.ambient_pressure_pa);
      result.samples.push_back(
          {t, inflow, p_abs - c.ambient_pressure_pa, s.height_m, volume, gas.mass_kg, t_gas, s.rim_inset_m});
      next_sample += setup.sample_s;
      if (progress) progress(t / setup.duration_s);
    }
    if (k == total) break;
    model.step(dt, setup.film_damping_per_s);
    const double new_volume = model.volume();
    // Energy: work p dV on the film (eq. 12-15), enthalpy in with the inflow, out with the leak.
    gas.energy_j += -p_abs * (new_volume - volume) + dt * (inflow * c.gas.cp() * t_in - leak * c.gas.cp() * t_gas);
    gas.mass_kg += dt * (inflow - leak);  // eq. 17
    volume = new_volume;
    if (!std::isfinite(gas.energy_j) || !(gas.mass_kg > 0.0) || !(volume > 0.0) || !model.positions().allFinite()) {
      std::ostringstream msg;
      msg << "transient failed at t = " << t << " s: non-finite or non-physical state (volume " << volume << " m^3)";
      result.message = msg.str();
      result.steps = k;
      return result;
    }
  }
  result.ok = true;
  result.message = "completed";
  result.steps = total;
  return result;
}

}  // namespace fe
}  // namespace nursing_bed
