#include "nursing_bed/core/gap/distortions.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/io/number_text.h"

namespace nursing_bed {
namespace {

/// A distortion candidate: one parameter <channel>_<kind> (+ unit suffix), off at 0; linear over
/// [-hi, hi] (a sign either way) unless `lag` (log over [lo, hi], 0 = off, a switch).
EffectSpec distortion(const std::string& channel, const std::string& kind, const std::string& unit_suffix,
                      const std::string& unit, double lo, double hi, double adm, const std::string& what) {
  EffectSpec e;
  e.name = channel + "_" + kind;
  e.candidate = true;
  e.channel = channel;
  e.kind = kind;
  e.description = channel + " channel: " + what;
  e.signature = "a " + kind + " of the " + channel + " channel alone";
  EffectParamSpec p;
  p.name = e.name + unit_suffix;
  p.unit = unit;
  p.description = what;
  p.off_value = 0.0;
  p.log_scale = kind == "lag";
  p.lo = p.log_scale ? lo : -hi;
  p.hi = hi;
  p.min_value = p.log_scale ? 0.0 : -adm;
  p.max_value = adm;
  e.switch_param = p.name;
  e.params.push_back(p);
  return e;
}

std::vector<EffectSpec> makeDistortions() {
  const char* gain = "reads (1 + g) times the truth";
  const char* shift = "reads the truth d late (d < 0: early)";
  const char* lag = "first-order lag tau between truth and reading";
  return {
      distortion("pressure", "gain", "", "-", 0.0, 0.1, 0.5, gain),
      distortion("pressure", "offset", "_pa", "Pa", 0.0, 500.0, 2.0e4, "zero offset b"),
      distortion("pressure", "drift", "_pa_s", "Pa/s", 0.0, 5.0, 100.0, "zero drifting at r per second of the run"),
      distortion("pressure", "shift", "_s", "s", 0.0, 0.2, 2.0, shift),
      distortion("height", "gain", "", "-", 0.0, 0.1, 0.5, gain),
      distortion("height", "offset", "_m", "m", 0.0, 2.0e-3, 0.05, "zero offset b"),
      distortion("height", "drift", "_m_s", "m/s", 0.0, 2.0e-5, 1.0e-3, "zero drifting at r per second of the run"),
      distortion("height", "shift", "_s", "s", 0.0, 0.2, 2.0, shift),
      distortion("height", "lag", "_s", "s", 0.05, 1.0, 10.0, lag),
      distortion("inflow", "drift", "_kg_s2", "kg/s^2", 0.0, 3.0e-7, 1.0e-5,
                 "meter zero drifting at r per second of the run"),
      distortion("inflow", "shift", "_s", "s", 0.0, 0.2, 2.0, shift),
      distortion("load", "gain", "", "-", 0.0, 0.1, 0.5, "recorded load is (1 + g) times the true one"),
      distortion("load", "offset", "_n", "N", 0.0, 1.0, 20.0, "recorded load is the true one + b"),
      distortion("valve_cmd", "shift", "_s", "s", 0.0, 0.2, 2.0, "the valve acts d after its command"),
      distortion("valve_cmd", "lag", "_s", "s", 0.01, 0.5, 5.0, "the valve follows its command with a lag tau"),
      distortion("supply", "gain", "", "-", 0.0, 0.1, 0.5, gain),
      distortion("supply", "offset", "_pa", "Pa", 0.0, 1000.0, 5.0e4, "zero offset b"),
  };
}

const std::vector<std::string> kChannels{"pressure", "height", "inflow", "valve_cmd", "supply", "load"};

bool anyFinite(const std::vector<double>& v) {
  return std::any_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

/// x at time s by linear interpolation on (t, x), the end values held beyond the ends.
double sampleAt(const std::vector<double>& t, const std::vector<double>& x, double s) {
  if (s <= t.front()) return x.front();
  if (s >= t.back()) return x.back();
  const std::size_t j = static_cast<std::size_t>(std::upper_bound(t.begin(), t.end(), s) - t.begin());
  const double w = (s - t[j - 1]) / (t[j] - t[j - 1]);
  return x[j - 1] + w * (x[j] - x[j - 1]);
}

/// x(t - d) on the finite samples alone: a replay's samples after its plate landed are NaN, and
/// a reading early (d < 0) near them takes the last finite value, as at a run's end. Before the
/// first sample, its value held, or (finite `at_rest`) `at_rest` |d| before it.
void shiftSeries(double d, const std::vector<double>& t, std::vector<double>* x, double at_rest) {
  if (d == 0.0 || x->empty()) return;
  std::vector<double> tf, xf;
  if (std::isfinite(at_rest)) {
    tf.push_back(t.front() - std::fabs(d));
    xf.push_back(at_rest);
  }
  for (std::size_t i = 0; i < x->size(); ++i)
    if (std::isfinite((*x)[i])) {
      tf.push_back(t[i]);
      xf.push_back((*x)[i]);
    }
  if (tf.empty()) return;
  for (std::size_t i = 0; i < x->size(); ++i)
    if (std::isfinite((*x)[i])) (*x)[i] = sampleAt(tf, xf, t[i] - d);
}

/// tau dy/dt = x - y with x linear between samples: y1 = x1 - tau s + (y0 - x0 + tau s) e^(-dt/tau),
/// s the slope of x over the step.
void lagSeries(double tau, const std::vector<double>& t, std::vector<double>* x) {
  if (tau <= 0.0) return;
  bool started = false;
  double y = 0.0, x_prev = 0.0, t_prev = 0.0;
  for (std::size_t i = 0; i < x->size(); ++i) {
    const double xi = (*x)[i];
    if (!std::isfinite(xi)) continue;
    if (started) {
      const double dt = t[i] - t_prev;
      const double slope = (xi - x_prev) / dt;
      y = xi - tau * slope + (y - x_prev + tau * slope) * std::exp(-dt / tau);
    } else {
      y = xi;
      started = true;
    }
    x_prev = xi;
    t_prev = t[i];
    (*x)[i] = y;
  }
}

std::string knownKinds(const std::string& channel) {
  std::string s;
  for (const auto& m : distortionMembers())
    if (m.channel == channel) s += (s.empty() ? "" : ", ") + m.kind;
  return s;
}

/// How a value of a kind reads in a description.
std::string valueText(const std::string& kind, double v, double se, const std::string& unit) {
  const bool relative = kind == "gain";
  std::ostringstream s;
  s << std::showpos;
  if (relative) {
    // One decimal of a percent, more where the standard error is smaller than that.
    const int decimals =
        std::isfinite(se) && se > 0.0 ? std::clamp(-static_cast<int>(std::floor(std::log10(100.0 * se))), 1, 4) : 1;
    s << std::fixed << std::setprecision(decimals) << 100.0 * v << " %";
    if (std::isfinite(se)) s << std::noshowpos << " ± " << 100.0 * se << " %";
    return s.str();
  }
  s << std::defaultfloat << std::setprecision(3) << v << " " << unit;
  if (std::isfinite(se)) s << std::noshowpos << std::setprecision(2) << " ± " << se << " " << unit;
  return s.str();
}

}  // namespace

const std::vector<EffectSpec>& distortionCatalog() {
  static const std::vector<EffectSpec> catalog = makeDistortions();
  return catalog;
}

const std::vector<DistortionMember>& distortionMembers() {
  static const std::vector<DistortionMember> members = [] {
    std::vector<DistortionMember> m;
    for (const auto& e : distortionCatalog()) m.push_back({e.channel, e.kind, e.name, e.params.front().name});
    m.push_back({"pressure", "lag", "pressure_sensor_lag", "time_constant_s"});
    m.push_back({"inflow", "gain", "inflow_bias", "scale_error"});
    m.push_back({"inflow", "offset", "inflow_bias", "offset_kg_s"});
    return m;
  }();
  return members;
}

std::vector<std::string> distortionCandidatesFor(const std::vector<const RunData*>& runs) {
  std::set<std::string> present{"pressure", "load"};
  for (const RunData* r : runs) {
    if (anyFinite(r->h_m)) present.insert("height");
    if (anyFinite(r->mdot_in_kg_s)) present.insert("inflow");
    if (runIsValveDriven(*r)) present.insert({"valve_cmd", "supply"});
  }
  std::vector<std::string> out;
  for (const auto& e : distortionCatalog())
    if (present.count(e.channel)) out.push_back(e.name);
  return out;
}

bool isDistortionEffect(const std::string& effect_name) {
  for (const auto& m : distortionMembers())
    if (m.effect == effect_name) return true;
  return false;
}

std::map<std::string, std::map<std::string, double>> parseDistortion(const std::string& text) {
  const auto colon = text.find(':');
  const std::string channel = text.substr(0, colon);
  if (std::find(kChannels.begin(), kChannels.end(), channel) == kChannels.end())
    throw std::invalid_argument("distortion '" + text + "': unknown channel '" + channel +
                                "' (known: pressure, height, inflow, valve_cmd, supply, load)");
  if (colon == std::string::npos || colon + 1 == text.size())
    throw std::invalid_argument("distortion '" + text + "': expected " + channel + ":kind=value (kinds of " + channel +
                                ": " + knownKinds(channel) + ")");
  std::map<std::string, std::map<std::string, double>> out;
  std::set<std::string> kinds;
  std::stringstream items(text.substr(colon + 1));
  std::string item;
  while (std::getline(items, item, ',')) {
    const auto eq = item.find('=');
    const std::string kind = item.substr(0, eq);
    const auto m = std::find_if(distortionMembers().begin(), distortionMembers().end(),
                                [&](const DistortionMember& d) { return d.channel == channel && d.kind == kind; });
    if (m == distortionMembers().end())
      throw std::invalid_argument("distortion '" + text + "': unknown kind '" + kind + "' for channel " + channel +
                                  " (known: " + knownKinds(channel) + ")");
    if (eq == std::string::npos)
      throw std::invalid_argument("distortion '" + text + "': " + kind + " needs a value (" + kind + "=value)");
    if (!kinds.insert(kind).second) throw std::invalid_argument("distortion '" + text + "': " + kind + " given twice");
    const std::string value = item.substr(eq + 1);
    double v = 0.0;
    if (!parseFiniteNumber(value, &v))
      throw std::invalid_argument("distortion '" + text + "': " + kind + " value '" + value +
                                  "' is not a finite number");
    out[m->effect][m->param] = v;
  }
  // Every parameter of each effect (inflow_bias has two), the others at off; then the ranges.
  for (auto& [effect, params] : out) {
    const EffectSpec& spec = effectSpec(effect);
    for (const auto& p : spec.params)
      if (!params.count(p.name)) params[p.name] = p.off_value;
    try {
      makeEffect(effect, params);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("distortion '" + text + "': " + e.what());
    }
  }
  return out;
}

std::string describeDistortion(const std::string& effect_name, const std::map<std::string, double>& params,
                               const std::map<std::string, double>& std_errors) {
  std::string s;
  for (const auto& m : distortionMembers()) {
    if (m.effect != effect_name || !params.count(m.param)) continue;
    const double v = params.at(m.param);
    if (m.effect == "inflow_bias" && v == 0.0) continue;  // the member not in play
    const auto se = std_errors.find(m.param);
    const EffectSpec& spec = effectSpec(m.effect);
    s += (s.empty() ? m.channel + ": " : ", ") + m.kind + " " +
         valueText(m.kind, v, se == std_errors.end() ? NAN : se->second, spec.param(m.param)->unit);
  }
  return s;
}

void distortSeries(const std::string& kind, double value, const std::vector<double>& t, std::vector<double>* x,
                   double at_rest) {
  if (kind == "shift") return shiftSeries(value, t, x, at_rest);
  if (kind == "lag") return lagSeries(value, t, x);
  for (std::size_t i = 0; i < x->size(); ++i) {
    double& v = (*x)[i];
    if (!std::isfinite(v)) continue;
    if (kind == "gain") v *= 1.0 + value;
    else if (kind == "offset") v += value;
    else if (kind == "drift") v += value * (t[i] - t.front());
    else throw std::invalid_argument("unknown distortion kind '" + kind + "'");
  }
}

void undistortSeries(const std::string& kind, double value, const std::vector<double>& t, std::vector<double>* x,
                     double at_rest) {
  if (kind == "shift") return shiftSeries(-value, t, x, at_rest);
  if (kind == "lag")
    throw std::invalid_argument("a lag of a measured input cannot be undone (it differentiates noise)");
  for (std::size_t i = 0; i < x->size(); ++i) {
    double& v = (*x)[i];
    if (!std::isfinite(v)) continue;
    if (kind == "gain") v /= 1.0 + value;
    else if (kind == "offset") v -= value;
    else if (kind == "drift") v = v == 0.0 ? 0.0 : v - value * (t[i] - t.front());
    else throw std::invalid_argument("unknown distortion kind '" + kind + "'");
  }
}

ChannelDistortionEffect::ChannelDistortionEffect(std::string effect, std::string channel, std::string kind,
                                                 std::string param, double value)
    : effect_(std::move(effect)),
      channel_(std::move(channel)),
      kind_(std::move(kind)),
      param_(std::move(param)),
      value_(value) {}

bool onlyOutputDistortions(const std::vector<CellEffectPtr>& effects) {
  if (effects.empty()) return false;
  return std::all_of(effects.begin(), effects.end(), [](const CellEffectPtr& e) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    return d && d->outputSide();
  });
}

bool readsHeightEarly(const std::vector<CellEffectPtr>& effects) {
  return std::any_of(effects.begin(), effects.end(), [](const CellEffectPtr& e) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    return d && d->channel() == "height" && d->kind() == "shift" && d->value() < 0.0;
  });
}

bool applyInputDistortions(const std::vector<CellEffectPtr>& effects, RunData* run) {
  bool any = false;
  for (const auto& e : effects) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    if (!d || d->outputSide() || d->value() == 0.0) continue;
    any = true;
    const std::string& c = d->channel();
    // A run starts at rest: no flow and valves shut before its first sample.
    if (c == "inflow") undistortSeries(d->kind(), d->value(), run->t_s, &run->mdot_in_kg_s, 0.0);
    if (c == "supply") undistortSeries(d->kind(), d->value(), run->t_s, &run->p_supply_gauge_pa);
    if (c == "valve_cmd") distortSeries(d->kind(), d->value(), run->t_s, &run->valve_cmd, 0.0);
    if (c == "load") {
      std::vector<double> constant{run->load_n};
      undistortSeries(d->kind(), d->value(), {run->t_s.front()}, &constant);
      run->load_n = constant[0];
      undistortSeries(d->kind(), d->value(), run->t_s, &run->load_n_series);
    }
  }
  return any;
}

bool undoHeightReadingDistortions(const std::vector<CellEffectPtr>& effects, const std::vector<double>& t,
                                  const std::vector<double>& h, std::vector<double>* out) {
  bool any = false;
  for (const auto& e : effects) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    if (!d || d->channel() != "height" || d->value() == 0.0) continue;
    if (d->kind() != "gain" && d->kind() != "offset" && d->kind() != "drift") continue;
    if (!any) *out = h;  // copied only for a distortion that undoes it
    undistortSeries(d->kind(), d->value(), t, out);
    any = true;
  }
  return any;
}

void applyOutputDistortions(const std::vector<CellEffectPtr>& effects, const std::vector<double>& t,
                            std::vector<double>* p, std::vector<double>* h) {
  for (const auto& e : effects) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    if (!d || !d->outputSide() || d->value() == 0.0) continue;
    distortSeries(d->kind(), d->value(), t, d->channel() == "pressure" ? p : h);
  }
}

}  // namespace nursing_bed
