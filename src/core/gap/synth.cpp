#include "nursing_bed/core/gap/synth.h"

#include "nursing_bed/core/gap/distortions.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <ostream>
#include <set>
#include <sstream>
#include <stdexcept>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/discovery_terms.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/io/number_text.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/paper_experiment.h"
#include "nursing_bed/core/physics/pillow_structure.h"

namespace nursing_bed {
namespace {

namespace fs = std::filesystem;

// Heights the two flow magnitudes bring the cell to at rest (ambient temperature).
constexpr double kLowTargetHeightM = 0.110;
constexpr double kHighTargetHeightM = 0.145;
// The inlet valve opens linearly over this time when the vent starts.
constexpr double kVentOpeningRampS = 0.3;

std::string shortNumber(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

// "10p6" for 10.6 N.
std::string loadTag(double load_n) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << load_n;
  std::string t = s.str();
  std::replace(t.begin(), t.end(), '.', 'p');
  return t;
}

// Gas mass to add to the flat cell (ambient, dead volume only) so that it rests at `height_m`
// under `load_n` at ambient temperature.
double massToReach(const CellParams& params, const CellStructure& structure, double height_m, double load_n) {
  const StructureEquilibrium eq = structure.equilibriumAtHeight(height_m, load_n);
  if (!eq.converged) {
    std::ostringstream msg;
    msg << "gap synth: no equilibrium holds " << load_n << " N at " << height_m << " m";
    throw std::runtime_error(msg.str());
  }
  const double rest_volume = structure.evaluate(0.0, structure.restShape().data()).volume_m3;
  const double m_flat =
      massFromState(params.gas, params.ambient_pressure_pa, params.ambient_temperature_k, rest_volume);
  const double m_target = massFromState(params.gas, params.ambient_pressure_pa + eq.gauge_pressure_pa,
                                        params.ambient_temperature_k, eq.eval.volume_m3);
  return m_target - m_flat;
}

}  // namespace

SynthEffectRequest parseEffectRequest(const std::string& text) {
  SynthEffectRequest r;
  const auto colon = text.find(':');
  r.name = text.substr(0, colon);
  const EffectSpec& spec = effectSpec(r.name);  // throws for an unknown name
  if (colon == std::string::npos) return r;
  std::stringstream items(text.substr(colon + 1));
  std::string item;
  while (std::getline(items, item, ',')) {
    if (item.empty()) continue;
    const auto eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("effect '" + r.name + "': expected param=value, got '" + item + "'");
    const std::string key = item.substr(0, eq);
    const std::string value = item.substr(eq + 1);
    if (!spec.param(key)) {
      std::string expected;
      for (const auto& p : spec.params) expected += (expected.empty() ? "" : ", ") + p.name;
      throw std::invalid_argument("effect '" + r.name + "': unknown parameter '" + key + "' (expected: " + expected +
                                  ")");
    }
    double v = 0.0;
    if (!parseFiniteNumber(value, &v))
      throw std::invalid_argument("effect '" + r.name + "': parameter " + key + ": '" + value +
                                  "' is not a finite number");
    if (r.params.count(key)) throw std::invalid_argument("effect '" + r.name + "': parameter " + key + " given twice");
    r.params[key] = v;
  }
  return r;
}

SynthProtocol synthProtocol(const std::string& name, const CellParams& params) {
  SynthProtocol p;
  p.name = name;
  std::vector<double> loads;
  // (load, flow) pairs that are withheld.
  std::set<std::pair<double, std::string>> withheld;
  if (name == "standard") {
    loads.assign(kPaperLoadsN.begin(), kPaperLoadsN.end());
    withheld = {{10.6, "high"}, {20.6, "low"}};
  } else if (name == "small") {
    p.hold_s = 30.0;
    p.sample_hz = 50.0;
    loads = {0.6, 15.6};
    withheld = {{0.6, "high"}, {15.6, "low"}};
  } else {
    throw std::invalid_argument("unknown protocol '" + name + "' (known: standard, small)");
  }
  for (double load : loads) {
    for (const std::string flow : {"low", "high"}) {
      SynthRunPlan r = synthRunPlan(params, load, flow, 1.0);
      r.role = withheld.count({load, flow}) ? "withheld" : "fit";
      p.runs.push_back(r);
    }
  }
  return p;
}

SynthRunPlan synthRunPlan(const CellParams& params, double load_n, const std::string& flow, double rise_scale) {
  if (!(load_n >= 0.1 && load_n <= 200.0))
    throw std::invalid_argument("run load " + shortNumber(load_n) + " N outside 0.1-200 N");
  if (flow != "low" && flow != "high") throw std::invalid_argument("run flow '" + flow + "' (known: low, high)");
  if (!(rise_scale >= 0.25 && rise_scale <= 10.0))
    throw std::invalid_argument("run rise_scale " + shortNumber(rise_scale) + " outside 0.25-10");
  SynthRunPlan r;
  r.load_n = load_n;
  r.flow = flow;
  r.rise_scale = rise_scale;
  r.target_height_m = flow == "low" ? kLowTargetHeightM : kHighTargetHeightM;
  r.inflow_mass_kg = massToReach(params, *makeCellStructure(params), r.target_height_m, load_n);
  r.name = "load" + loadTag(load_n) + "N_" + flow + (rise_scale == 1.0 ? "" : "_rise" + loadTag(rise_scale)) + ".csv";
  r.role = "fit";
  return r;
}

SynthRunPlan parseRunPlan(const std::string& text, const CellParams& params) {
  std::map<std::string, std::string> fields;
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    const auto eq = item.find('=');
    const std::string key = item.substr(0, eq);
    if (eq == std::string::npos || (key != "load_n" && key != "flow" && key != "rise_scale" && key != "role"))
      throw std::invalid_argument("run '" + text + "': '" + item +
                                  "' is not one of load_n=N, flow=low|high, rise_scale=K, role=fit|withheld");
    if (!fields.emplace(key, item.substr(eq + 1)).second)
      throw std::invalid_argument("run '" + text + "': " + key + " given twice");
  }
  if (!fields.count("load_n") || !fields.count("flow"))
    throw std::invalid_argument("run '" + text + "': load_n and flow are required");
  auto number = [&](const std::string& key, double fallback) {
    if (!fields.count(key)) return fallback;
    double v = 0.0;
    if (!parseFiniteNumber(fields.at(key), &v))
      throw std::invalid_argument("run '" + text + "': " + key + " '" + fields.at(key) + "' is not a finite number");
    return v;
  };
  SynthRunPlan r = synthRunPlan(params, number("load_n", 0.0), fields.at("flow"), number("rise_scale", 1.0));
  if (fields.count("role")) {
    r.role = fields.at("role");
    if (r.role != "fit" && r.role != "withheld")
      throw std::invalid_argument("run '" + text + "': role '" + r.role + "' (known: fit, withheld)");
  }
  return r;
}

SensorNoise SensorNoise::scaled(double factor) const {
  SensorNoise n = *this;
  n.pressure_sd_pa *= factor;
  n.pressure_step_pa *= factor;
  n.height_sd_m *= factor;
  n.height_step_m *= factor;
  n.flow_relative_sd *= factor;
  n.flow_sd_kg_s *= factor;
  n.flow_step_kg_s *= factor;
  return n;
}

double quantise(double x, double step) {
  if (!(step > 0.0) || !std::isfinite(x)) return x;
  // Divide by an integer 1/step where there is one: k / 10000 is the double nearest to the
  // decimal k e-4 (k * 1e-4 often is not), so the CSV gets short numbers.
  const double inverse = std::round(1.0 / step);
  if (inverse >= 1.0 && std::fabs(inverse * step - 1.0) < 1e-12) return std::round(x * inverse) / inverse;
  return std::round(x / step) * step;
}

namespace {

/// The valve command a valve-driven run gives, as a step function (signed like valve_cmd: +
/// inlet opening, - vent opening), each value in force from its start time on.
struct ValveSchedule {
  std::vector<double> start_s, value;

  void add(double t, double v) {
    if (value.empty() || value.back() != v) {
      start_s.push_back(t);
      value.push_back(v);
    }
  }
  /// The command in force at time s (shut before the first).
  double at(double s) const {
    const auto k = std::upper_bound(start_s.begin(), start_s.end(), s) - start_s.begin();
    return k == 0 ? 0.0 : value[static_cast<std::size_t>(k - 1)];
  }
};

/// Advances `model` over one sample interval ending at `t` on the valve-driven protocol: the
/// inlet open to the supply (by `opening`) until the bag holds `target_mass_kg`, closed for the
/// hold, the vent valve open for the vent. Returns the mean valve command over the interval;
/// `told` (if given) gets the command step by step.
double advanceValveDriven(CellModel* model, const SynthProtocol& protocol, double t, double opening,
                          double target_mass_kg, CellInputs* in, ValveSchedule* told) {
  const double hold_end = protocol.inflate_s + protocol.hold_s;
  in->prescribed_inflow = nullptr;
  in->inlet_opening = in->vent_opening = 0.0;
  const double t0 = model->time();
  double command = 0.0;
  if (t <= hold_end + 1e-9 && t0 < protocol.inflate_s - 1e-9) {
    while (t - model->time() > 1e-12) {  // 1 ms steps: the valve closes once the mass is in
      const double dt = std::min(1e-3, t - model->time());
      in->inlet_opening = model->state()[CellModel::kMass] < target_mass_kg ? opening : 0.0;
      if (told) told->add(model->time(), in->inlet_opening);
      command += in->inlet_opening * dt;
      model->advance(dt, *in);
    }
    return command / (t - t0);
  }
  if (t > hold_end + 1e-9) in->vent_opening = 1.0;
  if (told) told->add(t0, -in->vent_opening);
  model->advance(t - t0, *in);
  return -in->vent_opening;
}

/// The rig's valves acting on `told` through a planted valve_cmd distortion (the valve d late,
/// or following with a first-order lag tau): the run's readings simulated again, in 1 ms steps,
/// from the same start; the recorded command stays the one given.
void simulateDistortedValves(CellModel* model, const ChannelDistortionEffect& d, const ValveSchedule& told,
                             RunData* run) {
  constexpr double kStepS = 1e-3;
  CellInputs in;
  in.load_n = run->load_n;
  double lagged = 0.0;  // the lagging valve's opening
  const double tau = d.kind() == "lag" ? d.value() : 0.0;
  for (std::size_t i = 1; i < run->size(); ++i) {
    while (run->t_s[i] - model->time() > 1e-12) {
      const double dt = std::min(kStepS, run->t_s[i] - model->time());
      const double mid = model->time() + 0.5 * dt;
      double open = told.at(mid - (d.kind() == "shift" ? d.value() : 0.0));
      if (tau > 0.0) {
        // tau dy/dt = c - y with c constant over the step: y's mean over it, then its end value.
        const double c = open, decay = std::exp(-dt / tau);
        open = c + (lagged - c) * tau / dt * (1.0 - decay);
        lagged = c + (lagged - c) * decay;
      }
      in.inlet_opening = std::max(0.0, open);
      in.vent_opening = std::max(0.0, -open);
      model->advance(dt, in);
    }
    const Readings m = model->measure();
    run->p_gauge_pa[i] = m.gauge_pressure_pa;
    run->h_m[i] = m.height_m;
  }
}

/// The metadata of a synthetic run.
void synthRunHeader(const SynthProtocol& protocol, const SynthRunPlan& plan, const std::string& airbag_name,
                    RunData* run) {
  run->name = plan.name;
  run->airbag = airbag_name;
  run->load_n = plan.load_n;
  run->meta["nursing_bed_run"] = std::to_string(kRunCsvVersion);
  run->meta["load_n"] = shortNumber(plan.load_n);
  run->meta["airbag"] = airbag_name;
  std::ostringstream note;
  note << "gap synth, protocol " << protocol.name << ": load " << plan.load_n << " N, " << plan.flow << " flow ("
       << std::setprecision(4) << plan.inflow_mass_kg * 1e3 << " g, ~" << std::setprecision(3)
       << plan.target_height_m * 1e3 << " mm at rest); inflate 0-" << protocol.inflate_s << " s, hold to "
       << protocol.inflate_s + protocol.hold_s << " s, vent "
       << (protocol.valve_driven ? "through the vent valve (no flow meter)" : "through the inlet") << " to "
       << protocol.durationS() << " s";
  run->meta["note"] = note.str();
}

/// Advances `model` over one sample interval ending at `t` on the metered protocol (prescribed
/// paper-shaped inflow, hold, vent through the inlet); returns the valve command from `t` on.
double advanceMetered(CellModel* model, const SynthProtocol& protocol, double t, const TimeSeries& inflow,
                      CellInputs* in) {
  const double hold_end = protocol.inflate_s + protocol.hold_s;
  in->prescribed_inflow = nullptr;
  in->inlet_opening = 0.0;
  in->supply_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  if (t <= protocol.inflate_s + 1e-9) {
    in->prescribed_inflow = &inflow;
    model->advance(t - model->time(), *in);
  } else if (t <= hold_end + 1e-9) {
    model->advance(t - model->time(), *in);
  } else {
    // The inlet valve opens over kVentOpeningRampS (in 1 ms steps): a flow that starts
    // smoothly, so that the sampled metered flow carries the mass that left.
    in->supply_pressure_pa = 0.0;
    while (t - model->time() > 1e-12) {
      const double ramp_end = hold_end + kVentOpeningRampS;
      const double dt = model->time() < ramp_end - 1e-12 ? std::min(1e-3, t - model->time()) : t - model->time();
      in->inlet_opening = std::min(1.0, (model->time() + 0.5 * dt - hold_end) / kVentOpeningRampS);
      model->advance(dt, *in);
    }
  }
  return t < protocol.inflate_s - 1e-9 ? 1.0 : (t < hold_end - 1e-9 ? 0.0 : -1.0);
}

/// The planted channel distortions (distortions.h) on the true readings, before the noise: what
/// the distorted sensors report, the recorded load and the flow meter's reading.
void distortRecording(const std::vector<CellEffectPtr>& effects, RunData* run) {
  applyOutputDistortions(effects, run->t_s, &run->p_gauge_pa, &run->h_m);
  for (const auto& e : effects) {
    const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get());
    if (!d || d->outputSide()) continue;
    if (d->channel() == "inflow") distortSeries(d->kind(), d->value(), run->t_s, &run->mdot_in_kg_s, 0.0);
    if (d->channel() == "supply") distortSeries(d->kind(), d->value(), run->t_s, &run->p_supply_gauge_pa);
    if (d->channel() == "load") {
      std::vector<double> load{run->load_n};
      distortSeries(d->kind(), d->value(), {run->t_s.front()}, &load);
      run->load_n = load[0];
      run->meta["load_n"] = shortNumber(load[0]);
    }
  }
}

/// Sensor noise and quantisation on every reading, drawn per sample in the order pressure,
/// height, the flow's relative and absolute parts.
void addSensorNoise(const SensorNoise& noise, std::mt19937* rng, RunData* run) {
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (std::size_t i = 0; i < run->size(); ++i) {
    run->p_gauge_pa[i] = quantise(run->p_gauge_pa[i] + noise.pressure_sd_pa * gauss(*rng), noise.pressure_step_pa);
    run->h_m[i] = quantise(run->h_m[i] + noise.height_sd_m * gauss(*rng), noise.height_step_m);
    const double relative = noise.flow_relative_sd * gauss(*rng);
    double& flow = run->mdot_in_kg_s[i];
    flow = quantise(flow * (1.0 + relative) + noise.flow_sd_kg_s * gauss(*rng), noise.flow_step_kg_s);
  }
}

}  // namespace

RunData simulateSynthRun(const CellParams& params, const std::vector<CellEffectPtr>& effects,
                         const SynthProtocol& standard_rise, const SynthRunPlan& plan, const SensorNoise& noise,
                         std::mt19937* rng, const std::string& airbag_name) {
  SynthProtocol protocol = standard_rise;
  protocol.inflate_s *= plan.rise_scale;
  protocol.peak_s *= plan.rise_scale;
  CellParams p = params;
  // Metered: the vent's supply sits at 0 gauge at once. Valve-driven: the rig's regulator.
  if (!protocol.valve_driven) p.regulator_time_constant_s = 0.0;
  CellModel model(p);
  for (const auto& e : effects) model.addEffect(e);
  model.reset(plan.load_n);
  const double target_mass = model.state()[CellModel::kMass] + plan.inflow_mass_kg;
  const double opening = std::min(1.0, (plan.flow == "low" ? 0.5 : 1.0) / plan.rise_scale);

  const double hz = protocol.sample_hz;
  const TimeSeries inflow = paperShapedInflow(plan.inflow_mass_kg, protocol.peak_s, protocol.inflate_s, 1.0 / hz);
  const long n_total = std::lround(protocol.durationS() * hz);
  RunData run;
  synthRunHeader(protocol, plan, airbag_name, &run);
  for (auto* v : {&run.t_s, &run.mdot_in_kg_s, &run.p_gauge_pa, &run.h_m, &run.valve_cmd})
    v->reserve(static_cast<std::size_t>(n_total + 1));

  // A planted valve_cmd distortion: the rig's valves act on the command distorted (below).
  const ChannelDistortionEffect* valve_distortion = nullptr;
  for (const auto& e : effects)
    if (const auto* d = dynamic_cast<const ChannelDistortionEffect*>(e.get()); d && d->channel() == "valve_cmd")
      valve_distortion = d;
  ValveSchedule told;
  CellInputs in;
  in.load_n = plan.load_n;
  for (long i = 0; i <= n_total; ++i) {
    const double t = static_cast<double>(i) / hz;
    double command = 0.0;
    if (protocol.valve_driven)
      command = i > 0 ? advanceValveDriven(&model, protocol, t, opening, target_mass, &in, &told) : 0.0;
    else if (i > 0) command = advanceMetered(&model, protocol, t, inflow, &in);
    else command = 1.0;
    const Readings m = model.measure();
    run.t_s.push_back(t);
    run.mdot_in_kg_s.push_back(m.inflow_kg_s);
    run.p_gauge_pa.push_back(m.gauge_pressure_pa);
    run.h_m.push_back(m.height_m);
    // Metered: the command in force from this sample on; valve-driven: the mean opening over
    // the interval that ends here (doc/formats/run_data.md).
    run.valve_cmd.push_back(command);
  }
  if (valve_distortion && valve_distortion->value() != 0.0) {
    CellModel rig(p);
    for (const auto& e : effects) rig.addEffect(e);
    rig.reset(plan.load_n);
    simulateDistortedValves(&rig, *valve_distortion, told, &run);
  }
  if (protocol.valve_driven) run.p_supply_gauge_pa.assign(run.size(), p.supply_pressure_pa);
  distortRecording(effects, &run);
  if (rng) addSensorNoise(noise, rng, &run);
  if (protocol.valve_driven) run.mdot_in_kg_s.assign(run.size(), std::numeric_limits<double>::quiet_NaN());
  return run;
}

void resolveSynthEffects(const std::vector<SynthEffectRequest>& requests, std::uint32_t seed,
                         std::vector<std::string>* names, std::vector<std::map<std::string, double>>* params,
                         std::vector<CellEffectPtr>* effects) {
  std::set<std::string> requested;
  for (const auto& r : requests) {
    effectSpec(r.name);  // throws for an unknown name
    if (dictionaryTerm(r.name))
      throw std::invalid_argument("effect '" + r.name +
                                  "' is a term of the discovery's dictionary, not an effect gap synth plants");
    if (!requested.insert(r.name).second) throw std::invalid_argument("effect '" + r.name + "' given twice");
  }
  names->clear();
  params->clear();
  effects->clear();
  // Catalogue order, one generator for all: the draw does not depend on the order given.
  std::mt19937 rng(seed);
  for (const auto& spec : effectCatalog()) {
    if (!requested.count(spec.name)) continue;
    const auto& req = *std::find_if(requests.begin(), requests.end(),
                                    [&spec](const SynthEffectRequest& r) { return r.name == spec.name; });
    std::map<std::string, double> values = randomEffectParams(spec.name, rng);
    for (const auto& [k, v] : req.params) values[k] = v;
    effects->push_back(makeEffect(spec.name, values));  // checks names and ranges
    names->push_back(spec.name);
    params->push_back(values);
  }
}

namespace {

void sayProtocol(const SynthOptions& o, const SynthResult& result) {
  *o.progress << "gap synth: protocol " << o.protocol << ", " << result.protocol.runs.size() << " runs of "
              << result.protocol.durationS() << " s at " << result.protocol.sample_hz << " Hz, seed " << o.seed
              << ", noise scale " << o.noise_scale << "\n";
  *o.progress << "gap synth: truth effects:";
  if (result.effect_names.empty()) *o.progress << " none (nominal model)";
  for (std::size_t i = 0; i < result.effect_names.size(); ++i)
    *o.progress << " " << describeEffect(result.effect_names[i], result.effect_params[i]);
  for (std::size_t i = 0; i < result.distortion_names.size(); ++i)
    *o.progress << " " << describeDistortion(result.distortion_names[i], result.distortion_params[i]);
  *o.progress << "\n";
}

void sayRun(const SynthOptions& o, const SynthResult& result, std::size_t k, const RunData& run) {
  const SynthRunPlan& plan = result.protocol.runs[k];
  double h_max = -1e300, p_max = -1e300;
  for (std::size_t i = 0; i < run.size(); ++i) {
    h_max = std::max(h_max, run.h_m[i]);
    p_max = std::max(p_max, run.p_gauge_pa[i]);
  }
  *o.progress << "  [" << k + 1 << "/" << result.protocol.runs.size() << "] " << plan.name << ": load " << plan.load_n
              << " N, " << std::setprecision(4) << plan.inflow_mass_kg * 1e3 << " g, max height "
              << std::setprecision(4) << h_max * 1e3 << " mm, max pressure " << std::setprecision(5) << p_max / 1e3
              << " kPa (" << plan.role << ")\n";
}

void writeDatasetYaml(const SynthOptions& o, const SynthResult& result, const fs::path& dir) {
  YAML::Emitter e;
  e << YAML::BeginMap << YAML::Key << "airbag" << YAML::Value << o.airbag_file;
  e << YAML::Key << "runs" << YAML::Value << YAML::BeginMap;
  for (const auto& plan : result.protocol.runs) e << YAML::Key << plan.name << YAML::Value << plan.role;
  e << YAML::EndMap << YAML::EndMap;
  std::ofstream y(dir / "dataset.yaml");
  y << "# Written by gap synth (protocol " << o.protocol << "). Roles: fit runs train the diagnosis, withheld\n"
    << "# runs only judge it.\n"
    << e.c_str() << "\n";
  if (!y) throw std::runtime_error("gap synth: cannot write " + (dir / "dataset.yaml").string());
}

using Json = nlohmann::ordered_json;  // keys in a fixed order: same seed, same file

Json noiseJson(const SensorNoise& n) {
  return {{"pressure_sd_pa", n.pressure_sd_pa},     {"pressure_step_pa", n.pressure_step_pa},
          {"height_sd_m", n.height_sd_m},           {"height_step_m", n.height_step_m},
          {"flow_relative_sd", n.flow_relative_sd}, {"flow_sd_kg_s", n.flow_sd_kg_s},
          {"flow_step_kg_s", n.flow_step_kg_s}};
}

Json numbers(const std::map<std::string, double>& values) {
  Json j = Json::object();
  for (const auto& [k, v] : values) j[k] = v;
  return j;
}

Json effectsJson(const SynthResult& result) {
  Json j = Json::array();
  for (std::size_t i = 0; i < result.effect_names.size(); ++i)
    j.push_back({{"name", result.effect_names[i]},
                 {"candidate", effectSpec(result.effect_names[i]).candidate},
                 {"params", numbers(result.effect_params[i])}});
  return j;
}

Json runsJson(const SynthProtocol& protocol) {
  Json j = Json::array();
  for (const SynthRunPlan& r : protocol.runs)
    j.push_back({{"file", r.name},
                 {"load_n", r.load_n},
                 {"flow", r.flow},
                 {"target_height_m", r.target_height_m},
                 {"inflow_mass_kg", r.inflow_mass_kg},
                 {"rise_scale", r.rise_scale},
                 {"role", r.role}});
  return j;
}

/// truth.json: what was hidden in the runs (never read by the diagnosis). Numbers that are not
/// finite are written as null (nlohmann-json's rule; JSON has no NaN).
void writeTruthJson(const SynthOptions& o, const SynthResult& result, const SensorNoise& noise, const fs::path& dir) {
  const SynthProtocol& p = result.protocol;
  Json j;
  j["format"] = "nursing_bed_gap_truth/1";
  j["protocol"] = o.protocol;
  j["seed"] = o.seed;
  j["noise_scale"] = o.noise_scale;
  j["noise"] = noiseJson(noise);
  j["effects"] = effectsJson(result);
  Json distortions = Json::array();
  for (std::size_t i = 0; i < result.distortion_names.size(); ++i) {
    const EffectSpec& spec = effectSpec(result.distortion_names[i]);
    distortions.push_back({{"name", spec.name},
                           {"channel", spec.channel},
                           {"kind", spec.kind},
                           {"params", numbers(result.distortion_params[i])}});
  }
  j["distortions"] = distortions;
  j["airbag_params"] = numbers(o.airbag_params);
  j["rig_airbag_file"] = o.rig_airbag_file.empty() ? Json() : Json(o.rig_airbag_file);
  j["flow_meter"] = o.flow_meter;
  j["height_sensor"] = o.height_sensor;
  j["runs"] = runsJson(p);
  j["timing"] = {{"inflate_s", p.inflate_s},
                 {"peak_s", p.peak_s},
                 {"hold_s", p.hold_s},
                 {"vent_s", p.vent_s},
                 {"sample_hz", p.sample_hz}};
  std::ofstream out(dir / "truth.json");
  out << j.dump(2, ' ', false, Json::error_handler_t::replace) << "\n";
  if (!out) throw std::runtime_error("gap synth: cannot write " + (dir / "truth.json").string());
}

}  // namespace

std::vector<CellEffectPtr> synthDistortions(const std::vector<std::string>& texts,
                                            std::vector<SynthEffectRequest>* requests, SynthResult* result) {
  std::map<std::string, std::map<std::string, double>> planted;
  for (const auto& text : texts)
    for (const auto& [effect, params] : parseDistortion(text))
      if (!planted.emplace(effect, params).second)
        throw std::invalid_argument("gap synth: distortion '" + text + "': " + effect + " planted twice");
  std::vector<CellEffectPtr> out;
  for (const auto& [effect, params] : planted) {
    const EffectSpec& spec = effectSpec(effect);
    // A metered run records the flow, not the valves and their supply.
    if ((spec.channel == "valve_cmd" || spec.channel == "supply") && !result->protocol.valve_driven)
      throw std::invalid_argument("gap synth: the " + spec.channel +
                                  " channel is planted only on runs driven through the valves (--no-flow-meter)");
    if (spec.channel == "inflow" && result->protocol.valve_driven)
      throw std::invalid_argument(
          "gap synth: the inflow channel is planted only on metered runs (not with "
          "--no-flow-meter)");
    if (std::any_of(requests->begin(), requests->end(), [&](const SynthEffectRequest& r) { return r.name == effect; }))
      throw std::invalid_argument("gap synth: " + effect + " given both as --effect and as --distort");
    // The physical catalogue's members (pressure_sensor_lag, inflow_bias) are effects of the model.
    if (std::any_of(effectCatalog().begin(), effectCatalog().end(),
                    [&](const EffectSpec& e) { return e.name == effect; })) {
      requests->push_back({effect, params});
      continue;
    }
    out.push_back(makeEffect(effect, params));
    result->distortion_names.push_back(effect);
    result->distortion_params.push_back(params);
  }
  return out;
}

CellParams rigAirbag(const CellParams& model, const std::map<std::string, double>& differences) {
  CellParams rig = model;
  for (const auto& [name, value] : differences) {
    bool known = false;
    for (const auto& d : calibrationCatalog())
      if (d.name == name) {
        rig = applyCalibration({{name, value}}, rig);
        known = true;
      }
    for (const auto& f : cellParamFields())
      if (f.key == name) {
        f.set(rig, value);
        known = true;
      }
    if (!known)
      throw std::invalid_argument("airbag parameter '" + name +
                                  "' is neither a calibration parameter nor a key of the parameter file");
  }
  const std::string problem = rig.validate();
  if (!problem.empty()) throw std::invalid_argument("the rig's airbag parameters are invalid: " + problem);
  return rig;
}

CellParams rigBase(const SynthOptions& o) {
  if (o.rig_airbag_file.empty()) return o.params;
  try {
    return loadCellParamsYaml(o.rig_airbag_file);
  } catch (const std::exception& e) {
    throw std::invalid_argument("the rig's airbag file " + o.rig_airbag_file + ": " + e.what());
  }
}

SynthResult synthesizeDataset(const SynthOptions& o) {
  if (o.out_dir.empty()) throw std::invalid_argument("gap synth: an output directory is required");
  if (!(o.noise_scale >= 0.0) || !std::isfinite(o.noise_scale))
    throw std::invalid_argument("gap synth: noise scale must be a finite number >= 0, got " +
                                shortNumber(o.noise_scale));
  SynthResult result;
  // The protocol (its inflow masses) is planned on the model's file with the differences; a rig
  // on its own file (rig_airbag_file) gets the same protocol, as a rig would.
  const CellParams planned = rigAirbag(o.params, o.airbag_params);
  const CellParams rig = o.rig_airbag_file.empty() ? planned : rigAirbag(rigBase(o), o.airbag_params);
  result.protocol = synthProtocol(o.protocol, planned);
  for (const std::string& text : o.extra_runs) {
    SynthRunPlan extra = parseRunPlan(text, planned);
    for (const auto& r : result.protocol.runs)
      if (r.name == extra.name)
        throw std::invalid_argument("gap synth: run '" + text + "' is the protocol's " + r.name + " already");
    result.protocol.runs.push_back(extra);
  }
  result.protocol.valve_driven = !o.flow_meter;
  std::vector<CellEffectPtr> effects;
  std::vector<SynthEffectRequest> requests = o.effects;
  const std::vector<CellEffectPtr> distortions = synthDistortions(o.distortions, &requests, &result);
  resolveSynthEffects(requests, o.seed, &result.effect_names, &result.effect_params, &effects);
  effects.insert(effects.end(), distortions.begin(), distortions.end());

  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) throw std::runtime_error("gap synth: cannot create " + o.out_dir + ": " + ec.message());
  const fs::path dir(o.out_dir);
  const SensorNoise noise = SensorNoise{}.scaled(o.noise_scale);
  if (o.progress) sayProtocol(o, result);
  for (std::size_t k = 0; k < result.protocol.runs.size(); ++k) {
    const SynthRunPlan& plan = result.protocol.runs[k];
    std::seed_seq seq{o.seed, static_cast<std::uint32_t>(k), 0x5eedu};
    std::mt19937 rng(seq);
    RunData run = simulateSynthRun(rig, effects, result.protocol, plan, noise, &rng, o.airbag_name);
    if (!o.height_sensor) run.h_m.assign(run.size(), std::numeric_limits<double>::quiet_NaN());
    run.role = plan.role;
    const fs::path file = dir / plan.name;
    writeRunCsv(file.string(), run);
    run.source = file.string();
    if (o.progress) sayRun(o, result, k, run);
    result.runs.push_back(std::move(run));
  }
  writeDatasetYaml(o, result, dir);
  writeTruthJson(o, result, noise, dir);
  if (o.progress)
    *o.progress << "gap synth: wrote " << result.runs.size() << " runs, dataset.yaml and truth.json to " << o.out_dir
                << "\n";
  return result;
}

std::vector<CellEffectPtr> effectsFromText(const std::string& text, std::uint32_t seed) {
  std::vector<SynthEffectRequest> requests;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find(';', start);
    if (end == std::string::npos) end = text.size();
    std::string item = text.substr(start, end - start);
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (!item.empty()) requests.push_back(parseEffectRequest(item));
    start = end + 1;
  }
  std::vector<std::string> names;
  std::vector<std::map<std::string, double>> params;
  std::vector<CellEffectPtr> effects;
  resolveSynthEffects(requests, seed, &names, &params, &effects);
  return effects;
}

}  // namespace nursing_bed
