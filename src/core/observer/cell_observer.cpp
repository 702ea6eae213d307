#include "nursing_bed/core/observer/cell_observer.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace {

// Flow noise is taken as correlated over this time: a relative flow error e gives a mass
// error of e times the gas moved in one such time (a valve's area error is nearly constant).
constexpr double kFlowCorrelationS = 1.0;

std::string joinErrors(const std::ostringstream& err) {
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

const CellParams& validModel(const CellParams& model, const CellObserverParams& params) {
  std::string error = params.validate();
  if (!error.empty()) throw std::invalid_argument("observer parameters: " + error);
  error = model.validate();
  if (!error.empty()) throw std::invalid_argument("observer model: " + error);
  return model;
}

}  // namespace

std::string CellObserverParams::validate() const {
  std::ostringstream err;
  auto positive = [&err](const char* name, double v) {
    if (!(v > 0.0 && std::isfinite(v))) err << name << " must be positive, got " << v << "; ";
  };
  auto non_negative = [&err](const char* name, double v) {
    if (!(v >= 0.0 && std::isfinite(v))) err << name << " must be >= 0, got " << v << "; ";
  };
  positive("period_s", period_s);
  positive("pressure_noise_pa", pressure_noise_pa);
  positive("height_noise_m", height_noise_m);
  positive("inflow_noise_kg_s", inflow_noise_kg_s);
  non_negative("flow_uncertainty", flow_uncertainty);
  non_negative("mass_walk_kg_sqrt_s", mass_walk_kg_sqrt_s);
  non_negative("heat_walk_w_sqrt_s", heat_walk_w_sqrt_s);
  non_negative("force_noise_n", force_noise_n);
  non_negative("load_walk_n_sqrt_s", load_walk_n_sqrt_s);
  positive("initial_load_sd_n", initial_load_sd_n);
  non_negative("valve_dead_time_s", valve_dead_time_s);
  non_negative("reading_time_sd_s", reading_time_sd_s);
  positive("reanchor_pressure_pa", reanchor_pressure_pa);
  non_negative("reanchor_time_s", reanchor_time_s);
  non_negative("mass_lock_height_m", mass_lock_height_m);
  if (jacobian_refresh_steps < 1 || jacobian_refresh_steps > 100)
    err << "jacobian_refresh_steps must lie in 1..100, got " << jacobian_refresh_steps << "; ";
  return joinErrors(err);
}

CellObserver::CellObserver(const CellParams& model, const CellObserverParams& params,
                           const std::vector<CellEffectPtr>& effects)
    : params_(params), model_(validModel(model, params)) {
  for (const auto& e : effects) model_.addEffect(e);
  reset(0.6);
}

void CellObserver::reset(double load_n) {
  model_.reset(load_n);
  const int n = model_.stateSize();
  x_.resize(n + 1);
  x_.head(n) = model_.state();
  x_[n] = load_n;
  scale_.setConstant(n + 1, 1e-3);
  scale_[CellModel::kMass] = 1e-4;
  scale_[CellModel::kEnergy] = 10.0;
  scale_[CellModel::kHeight] = 1e-2;
  scale_[CellModel::kVelocity] = 0.1;
  scale_[CellModel::kRegulator] = 1e3;
  scale_[n] = 1.0;
  p_.setZero(n + 1, n + 1);
  for (int i = 0; i < n; ++i) p_(i, i) = std::pow(1e-4 * scale_[i], 2);
  p_(n, n) = std::pow(params_.initial_load_sd_n, 2);
  time_ = 0.0;
  pending_.clear();
  applied_ = ObserverInputs{};
  flat_since_s_ = -1.0;
  pressure_rate_pa_s_ = 0.0;
  steps_since_jacobian_ = 1 << 30;
  refresh();
}

void CellObserver::resetToHeight(double height_m, double load_n) {
  reset(load_n);
  model_.resetToEquilibrium(height_m, load_n);
  const int n = model_.stateSize();
  x_.head(n) = model_.state();
  p_(CellModel::kMass, CellModel::kMass) = std::pow(1e-3 * x_[CellModel::kMass], 2);
  p_(n, n) = std::pow(0.5, 2);
  refresh();
}

CellInputs CellObserver::modelInputs(const ObserverInputs& in, double load_n) const {
  CellInputs c;
  c.inlet_opening = std::clamp(in.inlet_opening, 0.0, 1.0);
  c.vent_opening = std::clamp(in.vent_opening, 0.0, 1.0);
  c.vent_back_pressure_pa = in.vent_back_pressure_pa;
  c.supply_pressure_pa = in.supply_pressure_pa;
  c.load_n = load_n;
  return c;
}

CellModel::StateVector CellObserver::rate(const Vector& x, const CellInputs& in, CellVariables* vars) const {
  CellInputs with_load = in;
  with_load.load_n = x[loadIndex()];
  return model_.rate(time_, x.head(loadIndex()), with_load, vars);
}

void CellObserver::refresh() { rate(x_, modelInputs(applied_, x_[loadIndex()]), &vars_); }

void CellObserver::step(const ObserverInputs& inputs, const ObserverReadings& readings, double dt_s) {
  predict(inputs, dt_s);
  correct(readings);
}

ObserverInputs CellObserver::delayed(const ObserverInputs& in) {
  const auto steps = static_cast<std::size_t>(std::lround(params_.valve_dead_time_s / params_.period_s));
  if (steps == 0) return in;
  pending_.push_back(in);
  if (pending_.size() <= steps) return ObserverInputs{};  // nothing commanded that long ago: shut
  const ObserverInputs out = pending_.front();
  pending_.pop_front();
  return out;
}

void CellObserver::predict(const ObserverInputs& inputs, double dt_s) {
  const double dt = dt_s > 0.0 ? dt_s : params_.period_s;
  applied_ = delayed(inputs);
  const CellInputs in = modelInputs(applied_, x_[loadIndex()]);
  if (++steps_since_jacobian_ >= params_.jacobian_refresh_steps) linearise(in);
  propagateCovariance(dt);
  const double p_before = vars_.gauge_pressure_pa;
  integrateMean(in, dt);
  time_ += dt;
  keepPhysical();
  refresh();
  pressure_rate_pa_s_ = (vars_.gauge_pressure_pa - p_before) / dt;
}

void CellObserver::linearise(const CellInputs& in) {
  const int n = static_cast<int>(x_.size());
  const CellModel::StateVector f0 = rate(x_, in);
  jacobian_.setZero(n, n);
  for (int j = 0; j < n; ++j) {
    Vector xp = x_;
    const double d = 1e-6 * std::max(std::fabs(x_[j]), scale_[j]);
    xp[j] += d;
    jacobian_.col(j).head(n - 1) = (rate(xp, in) - f0) / d;
  }
  steps_since_jacobian_ = 0;
}

void CellObserver::integrateMean(const CellInputs& in, double dt_s) {
  // The cell model's own integrator (error-controlled sub-steps through the plate's lift-off
  // and touch-down), started from the estimate.
  const int n = loadIndex();
  CellInputs with_load = in;
  with_load.load_n = x_[n];
  model_.setState(time_, x_.head(n), true);
  model_.advance(dt_s, with_load);
  x_.head(n) = model_.state();
}

void CellObserver::propagateCovariance(double dt) {
  const int n = static_cast<int>(x_.size());
  // Backward Euler, (I - dt J)^-1: the fast modes (film, bed contact) decay in one period as
  // they do in the plant, where a W-method map would keep half of them.
  const Matrix phi = (Matrix::Identity(n, n) - dt * jacobian_).partialPivLu().inverse();
  p_ = phi * p_ * phi.transpose();
  // Valve and leak flows, each carrying its enthalpy into the energy balance.
  const double cp = model_.params().gas.cp();
  auto add_flow_noise = [&](double variance, double temperature_k) {
    Vector g = Vector::Zero(n);
    g[CellModel::kMass] = 1.0;
    g[CellModel::kEnergy] = cp * temperature_k;
    p_ += variance * g * g.transpose();
  };
  const double rel = params_.flow_uncertainty;
  add_flow_noise(std::pow(rel * vars_.inflow_kg_s, 2) * dt * kFlowCorrelationS, model_.params().supply_temperature_k);
  const double out_flow = std::fabs(vars_.vent_flow_kg_s) + std::fabs(vars_.leak_flow_kg_s);
  add_flow_noise((std::pow(rel * out_flow, 2) * kFlowCorrelationS + std::pow(params_.mass_walk_kg_sqrt_s, 2)) * dt,
                 vars_.temperature_k);
  p_(CellModel::kEnergy, CellModel::kEnergy) += std::pow(params_.heat_walk_w_sqrt_s, 2) * dt;
  p_(CellModel::kVelocity, CellModel::kVelocity) += std::pow(params_.force_noise_n / vars_.moving_mass_kg, 2) * dt;
  p_(CellModel::kRegulator, CellModel::kRegulator) += std::pow(100.0, 2) * dt;
  p_(n - 1, n - 1) += std::pow(params_.load_walk_n_sqrt_s, 2) * dt;
}

void CellObserver::correct(const ObserverReadings& readings) {
  if (std::isfinite(readings.gauge_pressure_pa)) correctPressure(readings.gauge_pressure_pa);
  if (std::isfinite(readings.height_m)) {
    Vector h_row = Vector::Zero(x_.size());
    h_row[CellModel::kHeight] = 1.0;
    scalarUpdate(h_row, readings.height_m - x_[CellModel::kHeight], std::pow(params_.height_noise_m, 2));
  }
  if (std::isfinite(readings.inflow_kg_s)) correctInflow(readings.inflow_kg_s);
  keepPhysical();
  refresh();
  checkReanchor(readings);
}

void CellObserver::correctPressure(double gauge_pressure_pa) {
  // p_abs = (gamma - 1) U / V(h, q): its gradient from the structure at the estimate.
  const double gamma = model_.params().gas.heat_capacity_ratio;
  const StructureEval& s = vars_.structure;
  const double v = s.volume_m3, p_abs = vars_.pressure_pa;
  Vector h_row = Vector::Zero(x_.size());
  h_row[CellModel::kEnergy] = (gamma - 1.0) / v;
  h_row[CellModel::kHeight] = -p_abs * s.effective_area_m2 / v;
  for (int i = 0; i < model_.structure().shapeDofs(); ++i)
    h_row[CellModel::kShape + i] = -p_abs * s.dvolume_dshape[i] / v;
  // A reading's time is known to reading_time_sd_s only (bus cycle, valve timing): while the
  // pressure moves fast (a fill, a lift-off) that is worth (dp/dt * sd)^2 more variance, so
  // that a transient is not taken for a load change.
  const double timing_pa = pressure_rate_pa_s_ * params_.reading_time_sd_s;
  scalarUpdate(h_row, gauge_pressure_pa - vars_.gauge_pressure_pa,
               std::pow(params_.pressure_noise_pa, 2) + timing_pa * timing_pa);
}

void CellObserver::correctInflow(double inflow_kg_s) {
  const CellInputs in = modelInputs(applied_, x_[loadIndex()]);
  const int n = static_cast<int>(x_.size());
  Vector h_row = Vector::Zero(n);
  CellVariables v;
  for (int j = 0; j < n; ++j) {
    Vector xp = x_;
    const double d = 1e-6 * std::max(std::fabs(x_[j]), scale_[j]);
    xp[j] += d;
    rate(xp, in, &v);
    h_row[j] = (v.inflow_kg_s - vars_.inflow_kg_s) / d;
  }
  scalarUpdate(h_row, inflow_kg_s - vars_.inflow_kg_s, std::pow(params_.inflow_noise_kg_s, 2));
}

void CellObserver::scalarUpdate(const Vector& h_row, double innovation, double variance) {
  const Vector ph = p_ * h_row;
  const double s = h_row.dot(ph) + variance;
  if (!(s > 0.0) || !std::isfinite(innovation)) return;
  Vector k = ph / s;
  // A lifted plate's pressure cannot tell a gas mass error from a load change: the mass is
  // integrated from the flows alone there, and corrected only while the plate is down.
  if (x_[CellModel::kHeight] > params_.mass_lock_height_m) k[CellModel::kMass] = 0.0;
  x_ += k * innovation;
  p_ -= k * ph.transpose();
  p_ = 0.5 * (p_ + p_.transpose());
  refresh();
}

void CellObserver::keepPhysical() {
  const int l = loadIndex();
  x_[CellModel::kMass] = std::max(x_[CellModel::kMass], 1e-9);
  x_[CellModel::kEnergy] = std::max(x_[CellModel::kEnergy], 1e-6);
  x_[l] = std::max(x_[l], 0.5 * model_.params().plate_mass_kg * kGravity);
  // While the load cannot be seen (a flat cell) its variance would grow without bound.
  const double cap = std::pow(3.0 * params_.initial_load_sd_n, 2);
  if (p_(l, l) > cap) {
    const double f = std::sqrt(cap / p_(l, l));
    p_.row(l) *= f;
    p_.col(l) *= f;
  }
}

void CellObserver::checkReanchor(const ObserverReadings& readings) {
  const bool flat = applied_.vent_opening >= 0.5 && applied_.vent_back_pressure_pa == 0.0 &&
                    std::fabs(readings.gauge_pressure_pa) < params_.reanchor_pressure_pa;
  if (!flat) {
    flat_since_s_ = -1.0;
    return;
  }
  if (flat_since_s_ < 0.0) flat_since_s_ = time_;
  if (time_ - flat_since_s_ + 1e-9 >= params_.reanchor_time_s) {
    anchorFlat();
    flat_since_s_ = time_;
  }
}

void CellObserver::anchorFlat() {
  // The flat cell holds ambient air in its rest volume: mass and energy are known again.
  const int l = loadIndex();
  model_.reset(x_[l]);
  const CellModel::StateVector flat = model_.state();
  for (int i = 0; i < l; ++i) {
    if (i == CellModel::kRegulator) continue;
    x_[i] = flat[i];
    p_.row(i).setZero();
    p_.col(i).setZero();
    p_(i, i) = std::pow(1e-4 * scale_[i], 2);
  }
  ++reanchors_;
  refresh();
}

CellEstimate CellObserver::estimate() const {
  CellEstimate e;
  const int l = loadIndex();
  e.height_m = x_[CellModel::kHeight];
  e.height_sd_m = std::sqrt(std::max(0.0, p_(CellModel::kHeight, CellModel::kHeight)));
  e.velocity_m_s = x_[CellModel::kVelocity];
  e.mass_kg = x_[CellModel::kMass];
  e.mass_sd_kg = std::sqrt(std::max(0.0, p_(CellModel::kMass, CellModel::kMass)));
  e.load_n = x_[l];
  e.load_sd_n = std::sqrt(std::max(0.0, p_(l, l)));
  e.gauge_pressure_pa = vars_.gauge_pressure_pa;
  e.temperature_k = vars_.temperature_k;
  e.volume_m3 = vars_.structure.volume_m3;
  e.reanchors = reanchors_;
  return e;
}

void ObserverErrorStats::add(double error_m) {
  sum_sq_m2 += error_m * error_m;
  max_abs_m = std::max(max_abs_m, std::fabs(error_m));
  ++samples;
}

double ObserverErrorStats::rmsM() const { return samples > 0 ? std::sqrt(sum_sq_m2 / samples) : 0.0; }

}  // namespace nursing_bed
