#include "nursing_bed/core/observer/cell_observer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
namespace {

// Flow noise is taken as correlated over this time: a relative flow error e gives a mass
// error of e times the gas moved in one such time (a valve's area error is nearly constant).
constexpr double kFlowCorrelationS = 1.0;
// The velocity reported is the height's rate, filtered over this time [s].
constexpr double kVelocityFilterS = 0.05;
// Within this many orifice linear bands of ambient the flows take the readings' mean as it is
// and their noise bias is taken off; beyond, the square-root law's curvature biases them by
// less than 0.05 % at the readings' noise, and the readings are smoothed within their noise.
constexpr double kCurvedFlowBands = 3.0;
// Readings within their noise of each other are smoothed over this time for the flows [s].
constexpr double kFlowPressureFilterS = 0.03;
// The readings' noise: both valves shut this long before their readings count (a heavy plate
// rings on its gas spring after an edge) [s]; the configured sd counts as this many readings;
// about this many are remembered.
constexpr double kStillSettleS = 0.5;
// The weight bound's margin in standard errors of the readings' running mean. It is tested at
// every window of a hold (120 looks a minute), and a running mean crosses 3 of its standard
// errors somewhere in a long hold far more often than once in 740 (at 3, 2 of 40 simulated
// 60 s holds of a right inventory were pulled down, one by 0.4 mm: 1 % of a light plate's gas
// at a low hold, 3-4 mm at the top); at 4 none.
constexpr double kBoundStandardErrors = 4.0;
// A flat test found under an open vent waits for the count to hold less height than this [m],
// at most this long [s] (countAllowsFlat).
constexpr double kFlatCountM = 0.001;
constexpr double kCountDrainWaitS = 5.0;
constexpr double kNoisePriorReadings = 20.0;
constexpr double kNoiseMemoryReadings = 24000.0;

const CellParams& validModel(const CellParams& model, const CellObserverParams& params) {
  const Status valid = params.validate();
  if (!valid.ok()) throw std::invalid_argument("observer parameters: " + valid.message());
  const std::string error = model.validate();
  if (!error.empty()) throw std::invalid_argument("observer model: " + error);
  return model;
}

}  // namespace

Status CellObserverParams::validate() const {
  ErrorList errors;
  auto positive = [&errors](const char* name, double v) {
    errors.addIf(!(v > 0.0 && std::isfinite(v)), name, " must be positive, got ", v);
  };
  auto non_negative = [&errors](const char* name, double v) {
    errors.addIf(!(v >= 0.0 && std::isfinite(v)), name, " must be >= 0, got ", v);
  };
  positive("period_s", period_s);
  positive("pressure_noise_pa", pressure_noise_pa);
  positive("height_noise_m", height_noise_m);
  non_negative("flow_uncertainty", flow_uncertainty);
  non_negative("mass_walk_kg_sqrt_s", mass_walk_kg_sqrt_s);
  non_negative("heat_walk_w_sqrt_s", heat_walk_w_sqrt_s);
  positive("load_filter_time_s", load_filter_time_s);
  positive("initial_load_sd_n", initial_load_sd_n);
  non_negative("valve_dead_time_s", valve_dead_time_s);
  positive("reanchor_pressure_pa", reanchor_pressure_pa);
  non_negative("reanchor_time_s", reanchor_time_s);
  non_negative("weight_bound_window_s", weight_bound_window_s);
  non_negative("weight_bound_lift_window_s", weight_bound_lift_window_s);
  errors.addIf(!(vent_count_doubt >= 0.0 && vent_count_doubt <= 1.0), "vent_count_doubt must be in [0, 1], got ",
               vent_count_doubt);
  return errors.status();
}

CellObserver::CellObserver(const CellParams& model, const CellObserverParams& params,
                           const std::vector<CellEffectPtr>& effects)
    : params_(params),
      model_(validModel(model, params)),
      gamma_(model.gas.heat_capacity_ratio),
      delay_(params.valve_dead_time_s),
      pulse_(kCurvedFlowBands * model.orifice_linear_band_pa),
      reanchor_(params.reanchor_time_s, params.period_s, 0.0),
      weight_bound_(params.weight_bound_window_s, params.weight_bound_lift_window_s),
      reading_noise_(params.pressure_noise_pa, kNoisePriorReadings, kNoiseMemoryReadings) {
  for (const auto& e : effects) model_.addEffect(e);
  unstretched_top_m_ = model_.structure().heightLimit(model_.structure().restShape().data());
  // Flat means below half the lightest lifted plate's pressure (at most reanchor_pressure_pa).
  weight_bound_.tabulate(model_.structure(), model_.params().plate_mass_kg * kGravity, unstretched_top_m_);
  reanchor_ = ReanchorDetector(params_.reanchor_time_s, params_.period_s,
                               std::min(params_.reanchor_pressure_pa, 0.5 * weight_bound_.lowestLiftedPressure()));
  reset(0.6);
}

void CellObserver::reset(double load_n) {
  model_.reset(load_n);
  x_ = model_.state();
  x_[CellModel::kRegulator] = model_.params().supply_pressure_pa;
  p_ = Matrix2::Zero();
  p_(0, 0) = std::pow(1e-3 * x_[CellModel::kMass], 2);
  p_(1, 1) = std::pow(1e-3 * x_[CellModel::kEnergy], 2);
  load_n_ = load_n;
  load_var_n2_ = std::pow(params_.initial_load_sd_n, 2);
  time_ = 0.0;
  delay_.reset();
  applied_ = ObserverInputs{};
  last_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
  flow_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
  reanchor_.reset();
  weight_bound_.reset();
  pulse_.reset();
  still_s_ = 0.0;
  clearCountDoubt();
  since_edge_s_ = 0.0;
  flat_claimed_s_ = -1.0;
  reading_noise_.interrupt();
  refresh(modelInputs(applied_, last_pressure_pa_));
}

void CellObserver::resetToHeight(double height_m, double load_n) {
  reset(load_n);
  model_.resetToEquilibrium(height_m, load_n);
  x_ = model_.state();
  p_(0, 0) = std::pow(1e-3 * x_[CellModel::kMass], 2);
  p_(1, 1) = std::pow(1e-3 * x_[CellModel::kEnergy], 2);
  load_var_n2_ = std::pow(0.5, 2);
  refresh(modelInputs(applied_, last_pressure_pa_));
}

CellInputs CellObserver::modelInputs(const ObserverInputs& in, double flow_gauge_pressure_pa) const {
  CellInputs c;
  c.inlet_opening = std::clamp(in.valves.inlet, 0.0, 1.0);
  c.vent_opening = std::clamp(in.valves.vent, 0.0, 1.0);
  c.vent_back_pressure_pa = in.vent_back_pressure_pa;
  c.supply_pressure_pa = in.supply_pressure_pa;
  c.load_n = load_n_;
  // The valves pass gas at the cell's measured pressure, not at a model's.
  c.flow_gauge_pressure_pa = flow_gauge_pressure_pa;
  return c;
}

void CellObserver::refresh(const CellInputs& in) { model_.rate(time_, x_, in, &vars_); }

void CellObserver::integrateFlows(const CellInputs& in, double dt_s, double pulse_factor) {
  // The model's rates at the estimate: the gas's mass and energy change by the flows and heat
  // (its own work term, p dV/dt at the model's velocity and film rate, is taken back out: the
  // work is done along the measured pressure in isentropicWork); the regulator outlet and the
  // effects' states (a sensor lag, ...) follow their own equations.
  CellVariables v;
  const Vector dx = model_.rate(time_, x_, in, &v);
  const Eigen::Vector2d at_reading = gasRates(dx, v);
  const FlowNoise noise = flowNoise(in, at_reading);
  const Eigen::Vector2d gas = pulse_factor * (at_reading - noise.bias);
  x_[CellModel::kMass] += gas[0] * dt_s;
  x_[CellModel::kEnergy] += gas[1] * dt_s;
  // Each period's reading mean carries its own noise: the count walks by it (white, so no
  // filter of the readings shortens the walk; only the flat cell or a height measures it off).
  const Eigen::Vector2d walk = pulse_factor * dt_s * noise.sd;
  p_ += walk * walk.transpose();
  count_noise_kg2_ += walk[0] * walk[0];
  x_[CellModel::kRegulator] += dx[CellModel::kRegulator] * dt_s;
  for (int i = CellModel::kShape + model_.structure().shapeDofs(); i < x_.size(); ++i) x_[i] += dx[i] * dt_s;
  vars_.inflow_kg_s = v.inflow_kg_s;
  vars_.vent_flow_kg_s = v.vent_flow_kg_s;
  vars_.leak_flow_kg_s = v.leak_flow_kg_s;
}

Eigen::Vector2d CellObserver::gasRates(const Vector& dx, const CellVariables& v) {
  return {dx[CellModel::kMass], dx[CellModel::kEnergy] + v.pressure_pa * v.volume_rate_m3_s};
}

CellObserver::FlowNoise CellObserver::flowNoise(const CellInputs& in, const Eigen::Vector2d& at_reading) {
  // Near ambient the flows are taken at the mean of two readings (sd s = noise / sqrt 2). The
  // orifice law is curved there (its cubic band, then the square root), so flows at noisy
  // readings are biased by f'' s^2 / 2: about half a percent for a light plate venting at
  // 40 Pa under 10 Pa of noise, always the same way. Two sigma points estimate it, and their
  // spread the flows' scatter f' s: a third of a light plate's 30 Pa vent flow at 10 Pa of
  // noise. Smoothing the readings instead lagged the step a valve edge makes on a light plate
  // (77 to 44 Pa within one sample): each vent opening then counted 0.3 % of the gas too much.
  const double p = in.flow_gauge_pressure_pa;
  const double s = pressureNoise() / std::sqrt(2.0);
  FlowNoise noise;
  if (!std::isfinite(p) || std::fabs(p) > kCurvedFlowBands * model_.params().orifice_linear_band_pa) return noise;
  Eigen::Vector2d side_rates[2];
  for (int k = 0; k < 2; ++k) {
    CellInputs shifted = in;
    shifted.flow_gauge_pressure_pa = p + (k == 0 ? -s : s);
    CellVariables v;
    side_rates[k] = gasRates(model_.rate(time_, x_, shifted, &v), v);
  }
  noise.bias = 0.5 * (side_rates[0] + side_rates[1]) - at_reading;
  noise.sd = 0.5 * (side_rates[1] - side_rates[0]).cwiseAbs();
  return noise;
}

void CellObserver::propagateCovariance(double dt_s) {
  // Valve and leak flows, each carrying its enthalpy into the energy balance.
  const double cp = model_.params().gas.cp();
  auto add_flow_noise = [&](double variance, double temperature_k) {
    const Eigen::Vector2d g(1.0, cp * temperature_k);
    p_ += variance * g * g.transpose();
  };
  const double rel = params_.flow_uncertainty;
  add_flow_noise(std::pow(rel * vars_.inflow_kg_s, 2) * dt_s * kFlowCorrelationS, model_.params().supply_temperature_k);
  const double out_flow = std::fabs(vars_.vent_flow_kg_s) + std::fabs(vars_.leak_flow_kg_s);
  add_flow_noise((std::pow(rel * out_flow, 2) * kFlowCorrelationS + std::pow(params_.mass_walk_kg_sqrt_s, 2)) * dt_s,
                 vars_.temperature_k);
  p_(1, 1) += std::pow(params_.heat_walk_w_sqrt_s, 2) * dt_s;
}

double CellObserver::flowPressure(double old_pressure_pa, double new_pressure_pa, double dt_s) {
  // The flows' pressure is the mean over the period. Near ambient it is taken as it comes (a
  // light plate's pressure steps by tens of Pa within one sample at each valve edge; smoothed,
  // the flow after the edge took the pressure before it) and flowNoise corrects the noise's
  // bias. Away from ambient, a reading within three sds of the smoothed one is smoothed over
  // kFlowPressureFilterS: there a valve pulse's small swing is averaged whichever reading it
  // falls on; a larger move (a lift-off) is taken as it comes.
  const double mean = 0.5 * (old_pressure_pa + new_pressure_pa);
  const bool near_ambient = std::fabs(mean) <= kCurvedFlowBands * model_.params().orifice_linear_band_pa;
  if (near_ambient || !std::isfinite(flow_pressure_pa_) ||
      std::fabs(mean - flow_pressure_pa_) > 3.0 * pressureNoise()) {
    flow_pressure_pa_ = mean;
  } else {
    flow_pressure_pa_ += (mean - flow_pressure_pa_) * std::min(1.0, dt_s / kFlowPressureFilterS);
  }
  return flow_pressure_pa_;
}

void CellObserver::isentropicWork(double old_pressure_pa, double new_pressure_pa, double v0_m3) {
  // dU = -p dV with V = (gamma - 1) U / p at both ends and p the mean (trapezoid):
  // U1 (1 + pm (gamma - 1) / p1) = U0' + pm V0, U0' the energy after the flows.
  const double pa = model_.params().ambient_pressure_pa;
  const double p0 = pa + old_pressure_pa, p1 = pa + new_pressure_pa, pm = 0.5 * (p0 + p1);
  const double u_flow = x_[CellModel::kEnergy];
  const double denominator = 1.0 + pm * (gamma_ - 1.0) / p1;
  x_[CellModel::kEnergy] = (u_flow + pm * v0_m3) / denominator;
  // dU1/dU0 through V0 = (gamma - 1) U0 / p0.
  const double a = (1.0 + pm * (gamma_ - 1.0) / p0) / denominator;
  p_.row(1) *= a;
  p_.col(1) *= a;
}

double CellObserver::topHeight(double gauge_pressure_pa) const {
  // The film stretches under pressure and the bag's top rises with it: the structure's limit
  // with the film relaxed to the pressure (145-149 mm at 20 kPa against 142 mm unstretched;
  // clamped there, a plate at 145.5 mm read 142). Relaxing the film costs a solve per period
  // and cell: only for a plate already within a tenth of the unstretched top (a step does not
  // cross that tenth; the next one then takes the stretched top).
  const CellStructure& structure = model_.structure();
  const double unstretched = unstretched_top_m_;
  if (x_[CellModel::kHeight] < 0.9 * unstretched) return unstretched;
  const auto q =
      structure.relaxedShape(std::min(x_[CellModel::kHeight], unstretched), gauge_pressure_pa, &x_[CellModel::kShape]);
  return std::max(unstretched, structure.heightLimit(q.data()));
}

bool CellObserver::invertVolume(double gauge_pressure_pa, double dt_s) {
  // The height whose volume, with the film relaxed to the pressure, holds the gas at it.
  const CellStructure& structure = model_.structure();
  const int nq = structure.shapeDofs();
  const double target =
      (gamma_ - 1.0) * x_[CellModel::kEnergy] / (model_.params().ambient_pressure_pa + gauge_pressure_pa);
  // The shape each trial height would take over the period from the last one: a fold snaps
  // at its own rate, not at the first reading past its pressure (a vent's dip that recovers
  // within the fold's time leaves it where it was, in the cell as here).
  double start[kMaxShapeDofs], shape[kMaxShapeDofs];
  for (int i = 0; i < nq; ++i) start[i] = shape[i] = x_[CellModel::kShape + i];
  auto volume_at = [&](double h) {
    const auto q = structure.shapeAfter(h, gauge_pressure_pa, start, dt_s);
    for (int i = 0; i < nq; ++i) shape[i] = q[i];
    return structure.evaluate(h, shape).volume_m3;
  };
  const double h_old = x_[CellModel::kHeight];
  const double top = topHeight(gauge_pressure_pa);
  const double v_flat = volume_at(0.0);
  bool lifted = target > v_flat;
  double h = 0.0;
  if (lifted) {
    // Secant iterations from the last height, kept within the bracket the heights tried so far
    // give (flat below the gas, the top above): a step that leaves it, or a slope that is not
    // positive (the flat cell's volume hardly grows near its dead volume), bisects instead.
    double lo = 0.0, hi = top;
    auto tried = [&](double h_tried, double f) { f < 0.0 ? lo = std::max(lo, h_tried) : hi = std::min(hi, h_tried); };
    double h0 = std::clamp(h_old, 1e-4, top), f0 = volume_at(h0) - target;
    tried(h0, f0);
    double h1 = std::clamp(h0 - f0 / std::max(volume_slope_m2_, 1e-5), 0.0, top);
    double f1 = volume_at(h1) - target;
    tried(h1, f1);
    for (int it = 0; it < 40 && std::fabs(f1) > 1e-10 && hi - lo > 1e-9; ++it) {
      const double slope = (f1 - f0) / (h1 - h0);
      double next = slope > 0.0 && std::fabs(h1 - h0) > 1e-12 ? h1 - f1 / slope : 0.5 * (lo + hi);
      if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
      if (slope > 0.0) volume_slope_m2_ = slope;
      h0 = h1;
      f0 = f1;
      h1 = next;
      f1 = volume_at(h1) - target;
      tried(h1, f1);
    }
    h = h1;
    lifted = h > 0.0;
  }
  if (!lifted) volume_at(0.0);
  for (int i = 0; i < nq; ++i) x_[CellModel::kShape + i] = shape[i];
  x_[CellModel::kHeight] = h;
  const double rate = (h - h_old) / dt_s;
  x_[CellModel::kVelocity] += (rate - x_[CellModel::kVelocity]) * std::min(1.0, dt_s / kVelocityFilterS);
  return lifted;
}

void CellObserver::measureEnergy(double energy_j, double variance_j2) {
  const Eigen::Vector2d k = p_.col(1) / (p_(1, 1) + variance_j2);
  const Eigen::Vector2d innovation = k * (energy_j - x_[CellModel::kEnergy]);
  x_[CellModel::kMass] += innovation[0];
  x_[CellModel::kEnergy] += innovation[1];
  const Eigen::Matrix2d a = Eigen::Matrix2d::Identity() - k * Eigen::RowVector2d(0.0, 1.0);
  p_ = a * p_ * a.transpose() + variance_j2 * k * k.transpose();
}

void CellObserver::fuseHeight(double height_m) {
  // The gas's height (quasi-static: the film taken as relaxed) and the sensor's, by their
  // variances; the gas's is the better one while the film lags a fast move only by its sd.
  const double var_gas = std::max(height_sd_m_ * height_sd_m_, 1e-12);
  const double var_sensor = params_.height_noise_m * params_.height_noise_m;
  const double w = var_gas / (var_gas + var_sensor);
  x_[CellModel::kHeight] += w * (height_m - x_[CellModel::kHeight]);
  height_sd_m_ = std::sqrt(var_gas * var_sensor / (var_gas + var_sensor));
}

void CellObserver::updateLoad(double gauge_pressure_pa, bool lifted, double dt_s) {
  // Lifted: the plate's force balance, p A_eff less the guide's damping (its inertia is a
  // bounce the filter averages out). Down, the bed carries what the gas does not, unseen, but
  // the load holds the plate down against the flat cell's gas: it is at least that force (its
  // mean over the filter: a landing's impact rings for a few ms).
  const double cap = std::pow(3.0 * params_.initial_load_sd_n, 2);
  const double w = std::min(1.0, dt_s / params_.load_filter_time_s);
  if (!lifted) {
    load_var_n2_ = std::min(cap, load_var_n2_ + std::pow(params_.initial_load_sd_n, 2) * dt_s);
    const double pushed = model_.structure().evaluate(0.0, &x_[CellModel::kShape]).plateForce(gauge_pressure_pa);
    if (pushed > load_n_) load_n_ += (pushed - load_n_) * w;
    return;
  }
  const double area = vars_.structure.effective_area_m2;
  const double raw =
      vars_.structure.plateForce(gauge_pressure_pa) - model_.params().plate_damping_n_s_m * x_[CellModel::kVelocity];
  load_n_ += (raw - load_n_) * w;
  load_n_ = std::max(load_n_, model_.params().plate_mass_kg * kGravity);
  // The filtered reading's noise, and the area's error through the height's.
  const double h = x_[CellModel::kHeight];
  const double dh = 1e-3;
  const double force_up = model_.structure().evaluate(h + dh, &x_[CellModel::kShape]).plateForce(gauge_pressure_pa);
  const double noise = std::pow(pressureNoise() * area, 2) * w / 2.0;
  const double from_height =
      std::pow((force_up - vars_.structure.plateForce(gauge_pressure_pa)) / dh * height_sd_m_, 2);
  load_var_n2_ = std::min(cap, (1.0 - w) * load_var_n2_ + w * from_height + noise);
}

ObserverEvents CellObserver::step(const ObserverInputs& inputs, const Readings& readings, double dt_s) {
  const double dt = dt_s > 0.0 ? dt_s : params_.period_s;
  const double p_new = readings.gauge_pressure_pa;
  ObserverEvents events;
  if (!std::isfinite(p_new)) {
    predict(inputs, dt);
    return events;
  }
  takeInputs(inputs, dt);
  trackReadingNoise(p_new, dt);
  const double p_old = std::isfinite(last_pressure_pa_) ? last_pressure_pa_ : vars_.gauge_pressure_pa;
  CellInputs in = modelInputs(applied_, flowPressure(p_old, p_new, dt));
  if (std::isfinite(readings.inflow_kg_s)) in.prescribed_inflow_kg_s = readings.inflow_kg_s;
  // The gas's own volume at the last reading: the structure's where the height was inverted, and
  // where a flat plate's measurement was skipped the gas's, not the flat film's at that pressure.
  const double v_start = (gamma_ - 1.0) * x_[CellModel::kEnergy] / (model_.params().ambient_pressure_pa + p_old);
  propagateCovariance(dt);
  const double pulse = pulse_.factor(model_, time_, x_, vars_.pressure_pa, in, p_old, dt);
  integrateFlows(in, dt, pulse);
  doubtVentCount(pulse * std::fabs(vars_.vent_flow_kg_s) * dt, in.flow_gauge_pressure_pa);
  isentropicWork(p_old, p_new, v_start);
  keepPhysical();
  bool lifted = invertVolume(p_new, dt);
  const double pa = model_.params().ambient_pressure_pa;
  if (!lifted) measureFlat(p_new);
  if (std::isfinite(readings.height_m)) {
    clearCountDoubt();  // the height is measured
    const double v = model_.structure().evaluate(readings.height_m, &x_[CellModel::kShape]).volume_m3;
    const double sd = (pa + p_new) * vars_.structure.effective_area_m2 * params_.height_noise_m / (gamma_ - 1.0);
    measureEnergy((pa + p_new) * v / (gamma_ - 1.0), sd * sd);
    lifted = invertVolume(p_new, dt);
  } else {
    events.weight_bounded = boundByPlateWeight(p_new, lifted, dt);
  }
  keepPhysical();
  time_ += dt;
  last_pressure_pa_ = p_new;
  refresh(modelInputs(applied_, p_new));
  // The height's sd from the energy's: dV = (gamma - 1) dU / p over the slope dV/dh.
  height_sd_m_ =
      lifted ? (gamma_ - 1.0) * std::sqrt(std::max(0.0, p_(1, 1))) / (pa + p_new) / std::max(volume_slope_m2_, 1e-5)
             : 0.0;
  if (std::isfinite(readings.height_m)) fuseHeight(readings.height_m);
  updateLoad(p_new, lifted, dt);
  events.reanchored = checkReanchor(readings);
  return events;
}

void CellObserver::measureFlat(double gauge_pressure_pa) {
  // The plate is on the bed: the flat cell's volume and the pressure give the energy. Only while
  // it rests there: a reading whose gas would lift the load (at 3 sds) is a landing's impact or
  // a lift-off under way, the plate pressed into the film stack or the film off its rest, and
  // the flat cell's volume at that pressure is not the gas's (an FE table's flat bag holds over
  // 100 mL with its film at 3 kPa, 5 mL at rest).
  const StructureEval flat = model_.structure().evaluate(0.0, &x_[CellModel::kShape]);
  if (flat.plateForce(gauge_pressure_pa) > load_n_ + 3.0 * std::sqrt(std::max(0.0, load_var_n2_))) return;
  const double pa = model_.params().ambient_pressure_pa;
  const double u = (pa + gauge_pressure_pa) * flat.volume_m3 / (gamma_ - 1.0);
  measureEnergy(u, std::pow(pressureNoise() * flat.volume_m3 / (gamma_ - 1.0), 2));
  clearCountDoubt();  // the flat cell's gas is measured
}

void CellObserver::doubtVentCount(double vent_kg, double flow_gauge_pressure_pa) {
  // Only while the plate rings after a valve edge (a steady vent moves the plate steadily). The
  // swing is tens to hundreds of Pa whatever the pressure: its share of the flows falls with
  // the pressure beyond the curved bands.
  const double ringing_pa = kCurvedFlowBands * model_.params().orifice_linear_band_pa;
  const double p = std::fabs(flow_gauge_pressure_pa);
  if (!(vent_kg > 0.0) || !std::isfinite(p) || since_edge_s_ > RestingPlatePulse::kRingDownS) return;
  count_doubt_kg_ += params_.vent_count_doubt * std::min(1.0, ringing_pa / std::max(p, 1e-9)) * vent_kg;
}

void CellObserver::doubtCount(double gas_kg) {
  if (gas_kg > 0.0 && std::isfinite(gas_kg)) count_doubt_kg_ += gas_kg;
}

void CellObserver::trackReadingNoise(double gauge_pressure_pa, double dt_s) {
  still_s_ = valvesShut() ? still_s_ + dt_s : 0.0;
  if (still_s_ > kStillSettleS) {
    reading_noise_.addQuiet(gauge_pressure_pa);
  } else {
    reading_noise_.interrupt();
  }
}

void CellObserver::takeInputs(const ObserverInputs& inputs, double dt) {
  const ValveOpenings before = applied_.valves;
  applied_ = delay_.delayed(inputs, dt);
  const bool edge =
      std::fabs(applied_.valves.inlet - before.inlet) > 1e-6 || std::fabs(applied_.valves.vent - before.vent) > 1e-6;
  since_edge_s_ = edge ? 0.0 : since_edge_s_ + dt;
  if (std::isfinite(inputs.measured_supply_pa)) x_[CellModel::kRegulator] = inputs.measured_supply_pa;
}

void CellObserver::predict(const ObserverInputs& inputs, double dt_s) {
  coast(inputs, dt_s);
  reanchor_.interrupt();
}

void CellObserver::coast(const ObserverInputs& inputs, double dt_s) {
  const double dt = dt_s > 0.0 ? dt_s : params_.period_s;
  takeInputs(inputs, dt);
  reading_noise_.interrupt();
  // No reading: the cell model runs open loop under the load estimate, plate and all. Held
  // where it was instead, a cell still filling (a terminal keeps its outputs until its
  // watchdog) saw its pressure climb to the supply's and counted a fraction of the gas.
  const CellInputs in = modelInputs(applied_, std::numeric_limits<double>::quiet_NaN());
  propagateCovariance(dt);
  model_.setState(time_, x_);
  model_.advance(dt, in);
  x_ = model_.state();
  keepPhysical();
  time_ += dt;
  last_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
  refresh(in);
  pulse_.interrupt();
}

void CellObserver::keepPhysical() {
  x_[CellModel::kMass] = std::max(x_[CellModel::kMass], 1e-9);
  x_[CellModel::kEnergy] = std::max(x_[CellModel::kEnergy], 1e-6);
}

bool CellObserver::checkReanchor(const Readings& readings) {
  // A plate cannot rest lifted below the plate alone's pressure: a cell with its inlet shut
  // found that low for reanchor_time_s is flat, and its gas is known again.
  double mean_pa = 0.0;
  if (!(applied_.valves.vent > 0.0)) flat_claimed_s_ = -1.0;  // the count's wait is per vent
  if (!reanchor_.update(time_, applied_, readings.gauge_pressure_pa, &mean_pa)) return false;
  if (!countAllowsFlat()) return false;
  anchorFlat(mean_pa);
  return true;
}

bool CellObserver::countAllowsFlat() {
  // A light plate venting reads flat a few mm up: its vent's flow takes a few Pa of the 20 that
  // carry it. The count follows the vent at the pressure read, so the test waits until the count
  // holds less gas above the flat cell's than kFlatCountM of the plate's travel does (gas, not
  // height: where V(h) is flat near flat, an FE table's slack bag near ambient, a few
  // micrograms put the count millimetres up); at most kCountDrainWaitS, as the count of a cell
  // emptied behind its back (a flat cell read at ambient) drains nothing through the vent.
  if (!(applied_.valves.vent > 0.0) || x_[CellModel::kHeight] <= kFlatCountM) return true;
  const double* shape = &x_[CellModel::kShape];
  const double area =
      std::max(vars_.structure.effective_area_m2,
               model_.structure().evaluate(x_[CellModel::kHeight] + kFlatCountM, shape).effective_area_m2);
  const double count_m3 =
      (gamma_ - 1.0) * x_[CellModel::kEnergy] / (model_.params().ambient_pressure_pa + last_pressure_pa_);
  if (count_m3 - model_.structure().evaluate(0.0, shape).volume_m3 <= kFlatCountM * area) return true;
  if (flat_claimed_s_ < 0.0) flat_claimed_s_ = time_;
  return time_ - flat_claimed_s_ >= kCountDrainWaitS;
}

bool CellObserver::boundByPlateWeight(double gauge_pressure_pa, bool lifted, double dt_s) {
  // A patient presses on a plate and never lifts it, so its load is at least its own weight,
  // and the plate alone rests the higher the more pressure holds it: a settled plate's mean
  // pressure p bounds its height by h_W(p). The inventory integrates every valve pulse, and
  // near the bag's top 1 % of gas moves a light plate 10 mm (a descent to 0.03 m under the
  // plate alone counts its ~30 Pa vent within 1-2 % for the readings' noise); where it has
  // drifted above the bound, the energy is measured at the bound.
  // Lifted (the inlet open, the vent shut, the plate not falling by the count) the plate needs
  // its weight and more: the same bound, within a tenth of a second of a fill that moves no gas.
  const bool lifting = applied_.valves.inlet > 0.0 && applied_.valves.vent == 0.0 && x_[CellModel::kVelocity] >= 0.0;
  double mean = 0.0, se = 0.0;
  const bool quiet = weight_bound_.quietMean(gauge_pressure_pa, lifted, valvesShut(), dt_s, reading_noise_, &mean, &se);
  if (!quiet && !(weight_bound_.liftingMean(gauge_pressure_pa, lifted, lifting, dt_s, reading_noise_, &mean, &se) &&
                  mean >= weight_bound_.lowestLiftedPressure()))
    return false;  // below every lifted rest nothing is being lifted: not this bound's case (the landed test's)
  // The bound at a pressure kBoundStandardErrors above the mean (the readings' noise must not
  // move a plate that is where the inventory says), and the estimate moved only as far as that.
  const double bound = weight_bound_.plateAloneHeight(mean + kBoundStandardErrors * se);
  if (!(x_[CellModel::kHeight] > bound)) return false;
  const double sd = 0.5 * (weight_bound_.plateAloneHeight(mean + (kBoundStandardErrors + 1.0) * se) -
                           weight_bound_.plateAloneHeight(mean + (kBoundStandardErrors - 1.0) * se));
  if (!std::isfinite(sd)) return false;
  const double velocity = x_[CellModel::kVelocity];
  measureSettledHeight(bound, std::max(sd, 1e-4), mean);
  invertVolume(gauge_pressure_pa, dt_s);
  x_[CellModel::kVelocity] = velocity;  // a settled plate: the correction is no motion
  ++weight_bounds_;
  return true;
}

void CellObserver::measureSettledHeight(double height_m, double sd_m, double gauge_pressure_pa) {
  // U whose volume at that height (the film relaxed to the pressure) holds the gas at the
  // pressure.
  const CellStructure& structure = model_.structure();
  const auto shape = structure.relaxedShape(height_m, gauge_pressure_pa, &x_[CellModel::kShape]);
  const double volume = structure.evaluate(height_m, shape.data()).volume_m3;
  const double to_energy = (model_.params().ambient_pressure_pa + gauge_pressure_pa) / (gamma_ - 1.0);
  measureEnergy(to_energy * volume, std::pow(to_energy * volume_slope_m2_ * sd_m, 2));
}

void CellObserver::expectFlat(double for_s) { reanchor_.expectFlatUntil(time_ + for_s); }

void CellObserver::anchorFlat(double gauge_pressure_pa) {
  // The flat cell holds air at ambient temperature in its rest volume, at the pressure read
  // (p V = m R T: mass and energy scale with the absolute pressure): the gas is known again.
  model_.reset(load_n_);
  const CellModel::StateVector flat = model_.state();
  for (int i = 0; i < CellModel::kShape + model_.structure().shapeDofs(); ++i) {
    if (i == CellModel::kRegulator) continue;
    x_[i] = flat[i];
  }
  const double pa = model_.params().ambient_pressure_pa;
  const double scale = std::max(0.0, pa + gauge_pressure_pa) / pa;
  x_[CellModel::kMass] *= scale;
  x_[CellModel::kEnergy] *= scale;
  keepPhysical();
  p_ = Matrix2::Zero();
  p_(0, 0) = std::pow(1e-4 * x_[CellModel::kMass], 2);
  p_(1, 1) = std::pow(1e-4 * x_[CellModel::kEnergy], 2);
  ++reanchors_;
  clearCountDoubt();
  refresh(modelInputs(applied_, last_pressure_pa_));
}

CellEstimate CellObserver::estimate() const {
  CellEstimate e;
  e.height_m = x_[CellModel::kHeight];
  e.height_sd_m = height_sd_m_;
  e.velocity_m_s = x_[CellModel::kVelocity];
  e.mass_kg = x_[CellModel::kMass];
  e.mass_sd_kg = std::sqrt(std::max(0.0, p_(0, 0)));
  e.load_n = load_n_;
  e.load_sd_n = std::sqrt(std::max(0.0, load_var_n2_));
  e.gauge_pressure_pa = vars_.gauge_pressure_pa;
  e.temperature_k = vars_.temperature_k;
  e.volume_m3 = vars_.structure.volume_m3;
  e.reanchors = reanchors_;
  e.weight_bounds = weight_bounds_;
  e.pressure_noise_pa = pressureNoise();
  // At the pressure, the volume (and the height over dV/dh) goes with the gas.
  const double m = x_[CellModel::kMass];
  e.count_doubt_m = x_[CellModel::kHeight] > 0.0 && m > 0.0
                        ? countDoubtKg() / m * vars_.structure.volume_m3 / std::max(volume_slope_m2_, 1e-5)
                        : 0.0;
  return e;
}

void CellObserver::clearCountDoubt() { count_doubt_kg_ = count_noise_kg2_ = 0.0; }

double CellObserver::countDoubtKg() const { return count_doubt_kg_ + 2.0 * std::sqrt(count_noise_kg2_); }

void ObserverErrorStats::add(double error_m) {
  sum_sq_m2 += error_m * error_m;
  max_abs_m = std::max(max_abs_m, std::fabs(error_m));
  ++samples;
}

double ObserverErrorStats::rmsM() const { return samples > 0 ? std::sqrt(sum_sq_m2 / samples) : 0.0; }

}  // namespace nursing_bed
