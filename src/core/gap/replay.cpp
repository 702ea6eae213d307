#include "nursing_bed/core/gap/replay.h"

#include "nursing_bed/core/gap/distortions.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <stdexcept>
#include <tuple>

namespace nursing_bed {
namespace {
/// Over kInitialRestS a plate at rest moves less than this (sensor noise ~0.3 mm averages out).
constexpr double kMovingPlateM = 0.001;
/// Over kInitialRestS a steady pressure's two half means differ by less than this (20 Pa noise
/// averages out); a run starting on a rising setpoint ramp differs by far more.
constexpr double kMovingPressurePa = 50.0;
/// A run without height readings starts at rest at its first pressure when that is above this
/// (a ventilated lung at PEEP); a flat cell's pressure is noise around 0 (5 sd of 30 Pa).
constexpr double kRestingPressureMinPa = 150.0;
/// A vent whose flow and pressure stay at zero within the noise this long has emptied the cell.
constexpr double kEmptiedWindowS = 0.5;

/// The pressure a run starts from: the mean over the first kInitialRestS while steady, else the
/// first reading; NaN when none is measured there.
double initialPressure(const RunData& run) {
  std::vector<double> p;
  for (std::size_t i = 0; i < run.size() && run.t_s[i] <= run.t_s[0] + kInitialRestS; ++i)
    if (std::isfinite(run.p_gauge_pa[i])) p.push_back(run.p_gauge_pa[i]);
  if (p.empty()) return NAN;
  const std::size_t half = p.size() / 2;
  if (half == 0) return p[0];
  const double first_half = std::accumulate(p.begin(), p.begin() + half, 0.0) / half;
  const double second_half = std::accumulate(p.begin() + half, p.end(), 0.0) / (p.size() - half);
  if (std::fabs(second_half - first_half) > kMovingPressurePa) return p[0];
  return std::accumulate(p.begin(), p.end(), 0.0) / p.size();
}

/// The structure's equilibrium at the first pressure (NaN: start flat; a spring-loaded chamber
/// at a low resting pressure holds it a few mm up: not landed).
double startHeightFromPressure(const RunData& run, const CellStructure& structure, double load_n) {
  const double p0 = initialPressure(run);
  if (!(p0 > kRestingPressureMinPa)) return NAN;
  const StructureEquilibrium eq = structure.equilibriumAtPressure(p0, load_n);
  return eq.converged && eq.height_m > 0.0 ? eq.height_m : NAN;
}

/// The height to start a replay at rest from (NaN: start flat): the measured one above
/// kLandedHeightM, or without height readings the pressure's (startHeightFromPressure()).
double startHeight(const RunData& run, const CellStructure& structure, double load_n) {
  const InitialHeight h0 = initialHeight(run);
  if (h0.samples > 0) return h0.h_m > kLandedHeightM ? h0.h_m : NAN;
  return startHeightFromPressure(run, structure, load_n);
}
/// Whether the finite samples of x in [begin, end) (at least 10) have a mean within 3 standard
/// errors of zero.
bool zeroMeanWithinNoise(const std::vector<double>& x, std::size_t begin, std::size_t end) {
  double sum = 0.0, sum2 = 0.0;
  int count = 0;
  for (std::size_t k = begin; k < end; ++k)
    if (std::isfinite(x[k])) {
      sum += x[k];
      sum2 += x[k] * x[k];
      ++count;
    }
  if (count < 10) return false;
  const double mean = sum / count, var = std::max(0.0, (sum2 - count * mean * mean) / (count - 1));
  return std::fabs(mean) <= 3.0 * std::sqrt(var / count);
}

/// Without height readings, where the plate has landed in the vent: from the first vent sample
/// after which, for kEmptiedWindowS, both the metered flow and the gauge pressure are zero
/// within the noise. A floating plate's load keeps the gas above ambient, and gas leaves; once
/// it rests on the bed neither holds, and the meter's noise would be replayed out of the few mL
/// left. n when the run has height readings, no metered flow, or never empties.
std::size_t emptiedFrom(const RunData& run, std::size_t vent_start) {
  const std::size_t n = run.size();
  const bool metered =
      std::any_of(run.mdot_in_kg_s.begin(), run.mdot_in_kg_s.end(), [](double q) { return std::isfinite(q); });
  const bool has_height = std::any_of(run.h_m.begin(), run.h_m.end(), [](double h) { return std::isfinite(h); });
  if (!metered || has_height) return n;
  for (std::size_t i = vent_start, end = vent_start; i < n; ++i) {
    while (end < n && run.t_s[end] < run.t_s[i] + kEmptiedWindowS) ++end;
    if (zeroMeanWithinNoise(run.mdot_in_kg_s, i, end) && zeroMeanWithinNoise(run.p_gauge_pa, i, end)) return i;
  }
  return n;
}
}  // namespace

const char* phaseName(RunPhase phase) {
  switch (phase) {
    case RunPhase::kDeploy: return "deploy";
    case RunPhase::kPressurize: return "pressurize";
    case RunPhase::kHold: return "hold";
    case RunPhase::kVent: return "vent";
    case RunPhase::kLanded: return "landed";
  }
  return "?";
}

bool runIsValveDriven(const RunData& run) {
  auto measured = [](const std::vector<double>& v) {
    return std::any_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
  };
  return !measured(run.mdot_in_kg_s) && run.valve_cmd.size() == run.size() && measured(run.valve_cmd) &&
         run.p_supply_gauge_pa.size() == run.size() && measured(run.p_supply_gauge_pa);
}

std::vector<RunPhase> classifyPhases(const RunData& run) {
  const std::size_t n = run.size();
  std::vector<RunPhase> phases(n, RunPhase::kHold);
  // Without a flow meter the valve command says when gas goes in or out.
  const std::vector<double>& flow = runIsValveDriven(run) ? run.valve_cmd : run.mdot_in_kg_s;
  double peak_flow = 0.0;
  for (double q : flow)
    if (std::isfinite(q)) peak_flow = std::max(peak_flow, std::fabs(q));
  const double threshold = 0.02 * peak_flow;
  // Inflation: from the start to the last sample with clear inflow before the first vent.
  std::size_t vent_start = n;
  for (std::size_t i = 0; i < n; ++i)
    if (flow[i] < -threshold) {
      vent_start = i;
      break;
    }
  std::size_t inflate_end = 0;
  for (std::size_t i = 0; i < vent_start; ++i)
    if (flow[i] > threshold) inflate_end = i + 1;
  double peak_p = 0.0;
  for (std::size_t i = 0; i < inflate_end; ++i)
    if (std::isfinite(run.p_gauge_pa[i])) peak_p = std::max(peak_p, run.p_gauge_pa[i]);
  const std::size_t landed_from = emptiedFrom(run, vent_start);
  bool landed = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (i < inflate_end) {
      phases[i] = run.p_gauge_pa[i] < 0.25 * peak_p ? RunPhase::kDeploy : RunPhase::kPressurize;
    } else if (i >= vent_start) {
      landed = landed || (std::isfinite(run.h_m[i]) && run.h_m[i] < kLandedHeightM) || i >= landed_from;
      phases[i] = landed ? RunPhase::kLanded : RunPhase::kVent;
    }
  }
  return phases;
}

bool distortionsMoveTheStart(const RunData& run, const std::vector<CellEffectPtr>& effects) {
  RunData head;  // the readings the start is taken from
  for (std::size_t i = 0; i < run.size() && run.t_s[i] <= run.t_s[0] + kInitialRestS; ++i) {
    head.t_s.push_back(run.t_s[i]);
    head.h_m.push_back(i < run.h_m.size() ? run.h_m[i] : NAN);
  }
  const InitialHeight read = initialHeight(head);
  if (!undoHeightReadingDistortions(effects, head.t_s, head.h_m, &head.h_m)) return false;
  const InitialHeight truth = initialHeight(head);
  const bool flat_read = !(read.h_m > kLandedHeightM), flat_truth = !(truth.h_m > kLandedHeightM);
  return !(flat_read && flat_truth) && read.h_m != truth.h_m;
}

InitialHeight initialHeight(const RunData& run) {
  std::vector<double> h;
  for (std::size_t i = 0; i < run.size() && run.t_s[i] <= run.t_s[0] + kInitialRestS; ++i)
    if (std::isfinite(run.h_m[i])) h.push_back(run.h_m[i]);
  if (h.empty()) return {NAN, 0};
  // A plate that is already moving is not at rest: then the first reading alone.
  const std::size_t half = h.size() / 2;
  const double first_half = std::accumulate(h.begin(), h.begin() + half, 0.0) / std::max<std::size_t>(half, 1);
  const double second_half = std::accumulate(h.begin() + half, h.end(), 0.0) / (h.size() - half);
  if (half == 0 || std::fabs(second_half - first_half) > kMovingPlateM) return {h[0], 1};
  return {std::accumulate(h.begin(), h.end(), 0.0) / h.size(), static_cast<int>(h.size())};
}

namespace {

/// Advances `model` over one interval of `dt` with `in`; an interval-mean inflow or vent opening
/// is spread over it, or (IntervalShape) concentrated into a pulse at its start or end with
/// `duty` (0..1] the share of the interval the valve was open.
void advanceInterval(CellModel* model, double dt, const CellInputs& in, IntervalShape shape, double duty) {
  const bool pulsed = shape != IntervalShape::kSpread && duty > 0.0 && duty < 1.0 &&
                      ((std::isfinite(in.prescribed_inflow_kg_s) && in.prescribed_inflow_kg_s != 0.0) ||
                       in.inlet_opening > 0.0 || in.vent_opening > 0.0);
  if (!pulsed) {
    model->advance(dt, in);
    return;
  }
  CellInputs open = in, shut = in;
  if (std::isfinite(in.prescribed_inflow_kg_s)) {
    open.prescribed_inflow_kg_s = in.prescribed_inflow_kg_s / duty;
    shut.prescribed_inflow_kg_s = 0.0;
  }
  // A valve-driven run (no flow meter) opens the model's own valves fully for the pulse.
  open.inlet_opening = in.inlet_opening > 0.0 ? 1.0 : 0.0;
  open.vent_opening = in.vent_opening > 0.0 ? 1.0 : 0.0;
  shut.inlet_opening = 0.0;
  shut.vent_opening = 0.0;
  const bool at_start = shape == IntervalShape::kPulseAtStart;
  model->advance((at_start ? duty : 1.0 - duty) * dt, at_start ? open : shut);
  model->advance((at_start ? 1.0 - duty : duty) * dt, at_start ? shut : open);
}

/// The share of interval i its valve was open: the mean opening the run reports (valve_cmd), 0.5
/// without one.
double valveDuty(const RunData& run, std::size_t i) {
  if (run.valve_cmd.size() != run.size() || !std::isfinite(run.valve_cmd[i])) return 0.5;
  return std::min(1.0, std::fabs(run.valve_cmd[i]));
}

/// A run without a flow meter drives the model's own valves: valve_cmd[i] is the mean opening
/// over the interval ending at sample i (+ inlet from the supply, - vent to ambient).
void valveInputs(const RunData& run, std::size_t i, CellInputs* in) {
  const double cmd = std::isfinite(run.valve_cmd[i]) ? run.valve_cmd[i] : 0.0;
  in->prescribed_inflow = nullptr;
  in->prescribed_inflow_kg_s = NAN;
  in->inlet_closed = false;
  in->inlet_opening = std::clamp(cmd, 0.0, 1.0);
  in->vent_opening = std::clamp(-cmd, 0.0, 1.0);
  const double supply = run.p_supply_gauge_pa[i];
  in->supply_pressure_pa = std::isfinite(supply) ? supply : in->supply_pressure_pa;
}

}  // namespace

namespace {

/// The samples after a replay's last simulated one (the plate landed in the vent, which goes on
/// emptying the cell) read flat and at ambient.
void flatAfterLanding(Replay* rep) {
  std::size_t last = rep->h_m.size();
  while (last > 0 && !(std::isfinite(rep->h_m[last - 1]) && std::isfinite(rep->p_gauge_pa[last - 1]))) --last;
  if (last == 0) return;
  std::fill(rep->h_m.begin() + last, rep->h_m.end(), 0.0);
  std::fill(rep->p_gauge_pa.begin() + last, rep->p_gauge_pa.end(), 0.0);
}

/// `run` through the model; its start and phases (where the plate landed) from `start_readings`
/// (the run's readings, or those a true height sensor would give: undoHeightReadingDistortions()).
Replay replayThroughModel(const RunData& run, const RunData& start_readings, const CellParams& params,
                          const std::vector<CellEffectPtr>& effects, long max_substeps, IntervalShape shape,
                          ReplayStart start) {
  Replay out;
  out.phases = classifyPhases(start_readings);
  const std::size_t n = run.size();
  out.p_gauge_pa.assign(n, NAN);
  out.h_m.assign(n, NAN);
  try {
    const bool valve_driven = runIsValveDriven(run);
    std::vector<double> t{run.t_s.front(), run.t_s.back()}, q{0.0, 0.0};
    if (!valve_driven) {
      t.clear();
      q.clear();
      for (std::size_t i = 0; i < n; ++i)
        if (std::isfinite(run.mdot_in_kg_s[i])) {
          t.push_back(run.t_s[i]);
          q.push_back(run.mdot_in_kg_s[i]);
        }
    }
    if (t.size() < 2) throw std::invalid_argument("fewer than 2 inflow samples");
    const TimeSeries inflow(t, q);
    CellModel model(params);
    for (const auto& e : effects) model.addEffect(e);
    const double load0 = run.loadAt(0);
    // At rest at the first measured height (or, without height readings, at the first measured
    // pressure), with the measured gas temperature if there is one.
    const double t_gas0 = run.t_gas_k.size() == n && run.t_gas_k[0] > 0.0 ? run.t_gas_k[0] : NAN;
    const double h_start = start == ReplayStart::kNotHeight
                               ? startHeightFromPressure(start_readings, model.structure(), load0)
                               : startHeight(start_readings, model.structure(), load0);
    if (std::isfinite(h_start)) model.resetToEquilibrium(h_start, load0, t_gas0);
    else model.reset(load0);
    // Model time starts at the run's first sample.
    model.setState(run.t_s[0], model.state());
    CellInputs in;
    in.prescribed_inflow = &inflow;
    const bool vent_valve = ventsThroughUnmeteredValve(run);
    // A default budget that only a runaway (a model pushed far from the data) exhausts.
    const double duration = run.t_s.back() - run.t_s.front();
    model.setSubstepBudget(max_substeps > 0 ? max_substeps
                                            : static_cast<long>(50.0 * duration / params.time_step_s) + 10000);
    for (std::size_t i = 0; i < n; ++i) {
      // After the plate has landed in the vent the few mL left make the replay ill-conditioned
      // (and a metered outflow may exceed what is left): not simulated, left NaN.
      if (out.phases[i] == RunPhase::kLanded) break;
      if (i > 0) {
        in.load_n = run.loadAt(i - 1);
        in.inlet_closed = run.inlet_closed.size() == n && run.inlet_closed[i - 1] && run.inlet_closed[i];
        // A bed's cell vents through its own valve, which the inlet's meter does not see.
        // valve_cmd at a sample is taken as the (mean) opening over the interval ending there, as
        // the bed's AirbagState reports it.
        in.vent_opening = vent_valve && run.valve_cmd[i] < 0.0 ? std::min(1.0, -run.valve_cmd[i]) : 0.0;
        // Interval means: the interval's own mean flow, constant over it (a missing sample
        // falls back to the interpolated series).
        const bool interval_mean = run.flow_interval_means && std::isfinite(run.mdot_in_kg_s[i]);
        in.prescribed_inflow = interval_mean ? nullptr : &inflow;
        in.prescribed_inflow_kg_s = interval_mean ? run.mdot_in_kg_s[i] : NAN;
        if (valve_driven) valveInputs(run, i, &in);
        const double dt = run.t_s[i] - run.t_s[i - 1];
        if (interval_mean || valve_driven) advanceInterval(&model, dt, in, shape, valveDuty(run, i));
        else model.advance(dt, in);
      }
      const Readings m = model.measure();
      out.p_gauge_pa[i] = m.gauge_pressure_pa;
      out.h_m[i] = m.height_m;
    }
    out.substeps = model.substeps();
  } catch (const std::exception& e) {
    out.ok = false;
    out.message = run.name + ": replay failed: " + e.what();
  }
  return out;
}

}  // namespace

Replay replayRun(const RunData& run, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                 long max_substeps, IntervalShape shape) {
  return replayRun(run, params, effects, max_substeps, shape,
                   readsHeightEarly(effects) ? ReplayStart::kNotHeight : ReplayStart::kReadings);
}

Replay replayRun(const RunData& run, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                 long max_substeps, IntervalShape shape, ReplayStart start) {
  // Channel distortions (distortions.h) act on the inputs before and on the readings after the
  // model; in the model they add nothing.
  const bool inputs = std::any_of(effects.begin(), effects.end(), [](const CellEffectPtr& e) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    return d && !d->outputSide();
  });
  RunData corrected;
  if (inputs) applyInputDistortions(effects, &(corrected = run));
  const RunData& driven = inputs ? corrected : run;
  // The start at rest where the plate was, not where a distorted height sensor put it.
  std::vector<double> true_h;
  const bool undone = undoHeightReadingDistortions(effects, run.t_s, run.h_m, &true_h);
  RunData start_readings;
  if (undone) {
    start_readings = driven;
    start_readings.h_m = std::move(true_h);
  }
  Replay out =
      replayThroughModel(driven, undone ? start_readings : driven, params, effects, max_substeps, shape, start);
  // Landed in truth where the distorted readings never show it.
  if (undone) flatAfterLanding(&out);
  applyOutputDistortions(effects, run.t_s, &out.p_gauge_pa, &out.h_m);
  return out;
}

namespace {

/// Robust sd of white noise from second differences d: 1.4826 MAD / sqrt(6).
double noiseOfSecondDifferences(std::vector<double> d) {
  if (d.empty()) return 0.0;
  for (double& v : d) v = std::fabs(v);
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return 1.4826 * d[d.size() / 2] / std::sqrt(6.0);
}

/// A local estimate of the meter's noise needs this many steady samples near.
constexpr std::size_t kMinSteadySamples = 5;

/// The sd of a reading's rounding to its quantisationStep(): uniform over one step.
double quantisationNoise(const std::vector<double>& x) { return quantisationStep(x) / std::sqrt(12.0); }

}  // namespace

double quantisationStep(const std::vector<double>& x) {
  constexpr double kOnLattice = 0.9;   // share of the changes that are whole steps
  constexpr double kTolerance = 0.01;  // of a step: a printed decimal's float error is far below
  double scale = 0.0;
  for (double v : x)
    if (std::isfinite(v)) scale = std::max(scale, std::fabs(v));
  std::vector<double> d;
  for (std::size_t i = 1; i < x.size(); ++i) {
    const double v = std::fabs(x[i] - x[i - 1]);
    if (std::isfinite(v) && v > 1e-9 * scale) d.push_back(v);  // below: the float's own rounding
  }
  if (d.size() < 10) return 0.0;
  const double q = *std::min_element(d.begin(), d.end());
  const auto whole = std::count_if(d.begin(), d.end(), [q](double v) {
    const double k = v / q;
    return std::fabs(k - std::round(k)) <= kTolerance;
  });
  return static_cast<double>(whole) >= kOnLattice * static_cast<double>(d.size()) ? q : 0.0;
}

double estimateNoise(const std::vector<double>& x) {
  std::vector<double> d;
  for (std::size_t i = 1; i + 1 < x.size(); ++i) {
    const double v = x[i + 1] - 2.0 * x[i] + x[i - 1];
    if (std::isfinite(v)) d.push_back(v);
  }
  return std::max(noiseOfSecondDifferences(d), quantisationNoise(x));
}

std::vector<double> meterNoise(const RunData& run, const std::vector<double>& flow, std::size_t w) {
  const std::size_t n = flow.size();
  if (n < 3) return std::vector<double>(n, 0.0);  // no second difference
  const bool has_valve = run.valve_cmd.size() == n;
  std::vector<double> d(n, NAN);  // second difference at i where the valve held still
  std::vector<double> steady;
  for (std::size_t i = 1; i + 1 < n; ++i) {
    const bool still = !has_valve || (std::isfinite(run.valve_cmd[i]) && run.valve_cmd[i - 1] == run.valve_cmd[i] &&
                                      run.valve_cmd[i + 1] == run.valve_cmd[i]);
    const double v = flow[i + 1] - 2.0 * flow[i] + flow[i - 1];
    if (still && std::isfinite(v)) {
      d[i] = v;
      steady.push_back(v);
    }
  }
  // No steady sample at all (a valve that never held still): every sample, as without valve_cmd.
  if (steady.empty()) {
    for (std::size_t i = 1; i + 1 < n; ++i) d[i] = flow[i + 1] - 2.0 * flow[i] + flow[i - 1];
    steady.assign(d.begin() + 1, d.end() - 1);
    steady.erase(std::remove_if(steady.begin(), steady.end(), [](double v) { return !std::isfinite(v); }),
                 steady.end());
  }
  const double rounding = quantisationNoise(flow);
  const double whole_run = std::max(noiseOfSecondDifferences(steady), rounding);
  std::vector<double> out(n, whole_run);
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<double> near;
    for (std::size_t k = i > w ? i - w : 0; k < std::min(n, i + w + 1); ++k)
      if (std::isfinite(d[k])) near.push_back(d[k]);
    if (near.size() >= kMinSteadySamples) out[i] = std::max(noiseOfSecondDifferences(near), rounding);
  }
  return out;
}

namespace {

/// Mean and standard error of the finite flow samples in [begin, end).
bool flowMean(const RunData& run, std::size_t begin, std::size_t end, double* mean, double* standard_error) {
  double sum = 0.0, sum2 = 0.0;
  int count = 0;
  for (std::size_t k = begin; k < end; ++k)
    if (std::isfinite(run.mdot_in_kg_s[k])) {
      sum += run.mdot_in_kg_s[k];
      sum2 += run.mdot_in_kg_s[k] * run.mdot_in_kg_s[k];
      ++count;
    }
  if (count < 10) return false;
  *mean = sum / count;
  const double var = std::max(0.0, (sum2 - count * *mean * *mean) / (count - 1));
  *standard_error = std::sqrt(var / count);
  return true;
}

/// Whether the flow in [begin, end) is consistent with zero (within 3 standard errors).
bool zeroWithinNoise(const RunData& run, std::size_t begin, std::size_t end) {
  double mean = 0.0, se = 0.0;
  return flowMean(run, begin, end, &mean, &se) && std::fabs(mean) <= 3.0 * se;
}

}  // namespace

bool ventsThroughUnmeteredValve(const RunData& run) {
  const std::size_t n = run.size();
  if (run.valve_cmd.size() != n) return false;
  // Venting intervals whose predecessor vented too (a lagging meter carries the inflow into a
  // vent's first interval); a controller that vents in single pulses: every venting interval.
  auto venting = [&](bool after_vent) {
    std::vector<std::size_t> idx;
    for (std::size_t i = 1; i < n; ++i)
      if (run.valve_cmd[i] < 0.0 && (!after_vent || run.valve_cmd[i - 1] < 0.0) && std::isfinite(run.mdot_in_kg_s[i]))
        idx.push_back(i);
    return idx;
  };
  std::vector<std::size_t> idx = venting(true);
  if (idx.size() < 5) idx = venting(false);
  if (idx.empty()) return false;
  // Venting through the metered inlet reads a clearly negative flow, in proportion to the vent's
  // opening: beyond 1 % of the peak inflow per unit of mean opening and beyond the meter's noise.
  double flow = 0.0, opening = 0.0;
  for (std::size_t i : idx) {
    flow += run.mdot_in_kg_s[i];
    opening += -run.valve_cmd[i];
  }
  double inflow_peak = 0.0;
  for (double x : run.mdot_in_kg_s)
    if (std::isfinite(x)) inflow_peak = std::max(inflow_peak, x);
  const double noise = 3.0 * estimateNoise(run.mdot_in_kg_s) * std::sqrt(static_cast<double>(idx.size()));
  return flow > -std::max(0.01 * inflow_peak * opening, noise);
}

int zeroClosedInletFlow(RunData* run) {
  const std::size_t n = run->size();
  // Closed stretches: from the valve command where recorded, else the hold phase trimmed of
  // half-second chunks at its ends whose flow is not yet zero within the noise (the tail of the
  // inflow, the start of the vent).
  std::vector<std::pair<std::size_t, std::size_t>> stretches;
  bool have_valve = run->valve_cmd.size() == n;
  for (std::size_t i = 0; have_valve && i < n; ++i) have_valve = std::isfinite(run->valve_cmd[i]);
  if (have_valve) {
    for (std::size_t i = 0; i < n;) {
      if (run->valve_cmd[i] != 0.0) {
        ++i;
        continue;
      }
      std::size_t end = i;
      while (end < n && run->valve_cmd[end] == 0.0) ++end;
      // The first closed sample may still carry flow of the interval before it (a meter that
      // reports the mean since its last sample).
      stretches.emplace_back(i + 1, end);
      i = end;
    }
  } else {
    const std::vector<RunPhase> phases = classifyPhases(*run);
    for (std::size_t i = 0; i < n;) {
      if (phases[i] != RunPhase::kHold) {
        ++i;
        continue;
      }
      std::size_t begin = i, end = i;
      while (end < n && phases[end] == RunPhase::kHold) ++end;
      i = end;
      auto chunkEnd = [&](std::size_t from) {
        std::size_t k = from;
        while (k < end && run->t_s[k] < run->t_s[from] + 0.5) ++k;
        return k;
      };
      while (begin < end && !zeroWithinNoise(*run, begin, chunkEnd(begin))) begin = chunkEnd(begin);
      auto chunkBegin = [&](std::size_t to) {
        std::size_t k = to;
        while (k > begin && run->t_s[k - 1] > run->t_s[to - 1] - 0.5) --k;
        return k;
      };
      while (end > begin && !zeroWithinNoise(*run, chunkBegin(end), end)) end = chunkBegin(end);
      if (end > begin) stretches.emplace_back(begin, end);
    }
  }
  int zeroed = 0;
  for (const auto& [begin, end] : stretches) {
    if (!zeroWithinNoise(*run, begin, end)) continue;  // a meter offset: keep it, it is a finding
    if (run->inlet_closed.size() != n) run->inlet_closed.assign(n, false);
    for (std::size_t k = begin; k < end; ++k) {
      run->inlet_closed[k] = true;
      if (std::isfinite(run->mdot_in_kg_s[k]) && run->mdot_in_kg_s[k] != 0.0) {
        run->mdot_in_kg_s[k] = 0.0;
        ++zeroed;
      }
    }
  }
  return zeroed;
}

RunResidual pooledResidual(const std::vector<const RunData*>& runs, const std::vector<const Replay*>& replays) {
  if (runs.size() != replays.size()) throw std::invalid_argument("pooledResidual: runs and replays differ in number");
  RunResidual r;
  double p_lo = INFINITY, p_hi = -INFINITY, h_lo = INFINITY, h_hi = -INFINITY, sp = 0.0, sh = 0.0;
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const RunData& run = *runs[k];
    const Replay& replay = *replays[k];
    for (std::size_t i = 0; i < run.size(); ++i) {
      if (replay.phases[i] == RunPhase::kLanded) continue;
      const double p = run.p_gauge_pa[i], h = run.h_m[i];
      if (!std::isfinite(p)) continue;
      p_lo = std::min(p_lo, p);
      p_hi = std::max(p_hi, p);
      sp += std::pow(p - replay.p_gauge_pa[i], 2);
      ++r.samples;
      if (!std::isfinite(h)) continue;  // no height sensor: pressure alone
      h_lo = std::min(h_lo, h);
      h_hi = std::max(h_hi, h);
      sh += std::pow(h - replay.h_m[i], 2);
      ++r.samples_h;
    }
  }
  if (r.samples == 0) return r;
  r.range_p_pa = std::max(p_hi - p_lo, 1e-9);
  r.range_h_m = std::max(h_hi - h_lo, 1e-12);
  r.nrmse_p = std::sqrt(sp / r.samples) / r.range_p_pa;
  r.nrmse_h = r.samples_h > 0 ? std::sqrt(sh / r.samples_h) / r.range_h_m : NAN;
  return r;
}

RunResidual runResidual(const RunData& run, const Replay& replay) { return pooledResidual({&run}, {&replay}); }

std::vector<GapShare> localizeGap(const std::vector<RunData>& runs, const std::vector<Replay>& replays) {
  if (runs.size() != replays.size()) throw std::invalid_argument("localizeGap: runs and replays differ in number");
  using Key = std::tuple<std::string, std::string, double>;
  std::map<Key, GapShare> cells;
  double total = 0.0;
  // One range per signal over all runs (a run whose own range is the size of the noise, like a
  // plate-only run's pressure, would otherwise weigh its noise as much as another run's gap).
  std::vector<const RunData*> all_runs;
  std::vector<const Replay*> all_replays;
  for (std::size_t k = 0; k < runs.size(); ++k)
    if (replays[k].ok) {
      all_runs.push_back(&runs[k]);
      all_replays.push_back(&replays[k]);
    }
  const RunResidual range = pooledResidual(all_runs, all_replays);
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const RunData& run = runs[k];
    const Replay& rep = replays[k];
    if (!rep.ok || range.samples == 0) continue;
    for (std::size_t i = 0; i < run.size(); ++i) {
      if (rep.phases[i] == RunPhase::kLanded) continue;
      const double ep = (run.p_gauge_pa[i] - rep.p_gauge_pa[i]) / range.range_p_pa;
      const double eh = (run.h_m[i] - rep.h_m[i]) / range.range_h_m;
      for (int s = 0; s < 2; ++s) {
        const double e2 = s == 0 ? ep * ep : eh * eh;
        if (!std::isfinite(e2)) continue;
        const Key key{s == 0 ? "pressure" : "height", phaseName(rep.phases[i]),
                      std::round(run.loadAt(i) * 10.0) / 10.0};
        auto [it, fresh] = cells.try_emplace(key);
        GapShare& g = it->second;
        if (fresh) {
          g.signal = std::get<0>(key);
          g.phase = std::get<1>(key);
          g.load_n = std::get<2>(key);
          g.t_start_s = run.t_s[i];
          g.t_end_s = run.t_s[i];
        }
        g.share += e2;
        g.t_start_s = std::min(g.t_start_s, run.t_s[i]);
        g.t_end_s = std::max(g.t_end_s, run.t_s[i]);
        total += e2;
      }
    }
  }
  std::vector<GapShare> out;
  for (auto& kv : cells) {
    kv.second.share = total > 0.0 ? kv.second.share / total : 0.0;
    out.push_back(kv.second);
  }
  std::sort(out.begin(), out.end(), [](const GapShare& a, const GapShare& b) { return a.share > b.share; });
  return out;
}

}  // namespace nursing_bed
