#include "nursing_bed/core/gap_replay.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <tuple>

namespace nursing_bed {
namespace {
constexpr double kLandedHeightM = 0.003;
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

std::vector<RunPhase> classifyPhases(const RunData& run) {
  const std::size_t n = run.size();
  std::vector<RunPhase> phases(n, RunPhase::kHold);
  double peak_flow = 0.0;
  for (double q : run.mdot_in_kg_s)
    if (std::isfinite(q)) peak_flow = std::max(peak_flow, std::fabs(q));
  const double threshold = 0.02 * peak_flow;
  // Inflation: from the start to the last sample with clear inflow before the first vent.
  std::size_t vent_start = n;
  for (std::size_t i = 0; i < n; ++i)
    if (run.mdot_in_kg_s[i] < -threshold) {
      vent_start = i;
      break;
    }
  std::size_t inflate_end = 0;
  for (std::size_t i = 0; i < vent_start; ++i)
    if (run.mdot_in_kg_s[i] > threshold) inflate_end = i + 1;
  double peak_p = 0.0;
  for (std::size_t i = 0; i < inflate_end; ++i)
    if (std::isfinite(run.p_gauge_pa[i])) peak_p = std::max(peak_p, run.p_gauge_pa[i]);
  bool landed = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (i < inflate_end) {
      phases[i] = run.p_gauge_pa[i] < 0.25 * peak_p ? RunPhase::kDeploy : RunPhase::kPressurize;
    } else if (i >= vent_start) {
      landed = landed || (std::isfinite(run.h_m[i]) && run.h_m[i] < kLandedHeightM);
      phases[i] = landed ? RunPhase::kLanded : RunPhase::kVent;
    }
  }
  return phases;
}

Replay replayRun(const RunData& run, const CellParams& params, const std::vector<CellEffectPtr>& effects) {
  Replay out;
  out.phases = classifyPhases(run);
  const std::size_t n = run.size();
  out.p_gauge_pa.assign(n, NAN);
  out.h_m.assign(n, NAN);
  try {
    std::vector<double> t, q;
    for (std::size_t i = 0; i < n; ++i)
      if (std::isfinite(run.mdot_in_kg_s[i])) {
        t.push_back(run.t_s[i]);
        q.push_back(run.mdot_in_kg_s[i]);
      }
    if (t.size() < 2) throw std::invalid_argument("fewer than 2 inflow samples");
    const TimeSeries inflow(t, q);
    CellModel model(params);
    for (const auto& e : effects) model.addEffect(e);
    const double load0 = run.loadAt(0);
    if (std::isfinite(run.h_m[0]) && run.h_m[0] > kLandedHeightM) model.resetToEquilibrium(run.h_m[0], load0);
    else model.reset(load0);
    // Model time starts at the run's first sample.
    model.setState(run.t_s[0], model.state());
    CellInputs in;
    in.prescribed_inflow = &inflow;
    for (std::size_t i = 0; i < n; ++i) {
      if (i > 0) {
        in.load_n = run.loadAt(i - 1);
        model.advance(run.t_s[i] - run.t_s[i - 1], in);
      }
      const Measurement m = model.measure();
      out.p_gauge_pa[i] = m.gauge_pressure_pa;
      out.h_m[i] = m.height_m;
    }
  } catch (const std::exception& e) {
    out.ok = false;
    out.message = run.name + ": replay failed: " + e.what();
  }
  return out;
}

double estimateNoise(const std::vector<double>& x) {
  std::vector<double> d;
  for (std::size_t i = 1; i + 1 < x.size(); ++i) {
    const double v = x[i + 1] - 2.0 * x[i] + x[i - 1];
    if (std::isfinite(v)) d.push_back(std::fabs(v));
  }
  if (d.empty()) return 0.0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return 1.4826 * d[d.size() / 2] / std::sqrt(6.0);
}

RunResidual runResidual(const RunData& run, const Replay& replay) {
  RunResidual r;
  double p_lo = INFINITY, p_hi = -INFINITY, h_lo = INFINITY, h_hi = -INFINITY, sp = 0.0, sh = 0.0;
  for (std::size_t i = 0; i < run.size(); ++i) {
    if (replay.phases[i] == RunPhase::kLanded) continue;
    const double p = run.p_gauge_pa[i], h = run.h_m[i];
    if (!std::isfinite(p) || !std::isfinite(h)) continue;
    p_lo = std::min(p_lo, p);
    p_hi = std::max(p_hi, p);
    h_lo = std::min(h_lo, h);
    h_hi = std::max(h_hi, h);
    sp += std::pow(p - replay.p_gauge_pa[i], 2);
    sh += std::pow(h - replay.h_m[i], 2);
    ++r.samples;
  }
  if (r.samples == 0) return r;
  r.range_p_pa = std::max(p_hi - p_lo, 1e-9);
  r.range_h_m = std::max(h_hi - h_lo, 1e-12);
  r.nrmse_p = std::sqrt(sp / r.samples) / r.range_p_pa;
  r.nrmse_h = std::sqrt(sh / r.samples) / r.range_h_m;
  return r;
}

std::vector<GapShare> localizeGap(const std::vector<RunData>& runs, const std::vector<Replay>& replays) {
  if (runs.size() != replays.size()) throw std::invalid_argument("localizeGap: runs and replays differ in number");
  using Key = std::tuple<std::string, std::string, double>;
  std::map<Key, GapShare> cells;
  double total = 0.0;
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const RunData& run = runs[k];
    const Replay& rep = replays[k];
    if (!rep.ok) continue;
    const RunResidual range = runResidual(run, rep);
    if (range.samples == 0) continue;
    for (std::size_t i = 0; i < run.size(); ++i) {
      if (rep.phases[i] == RunPhase::kLanded) continue;
      const double ep = (run.p_gauge_pa[i] - rep.p_gauge_pa[i]) / range.range_p_pa;
      const double eh = (run.h_m[i] - rep.h_m[i]) / range.range_h_m;
      for (int s = 0; s < 2; ++s) {
        const double e2 = s == 0 ? ep * ep : eh * eh;
        if (!std::isfinite(e2)) continue;
        const Key key{s == 0 ? "pressure" : "height", phaseName(rep.phases[i]), std::round(run.loadAt(i) * 10.0) / 10.0};
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
