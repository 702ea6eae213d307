// Synthetic datasets for the gap diagnosis: the run-data protocol (inflate with the paper-shaped
// flow, hold closed, vent through the inlet) simulated on the cell model with planted "truth"
// effects and realistic sensors, written in the run-data format. `gap synth` is its CLI;
// doc/gap_effects.md describes protocol, noise and files.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// An effect requested on the command line: NAME[:param=value,...]. Parameters not given are
/// drawn by randomEffectParams() from the seed.
struct SynthEffectRequest {
  std::string name;
  std::map<std::string, double> params;
};

/// Parses "NAME[:param=value,...]"; throws std::invalid_argument naming what is wrong (unknown
/// effect or parameter, a value that is not a number). Ranges are checked by makeEffect().
SynthEffectRequest parseEffectRequest(const std::string& text);

/// One run of a protocol.
struct SynthRunPlan {
  std::string name;              ///< file name, e.g. "load10p6N_low.csv"
  double load_n = 0.6;           ///< constant load, plate included [N]
  std::string flow;              ///< "low" or "high"
  double target_height_m = 0.0;  ///< height the injected gas holds at rest at ambient temperature
  double inflow_mass_kg = 0.0;   ///< mass the paper-shaped inflow carries
  std::string role;              ///< "fit" or "withheld"
  /// The rise takes this many times the protocol's inflate_s (and peak_s); driven through the
  /// valves, the inlet opens this many times less.
  double rise_scale = 1.0;
};

/// Timing of a protocol and its runs.
struct SynthProtocol {
  std::string name;        ///< "standard" or "small"
  double inflate_s = 5.5;  ///< paper-shaped inflow, peak at 1 s, zero at inflate_s
  double peak_s = 1.0;
  double hold_s = 60.0;  ///< inlet closed
  double vent_s = 10.0;  ///< inlet open to the supply at 0 gauge (venting through it)
  double sample_hz = 100.0;
  /// No flow meter: the inlet opens to the supply (fully for "high" runs, half for "low") until
  /// the bag holds the run's mass, the vent valve vents; runs carry valve_cmd (mean opening over
  /// each interval) and p_supply_gauge_pa instead of mdot_in_kg_s.
  bool valve_driven = false;
  std::vector<SynthRunPlan> runs;
  double durationS() const { return inflate_s + hold_s + vent_s; }
};

/**
 * "standard": loads 0.6, 10.6, 15.6, 20.6 N x two flows (the masses that hold the cell at
 * ~110 mm and ~145 mm at rest), 60 s hold, 10 s vent, 100 Hz: 8 runs, 6 fit and 2 withheld
 * (10.6 N high, 20.6 N low). "small": loads 0.6 and 15.6 N x the two flows, 30 s hold,
 * 50 Hz: 4 runs, 2 fit and 2 withheld (each flow and each load in both sets). Throws
 * std::invalid_argument for another name.
 */
SynthProtocol synthProtocol(const std::string& name, const CellParams& params);

/// One run: `load_n` with the gas that holds the cell at the flow's height at rest ("low"
/// ~110 mm, "high" ~145 mm), the rise `rise_scale` times as long, role "fit"; named
/// load<L>N_<flow>[_rise<k>].csv. Throws std::invalid_argument naming a load outside 0.1-200 N,
/// an unknown flow, a rise_scale outside 0.25-10, or a load no equilibrium holds.
SynthRunPlan synthRunPlan(const CellParams& params, double load_n, const std::string& flow, double rise_scale);

/// A run from "load_n=L,flow=low|high[,rise_scale=k][,role=fit|withheld]" (gap synth
/// --add-run; identifiability.h proposes them). Throws std::invalid_argument naming what is wrong.
SynthRunPlan parseRunPlan(const std::string& text, const CellParams& params);

/// Sensor noise: Gaussian with these standard deviations, then quantisation to these steps.
struct SensorNoise {
  double pressure_sd_pa = 30.0;
  double pressure_step_pa = 10.0;
  double height_sd_m = 0.3e-3;
  double height_step_m = 0.1e-3;
  double flow_relative_sd = 0.01;  ///< of the reading
  double flow_sd_kg_s = 5.0e-6;    ///< on top, independent
  double flow_step_kg_s = 1.0e-6;
  /// Every standard deviation and step times `factor` (0: exact readings).
  SensorNoise scaled(double factor) const;
};

/// Quantises x to multiples of step (0: unchanged); steps like 1e-4 give short decimals.
double quantise(double x, double step);

/**
 * Simulates one run on a CellModel of `params` with `effects` plugged in: paper-shaped
 * prescribed inflow until inflate_s, inlet closed for hold_s, then the inlet fully open to a
 * supply at 0 gauge (valve-driven, no regulator lag) for vent_s. Samples every 1/sample_hz:
 * the effects' measure(), then noise from `rng` (null: no noise). Columns t_s, mdot_in_kg_s,
 * p_gauge_pa, h_m and valve_cmd; metadata version, load_n, airbag, note.
 */
RunData simulateSynthRun(const CellParams& params, const std::vector<CellEffectPtr>& effects,
                         const SynthProtocol& protocol, const SynthRunPlan& plan, const SensorNoise& noise,
                         std::mt19937* rng, const std::string& airbag_name = "tpu_double_100");

struct SynthOptions {
  std::string out_dir;
  std::vector<SynthEffectRequest> effects;
  /// Channel distortions to plant, "channel:kind=value[,...]" (parseDistortion(), distortions.h):
  /// on the true readings before the noise, on the flow meter's reading and on the recorded load.
  std::vector<std::string> distortions;
  std::uint32_t seed = 1;
  double noise_scale = 1.0;
  std::string protocol = "standard";
  CellParams params;  ///< the model's airbag (the parameter file)
  /// The rig's airbag differs from `params` by these (calibration names, calibration.h, or keys
  /// of the parameter table such as "structure/film_thickness_m"); recorded in truth.json.
  std::map<std::string, double> airbag_params;
  /// The rig simulated on this parameter file (another structure, e.g. the FE table) while the
  /// model keeps `params` and the protocol is planned on it; `airbag_params` apply to both.
  /// Empty: the rig is `params`.
  std::string rig_airbag_file;
  bool flow_meter = true;     ///< false: valve-driven runs without mdot_in_kg_s (SynthProtocol::valve_driven)
  bool height_sensor = true;  ///< false: h_m left out (pressure sensors only)
  /// Runs added to the protocol's (parseRunPlan(): "load_n=36,flow=high,rise_scale=3").
  std::vector<std::string> extra_runs;
  std::string airbag_name = "tpu_double_100";              ///< written to the runs' metadata
  std::string airbag_file = "airbag_tpu_double_100.yaml";  ///< written to dataset.yaml
  std::ostream* progress = nullptr;                        ///< one line per run when set
};

struct SynthResult {
  std::vector<std::string> effect_names;                     ///< catalogue order
  std::vector<std::map<std::string, double>> effect_params;  ///< the truth, per effect
  /// Planted channel distortions of the distortion catalogue (members of the effect catalogue,
  /// pressure_sensor_lag and inflow_bias, are among the effects).
  std::vector<std::string> distortion_names;
  std::vector<std::map<std::string, double>> distortion_params;
  std::vector<RunData> runs;
  SynthProtocol protocol;
};

/// The truth effects of a request: missing parameters drawn from `seed`, checked by
/// makeEffect(), in catalogue order (so measure() compositions are canonical). Throws
/// std::invalid_argument naming a bad effect or parameter, or an effect given twice.
void resolveSynthEffects(const std::vector<SynthEffectRequest>& requests, std::uint32_t seed,
                         std::vector<std::string>* names, std::vector<std::map<std::string, double>>* params,
                         std::vector<CellEffectPtr>* effects);

/// The channel distortions of `texts` (parseDistortion(), distortions.h): the physical
/// catalogue's members (pressure:lag, inflow:gain/offset) appended to `requests` as effects, the
/// others returned (ChannelDistortionEffect) and recorded in `result`. Throws
/// std::invalid_argument naming a bad spec, a distortion planted twice or given as an effect
/// too, or a channel the runs do not have (valve_cmd and supply only on valve-driven runs,
/// inflow only on metered ones).
std::vector<CellEffectPtr> synthDistortions(const std::vector<std::string>& texts,
                                            std::vector<SynthEffectRequest>* requests, SynthResult* result);
/// Effects from a list "NAME[:param=value,...][;NAME...]" (empty: none), parameters not given
/// drawn from `seed`, checked, in catalogue order: how a simulated cell is given a hidden
/// effect (the airbag node's ~effects). Throws std::invalid_argument naming what is wrong.
std::vector<CellEffectPtr> effectsFromText(const std::string& text, std::uint32_t seed);

/// The rig's parameters before SynthOptions::airbag_params: the file `o.rig_airbag_file`
/// names, else `o.params`. Throws std::invalid_argument naming a file that cannot be read.
CellParams rigBase(const SynthOptions& o);

/// The rig's airbag: `model` with `differences` (see SynthOptions::airbag_params) applied.
/// Throws std::invalid_argument naming an unknown name or a result that fails validate().
CellParams rigAirbag(const CellParams& model, const std::map<std::string, double>& differences);

/**
 * Generates a dataset: DIR/<run>.csv, DIR/dataset.yaml (airbag and roles) and DIR/truth.json
 * (effects with their parameters, seed, noise scale, protocol; the diagnosis never reads it).
 * Creates DIR. Throws std::invalid_argument for bad options and std::runtime_error when
 * writing fails.
 */
SynthResult synthesizeDataset(const SynthOptions& options);

}  // namespace nursing_bed
