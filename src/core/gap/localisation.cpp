#include "nursing_bed/core/gap/localisation.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <type_traits>

namespace nursing_bed {
namespace {

/// A setpoint rises into a new cycle where it crosses this share of its range above its lowest.
constexpr double kCycleEdgeShare = 0.05;
/// A window needs this many samples after its anchor to say anything.
constexpr std::size_t kMinWindowSamples = 3;

/// Samples i0..i1 (inclusive) of `run` as a run of their own: every per-sample column cut.
RunData sliceRun(const RunData& run, std::size_t i0, std::size_t i1) {
  RunData out = run;
  const std::size_t n = run.size();
  auto cut = [&](auto* v) {
    if (v->size() == n) *v = std::decay_t<decltype(*v)>(v->begin() + i0, v->begin() + i1 + 1);
  };
  for (std::vector<double>* v :
       {&out.t_s, &out.mdot_in_kg_s, &out.p_gauge_pa, &out.h_m, &out.load_n_series, &out.valve_cmd,
        &out.p_supply_gauge_pa, &out.t_gas_k, &out.mdot_uncorrected_kg_s, &out.p_setpoint_gauge_pa})
    cut(v);
  cut(&out.inlet_closed);
  return out;
}

/// RMS of (measured - replayed) / noise over the samples after the anchor (NaN: none finite).
double windowRms(const std::vector<double>& measured, const std::vector<double>& replayed, double noise) {
  double sum = 0.0;
  int count = 0;
  for (std::size_t i = 1; i < measured.size() && i < replayed.size(); ++i) {
    const double z = (measured[i] - replayed[i]) / noise;
    if (!std::isfinite(z)) continue;
    sum += z * z;
    ++count;
  }
  return count > 0 ? std::sqrt(sum / count) : NAN;
}

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

/// The smaller of a whole-run noise estimate and the median of the windows' own (0 where
/// nothing is measured).
double quietest(double whole_run, const std::vector<double>& local) {
  std::vector<double> measured;
  for (double x : local)
    if (x > 0.0) measured.push_back(x);
  const double m = median(measured);
  if (!(whole_run > 0.0)) return std::isfinite(m) ? m : 0.0;
  return std::isfinite(m) ? std::min(whole_run, m) : whole_run;
}

/// The windows' floor per slot of the cycle: the median over the cycles of their RMS (at least
/// one noise floor); one noise floor everywhere with fewer than min_cycles cycles.
std::map<int, double> slotFloors(const std::vector<AnchoredWindow>& windows, bool pressure,
                                 const LocalisationOptions& options) {
  std::map<int, std::vector<double>> by_slot;
  int first_cycle = 0, last_cycle = 0;
  for (const AnchoredWindow& w : windows) {
    by_slot[w.slot].push_back(pressure ? w.rms_p : w.rms_h);
    first_cycle = std::min(first_cycle, w.cycle);
    last_cycle = std::max(last_cycle, w.cycle);
  }
  std::map<int, double> floors;
  const bool cyclic = last_cycle - first_cycle + 1 >= options.min_cycles;
  for (const auto& [slot, values] : by_slot) {
    const double m = median(values);
    floors[slot] = cyclic && std::isfinite(m) ? std::max(1.0, m) : 1.0;
  }
  return floors;
}

}  // namespace

std::string LocalisationOptions::validate() const {
  if (!(window_s > 0.0)) return "window_s must be positive";
  if (!(floor_ratio >= 1.0)) return "floor_ratio must be at least 1";
  if (!(min_rms > 0.0)) return "min_rms must be positive";
  if (!(merge_gap_s >= 0.0)) return "merge_gap_s must not be negative";
  if (min_cycles < 2) return "min_cycles must be at least 2";
  return "";
}

std::vector<double> cycleStarts(const RunData& run) {
  std::vector<double> starts;
  if (run.size() == 0) return starts;
  const std::vector<double>& sp = run.p_setpoint_gauge_pa;
  double lo = INFINITY, hi = -INFINITY;
  if (sp.size() == run.size())
    for (double x : sp)
      if (std::isfinite(x)) {
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
  if (!(hi > lo)) return {run.t_s.front()};
  const double edge = lo + kCycleEdgeShare * (hi - lo);
  for (std::size_t i = 1; i < sp.size(); ++i)
    if (sp[i - 1] <= edge && sp[i] > edge) starts.push_back(run.t_s[i]);
  if (starts.empty() || starts.front() > run.t_s.front()) starts.insert(starts.begin(), run.t_s.front());
  return starts;
}

std::vector<AnchoredWindow> anchoredWindows(const RunData& run, const CellParams& params,
                                            const std::vector<CellEffectPtr>& effects, double noise_p_pa,
                                            double noise_h_m, const LocalisationOptions& options) {
  const std::string problem = options.validate();
  if (!problem.empty()) throw std::invalid_argument("localisation options: " + problem);
  std::vector<AnchoredWindow> windows;
  std::vector<double> local_p, local_h;
  const std::vector<double> starts = cycleStarts(run);
  const std::size_t n = run.size();
  std::size_t i = 0;
  for (std::size_t c = 0; c < starts.size(); ++c) {
    const double cycle_end = c + 1 < starts.size() ? starts[c + 1] : run.t_s.back() + 1e-9;
    for (int slot = 0;; ++slot) {
      const double ws = starts[c] + slot * options.window_s;
      if (ws >= cycle_end) break;
      const double we = std::min(ws + options.window_s, cycle_end);
      while (i < n && run.t_s[i] < ws) ++i;
      std::size_t j = i;
      while (j + 1 < n && run.t_s[j + 1] <= we) ++j;
      if (j < i + kMinWindowSamples) continue;
      AnchoredWindow w;
      w.t_start_s = run.t_s[i];
      w.t_end_s = run.t_s[j];
      w.cycle = static_cast<int>(c);
      w.slot = slot;
      const RunData part = sliceRun(run, i, j);
      const Replay rep = replayRun(part, params, effects);
      w.rms_p = rep.ok ? windowRms(part.p_gauge_pa, rep.p_gauge_pa, 1.0) : NAN;
      w.rms_h = rep.ok ? windowRms(part.h_m, rep.h_m, 1.0) : NAN;
      local_p.push_back(estimateNoise(part.p_gauge_pa));
      local_h.push_back(estimateNoise(part.h_m));
      windows.push_back(w);
    }
  }
  // A fault that rings over part of the run inflates a whole-run noise estimate: the floor is
  // at most the median of the windows' own estimates.
  const double floor_p = quietest(noise_p_pa, local_p), floor_h = quietest(noise_h_m, local_h);
  for (AnchoredWindow& w : windows) {
    w.rms_p = floor_p > 0.0 ? w.rms_p / floor_p : NAN;
    w.rms_h = floor_h > 0.0 ? w.rms_h / floor_h : NAN;
  }
  return windows;
}

std::vector<GapEvent> eventsFromWindows(const std::string& run_name, const std::vector<AnchoredWindow>& windows,
                                        const LocalisationOptions& options) {
  std::vector<GapEvent> events;
  for (const bool pressure : {true, false}) {
    const std::map<int, double> floors = slotFloors(windows, pressure, options);
    GapEvent open;
    bool is_open = false;
    for (const AnchoredWindow& w : windows) {
      const double rms = pressure ? w.rms_p : w.rms_h;
      const double floor = floors.at(w.slot);
      if (!(rms > options.min_rms && rms > options.floor_ratio * floor)) continue;
      if (is_open && w.t_start_s - open.end_s <= options.merge_gap_s) {
        open.end_s = w.t_end_s;
        if (rms > open.peak_rms) {
          open.peak_rms = rms;
          open.floor_rms = floor;
        }
        continue;
      }
      if (is_open) events.push_back(open);
      open = GapEvent{run_name, pressure ? "pressure" : "height", w.t_start_s, w.t_end_s, rms, floor};
      is_open = true;
    }
    if (is_open) events.push_back(open);
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const GapEvent& a, const GapEvent& b) { return a.onset_s < b.onset_s; });
  return events;
}

std::vector<GapEvent> localiseInTime(const RunData& run, const CellParams& params,
                                     const std::vector<CellEffectPtr>& effects, double noise_p_pa, double noise_h_m,
                                     const LocalisationOptions& options) {
  return eventsFromWindows(run.name, anchoredWindows(run, params, effects, noise_p_pa, noise_h_m, options), options);
}

}  // namespace nursing_bed
