// gap SUBCOMMAND ...: the sim-to-real gap tools. Each subcommand's options are defined once with
// CLI11 (its --help is generated from them) and its run returns the exit code (0 ok, 1 failure
// while running, 2 bad command line). `gap synth` writes a synthetic dataset
// (doc/gap_effects.md); `gap diagnose` diagnoses a dataset (doc/gap_diagnosis.md); `gap import`
// turns logs of other formats into a dataset (doc/gap_import.md).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <glog/logging.h>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/distortions.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/log_import.h"
#include "nursing_bed/core/gap/paper_study.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/ros/bag_runs.h"
#include "tool_cli.h"

namespace nb = nursing_bed;

namespace {

namespace tools = nursing_bed::tools;
using tools::UsageError;

std::string calibrationParamText() {
  std::string s;
  for (const auto& d : nb::calibrationCatalog())
    s += "  " + d.name + " [" + d.unit + "]" + (d.valve_driven_only ? " (valve-driven runs)" : "") + ": " +
         d.description + "\n";
  return s;
}

std::string effectList() {
  std::string s;
  for (const auto& e : nb::effectCatalog()) {
    s += "  " + e.name + (e.candidate ? "" : " (not a candidate)") + ":";
    for (const auto& p : e.params) s += " " + p.name;
    s += "\n";
  }
  return s;
}

std::string distortionList() {
  std::string s;
  for (const auto& m : nb::distortionMembers()) {
    const nb::EffectParamSpec* p = nb::effectSpec(m.effect).param(m.param);  // the kind's parameter
    std::ostringstream line;
    line << "  " << m.channel << ":" << m.kind << "=VALUE [" << p->unit << "], plausible " << p->lo << " .. " << p->hi
         << (p->log_scale ? " (log)" : "") << ", admissible " << p->min_value << " .. " << p->max_value << "\n";
    s += line.str();
  }
  return s;
}

double parseNumber(const std::string& option, const std::string& text) {
  double v = 0.0;
  const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || r.ec != std::errc() || r.ptr != text.data() + text.size() || !std::isfinite(v))
    throw UsageError(option + ": expected a number, got '" + text + "'");
  return v;
}

/// `gap synth`'s options as given; checked by synthOptions.
struct SynthArgs {
  std::string out_dir, seed = "1", noise_scale = "1", protocol = "standard", rig_airbag;
  std::vector<std::string> effects, distortions, airbag_params, extra_runs;
  bool no_flow_meter = false, no_height = false;
};

constexpr const char* kSynthSynopsis =
    "usage: gap synth --out DIR [--effect NAME[:param=value,...]]... [--distort CHANNEL:KIND=VALUE]...\n"
    "                 [--seed N]\n"
    "                 [--noise-scale S] [--protocol standard|small] [--airbag-param NAME=VALUE]...\n"
    "                 [--rig-airbag FILE]\n"
    "                 [--no-flow-meter] [--no-height] [--add-run load_n=N,flow=low|high[,rise_scale=K]]...\n"
    "Simulates the run-data protocol (paper-shaped inflow, 60 s hold with the inlet closed,\n"
    "10 s vent through the inlet) on the cell model with the given 'truth' effects and\n"
    "realistic sensors, and writes DIR/<run>.csv, DIR/dataset.yaml and DIR/truth.json.";

void defineSynth(CLI::App& sub, SynthArgs* a) {
  sub.add_option("--out", a->out_dir, "output directory (created)")->type_name("DIR");
  tools::takeAll(sub.add_option("--effect", a->effects,
                                "a truth effect, repeatable; parameters not given are drawn from the seed within "
                                "their plausible range (e.g. --effect leak:leak_area_m2=1e-8)"))
      ->type_name("NAME[:param=value,...]");
  tools::takeAll(sub.add_option("--distort", a->distortions,
                                "a channel distortion, repeatable: pressure, height, load, inflow (metered runs), "
                                "valve_cmd or supply (with --no-flow-meter) with gain, offset, drift, shift or lag "
                                "(e.g. --distort height:gain=-0.04)"))
      ->type_name("CHANNEL:KIND=VALUE[,KIND=VALUE]");
  sub.add_option("--seed", a->seed, "random seed for drawn parameters and noise")->type_name("N");
  sub.add_option("--noise-scale", a->noise_scale, "multiplies every sensor noise and quantisation step (0: exact)")
      ->type_name("S");
  sub.add_option("--protocol", a->protocol,
                 "standard: 4 loads x 2 flows, 75.5 s at 100 Hz; small: 2 loads x 2 flows, 30 s hold, 50 Hz "
                 "(for CI)")
      ->type_name("standard|small");
  tools::takeAll(sub.add_option("--airbag-param", a->airbag_params,
                                "the rig's airbag differs from the model's file: a calibration parameter (gap "
                                "calibrate --help) or a key of the file, e.g. film_stiffness_scale=1.15, "
                                "structure/gusset_height_m=0.081 (repeatable; recorded in truth.json)"))
      ->type_name("NAME=VALUE");
  sub.add_option("--rig-airbag", a->rig_airbag,
                 "the rig runs on this parameter file (another structure, e.g. config/airbag_tpu_double_100_fe.yaml, "
                 "the FE table) while the dataset names the model's own; --airbag-param applies on top (recorded in "
                 "truth.json)")
      ->type_name("FILE");
  sub.add_flag(
      "--no-flow-meter", a->no_flow_meter,
      "runs driven through the valves: valve_cmd and p_supply_gauge_pa, no mdot_in_kg_s (doc/formats/run_data.md)");
  sub.add_flag("--no-height", a->no_height, "no height sensor: h_m left out");
  tools::takeAll(sub.add_option("--add-run", a->extra_runs,
                                "a run added to the protocol's, repeatable (gap diagnose proposes them where two "
                                "explanations fit alike): load in N, flow low or high, the rise rise_scale times "
                                "as long, role fit (default) or withheld"))
      ->type_name("load_n=N,flow=low|high[,rise_scale=K][,role=fit|withheld]");
  // The distortions first: scripts read the effects from "effects and their parameters:" on.
  sub.footer("distortions (--distort; diagnosed as the candidates <channel>_<kind>):\n" + distortionList() +
             "effects and their parameters:\n" + effectList());
}

/// The synthesis options from the command line; a UsageError naming the option when a value is
/// bad, an effect or airbag parameter unknown or out of range (before anything is written).
nb::SynthOptions synthOptions(const SynthArgs& a) {
  nb::SynthOptions o;
  o.progress = &std::cout;
  if (a.out_dir.empty()) throw UsageError("--out DIR is required");
  o.out_dir = a.out_dir;
  for (const std::string& v : a.effects) {
    try {
      o.effects.push_back(nb::parseEffectRequest(v));
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--effect ") + v + ": " + e.what());
    }
  }
  for (const std::string& v : a.distortions) {
    try {
      nb::parseDistortion(v);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--distort: ") + e.what());
    }
    o.distortions.push_back(v);
  }
  const double seed = parseNumber("--seed", a.seed);
  if (seed < 0.0 || seed > 4294967295.0 || seed != std::floor(seed))
    throw UsageError("--seed: expected a whole number 0..4294967295, got '" + a.seed + "'");
  o.seed = static_cast<std::uint32_t>(seed);
  o.noise_scale = parseNumber("--noise-scale", a.noise_scale);
  if (o.noise_scale < 0.0) throw UsageError("--noise-scale: expected a number >= 0, got '" + a.noise_scale + "'");
  for (const std::string& v : a.airbag_params) {
    const auto kv = tools::splitKeyValue(v);
    if (!kv) throw UsageError("--airbag-param: expected NAME=VALUE, got '" + v + "'");
    o.airbag_params[kv->first] = parseNumber("--airbag-param " + kv->first, kv->second);
  }
  o.rig_airbag_file = a.rig_airbag;
  o.flow_meter = !a.no_flow_meter;
  o.height_sensor = !a.no_height;
  for (const std::string& v : a.extra_runs) {
    try {
      nb::parseRunPlan(v, o.params);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--add-run: ") + e.what());
    }
    o.extra_runs.push_back(v);
  }
  o.protocol = a.protocol;
  if (o.protocol != "standard" && o.protocol != "small")
    throw UsageError("--protocol: expected standard or small, got '" + o.protocol + "'");
  return o;
}

int runSynth(const SynthArgs& args) {
  const nb::SynthOptions o = synthOptions(args);
  nb::CellParams rig_base;
  try {
    rig_base = nb::rigBase(o);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("--rig-airbag: ") + e.what());
  }
  try {
    nb::rigAirbag(rig_base, o.airbag_params);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("--airbag-param: ") + e.what());
  }
  // Resolve (draw and check) the effects before anything is simulated or written, so that a
  // bad parameter value is a command-line error.
  {
    std::vector<std::string> names;
    std::vector<std::map<std::string, double>> params;
    std::vector<nb::CellEffectPtr> effects;
    try {
      nb::resolveSynthEffects(o.effects, o.seed, &names, &params, &effects);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--effect: ") + e.what());
    }
    std::vector<nb::SynthEffectRequest> requests = o.effects;
    nb::SynthResult planned;
    planned.protocol.valve_driven = !o.flow_meter;
    try {
      nb::synthDistortions(o.distortions, &requests, &planned);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--distort: ") + e.what());
    }
  }
  nb::synthesizeDataset(o);
  return 0;
}

constexpr const char* kDiagnoseSynopsis =
    "usage: gap diagnose DATASET --out DIR [--topic TOPIC] [--effects NAME,NAME...] [--threads N]\n"
    "                    [--params NAME,...] [--no-calibration] [--no-discovery] [--no-proposals]\n"
    "                    [--airbag FILE] [--no-plots]\n"
    "                    [--verbose]\n"
    "Replays every run of DATASET (a directory of run CSVs and/or bags, optional dataset.yaml)\n"
    "through the nominal cell model, localises the gap, fits every candidate effect (and pairs)\n"
    "on the fit runs, names the effect that explains the gap (or says none / unexplained) and\n"
    "checks it on the withheld runs; a gap no effect explains gets a discovered correction to the\n"
    "balance equations where the withheld runs confirm one. Writes DIR/report.json, DIR/report.md, DIR/traces/*.csv "
    "and\n"
    "the plots DIR/traces.png, residual_by_phase.png, hp_loops.png.";

/// Runs of a dataset directory: CSVs, bags and dataset.yaml.
std::vector<nb::RunData> readDatasetWithBags(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw std::runtime_error(dir + ": not a directory (expected a dataset directory)");
  std::vector<std::string> bags;
  for (const auto& entry : fs::directory_iterator(dir, ec))
    if (entry.path().extension() == ".bag") bags.push_back(entry.path().string());
  if (ec) throw std::runtime_error(dir + ": cannot list: " + ec.message());
  std::sort(bags.begin(), bags.end());
  std::vector<nb::RunData> extra;
  for (const auto& b : bags) {
    auto runs = nb::readRunsFromBag(b);
    extra.insert(extra.end(), runs.begin(), runs.end());
  }
  return nb::readDataset(dir, extra);
}

/// The bag runs recorded from `topic`; a bed bag holds one run per cell, and each cell is a
/// dataset of its own.
std::vector<nb::RunData> runsOfTopic(std::vector<nb::RunData> runs, const std::string& topic,
                                     const std::string& dataset) {
  std::vector<nb::RunData> kept;
  std::set<std::string> topics;
  for (auto& r : runs) {
    const auto it = r.meta.find("topic");
    if (it == r.meta.end()) continue;
    topics.insert(it->second);
    if (it->second == topic) kept.push_back(std::move(r));
  }
  if (kept.empty()) {
    std::string list;
    for (const auto& t : topics) list += " " + t;
    throw std::runtime_error(dataset + ": no bag run has the topic '" + topic +
                             "' (topics:" + (list.empty() ? std::string(" none, no bags") : list) + ")");
  }
  return kept;
}

/// "a,b,c" as a list (duplicates dropped); each name checked by `check`, which throws a
/// UsageError naming the option.
std::vector<std::string> nameList(const std::string& option, const std::string& v,
                                  const std::function<void(const std::string&)>& check) {
  std::vector<std::string> names;
  std::set<std::string> seen;
  std::size_t start = 0;
  while (start <= v.size()) {
    const std::size_t comma = std::min(v.find(',', start), v.size());
    const std::string name = v.substr(start, comma - start);
    if (name.empty()) throw UsageError(option + ": empty name in '" + v + "'");
    check(name);
    if (seen.insert(name).second) names.push_back(name);
    start = comma + 1;
  }
  return names;
}

std::vector<std::string> calibrationParamList(const std::string& v) {
  return nameList("--params", v, [](const std::string& name) {
    try {
      nb::calibrationParam(name);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--params: ") + e.what());
    }
  });
}

/// Runs of a dataset (or one topic of its bags) and the one airbag parameter file they name.
std::vector<nb::RunData> datasetRuns(const std::string& dataset, const std::string& topic, std::string* airbag) {
  std::vector<nb::RunData> runs = readDatasetWithBags(dataset);
  if (!topic.empty()) runs = runsOfTopic(std::move(runs), topic, dataset);
  std::set<std::string> airbags;
  for (const auto& r : runs) airbags.insert(nb::resolveAirbagParamsFile(r.airbag, dataset));
  if (airbags.size() != 1) {
    std::string list;
    for (const auto& a : airbags) list += " " + a;
    throw std::runtime_error(dataset + ": runs name different airbag parameter sets (" + list.substr(1) +
                             "); diagnose each airbag's runs as a dataset of its own");
  }
  *airbag = *airbags.begin();
  return runs;
}

/// Options both calibrate and diagnose take, as given; checked by analysisOptions.
struct AnalysisArgs {
  std::vector<std::string> datasets;  ///< exactly one, checked after parsing (named in the error)
  std::string out_dir, topic, airbag_override, params, threads = "2", effects, model_floor = "auto";
  bool no_plots = false, no_calibration = false, no_discovery = false, no_proposals = false, verbose = false;
};

/// The checked common options.
struct CommonOptions {
  std::string dataset, out_dir, topic, airbag_override;
  bool plots = true;
};

void defineCommon(CLI::App& sub, AnalysisArgs* a) {
  tools::takeAll(sub.add_option("DATASET", a->datasets, "a directory of run CSVs and/or bags, optional dataset.yaml"));
  sub.add_option("--out", a->out_dir, "output directory (created)")->type_name("DIR");
  sub.add_option("--topic", a->topic,
                 "diagnose only the bag runs of this AirbagState topic (one cell of a bed bag); CSV runs are "
                 "left out then")
      ->type_name("TOPIC");
  sub.add_option("--params", a->params,
                 "model parameters to calibrate first (gap calibrate --help; default: those the runs can tell)")
      ->type_name("NAME,...");
  sub.add_option("--airbag", a->airbag_override, "the nominal parameter file (default: the one the dataset names)")
      ->type_name("FILE");
  sub.add_option("--threads", a->threads, "threads for the fits: candidates and their replays in parallel")
      ->type_name("N");
  sub.add_flag("--no-plots", a->no_plots, "skip the PNG plots (they need /usr/bin/python3 with matplotlib)");
  sub.add_flag("--verbose", a->verbose, "each fit's progress line also gives its replays and the solver's report");
  sub.add_flag("--no-proposals", a->no_proposals,
               "do not look for what the runs cannot tell apart, nor propose the run that would");
}

/// The common options checked, and the diagnosis options they set; a UsageError naming the
/// option otherwise.
CommonOptions analysisOptions(const AnalysisArgs& a, nb::DiagnosisOptions* options) {
  if (a.datasets.size() > 1)
    throw UsageError("one DATASET only, got '" + a.datasets[0] + "' and '" + a.datasets[1] + "'");
  CommonOptions c;
  c.dataset = a.datasets.empty() ? "" : a.datasets[0];
  c.out_dir = a.out_dir;
  c.topic = a.topic;
  c.airbag_override = a.airbag_override;
  c.plots = !a.no_plots;
  if (!a.params.empty()) options->calibration_params = calibrationParamList(a.params);
  const double t = parseNumber("--threads", a.threads);
  if (t < 1 || t > 64 || t != std::floor(t))
    throw UsageError("--threads: expected a whole number 1..64, got '" + a.threads + "'");
  options->threads = static_cast<int>(t);
  options->verbose = a.verbose;
  options->propose_runs = !a.no_proposals;
  if (c.dataset.empty()) throw UsageError("DATASET (a directory of runs) is required");
  if (c.out_dir.empty()) throw UsageError("--out DIR is required");
  return c;
}

/// Reads the dataset and its airbag (or --airbag FILE), runs `analyse`, writes the report (and
/// the calibrated parameter file), plots, prints the verdict.
int analyseDataset(const CommonOptions& c, nb::DiagnosisOptions options, const char* name,
                   nb::DiagnosisReport (*analyse)(std::vector<nb::RunData>, const nb::CellParams&,
                                                  const nb::DiagnosisOptions&, const std::string&)) {
  std::string airbag;
  std::vector<nb::RunData> runs = datasetRuns(c.dataset, c.topic, &airbag);
  if (!c.airbag_override.empty()) airbag = c.airbag_override;
  const nb::CellParams params = nb::loadCellParamsYaml(airbag);
  std::cout << "gap " << name << ": " << runs.size() << " runs from " << c.dataset << ", airbag " << airbag << "\n";
  options.progress = [](const std::string& line) { std::cout << "  " << line << std::endl; };
  options.status = [name](const std::string& line) { std::cerr << "gap " << name << ": " << line << std::endl; };
  const nb::DiagnosisReport report = analyse(runs, params, options, c.dataset);
  nb::writeReportFiles(c.out_dir, report);
  std::cout << "wrote " << c.out_dir << "/report.json, report.md, " << report.calibration.file << ", traces/\n";
  if (c.plots) {
    const std::string script = nb::findPackageFile("scripts/plot_gap_report.py");
    const std::string command = "/usr/bin/python3 '" + script + "' '" + c.out_dir + "'";
    if (std::system(command.c_str()) != 0)
      std::cerr << "gap " << name << ": the plots failed (" << command << "); the report itself is complete\n";
  }
  std::cout << "verdict: " << report.status;
  for (const auto& e : report.verdict_effects) std::cout << " " << e;
  for (const auto& [k, v] : report.calibration.movedValues()) std::cout << " " << k << "=" << v;
  std::cout << "\n";
  return 0;
}

constexpr const char* kCalibrateSynopsis =
    "usage: gap calibrate DATASET --out DIR [--params NAME,NAME...] [--airbag FILE] [--topic TOPIC]\n"
    "                     [--threads N] [--no-plots] [--verbose] [--no-proposals]\n"
    "Fits the model's own uncertain parameters on the fit runs of DATASET (the effects are not\n"
    "looked for) and writes DIR/calibrated_airbag.yaml (a complete parameter file: sim.launch\n"
    "cell_params:=..., the nodes and gap diagnose --airbag accept it), DIR/report.json (the\n"
    "calibration block: value, standard error, correlations, what the runs cannot tell apart),\n"
    "DIR/report.md, DIR/traces/*.csv and plots. --params defaults to those of the structure:\n"
    "film_stiffness_scale, gusset_height_m, dead_volume_m3, plate_mass_kg for the pillow;\n"
    "compliance_m3_pa, dead_volume_m3, plate_damping_n_s_m for a bellows; the airway's resistances\n"
    "when the parameter file has an airway (its linear one then instead of the plate's damping);\n"
    "plus inlet_area_m2, vent_area_m2, regulator_time_constant_s for runs driven through the valves.";

int runCalibrate(const AnalysisArgs& a) {
  nb::DiagnosisOptions options;
  const CommonOptions c = analysisOptions(a, &options);
  return analyseDataset(c, options, "calibrate", nb::calibrateRuns);
}

void defineDiagnose(CLI::App& sub, AnalysisArgs* a) {
  defineCommon(sub, a);
  sub.add_option("--effects", a->effects,
                 "candidates to try, comma-separated (default: all seven and the channel "
                 "distortions of the runs' channels)")
      ->type_name("NAME,NAME...");
  sub.add_flag("--no-calibration", a->no_calibration, "effects on top of the nominal model only");
  sub.add_flag("--no-discovery", a->no_discovery, "an unexplained gap stays unexplained (no dictionary terms)");
  sub.add_option("--model-floor", a->model_floor,
                 "judge candidates above the calibrated model's floor when it never fits to the noise: auto (runs "
                 "imported from recordings), on, off")
      ->check(CLI::IsMember({"auto", "on", "off"}));
}

int runDiagnose(const AnalysisArgs& a) {
  nb::DiagnosisOptions options;
  const CommonOptions c = analysisOptions(a, &options);
  options.calibrate = !a.no_calibration;
  options.discover = !a.no_discovery;
  options.model_floor = a.model_floor;
  if (!a.effects.empty())
    options.candidates = nameList("--effects", a.effects, [](const std::string& name) {
      auto known = nb::candidateEffectNames();
      for (const auto& e : nb::distortionCatalog()) known.push_back(e.name);
      if (std::find(known.begin(), known.end(), name) == known.end())
        throw UsageError("--effects: '" + name + "' is not a candidate effect; candidates:\n" + effectList());
    });
  return analyseDataset(c, options, "diagnose", nb::diagnoseRuns);
}

constexpr const char* kEq24Synopsis =
    "usage: gap eq24 [--out FILE]\n"
    "The paper's eq. 24 curve (x read as bar) as measured quasi-static h(p) at its 10.4 N load:\n"
    "where the nominal model departs from it, what each candidate effect changes, and the guide\n"
    "friction that would be needed. Prints markdown (and writes it to FILE).";

int runEq24(const std::string& out) {
  const nb::CellParams params = nb::loadCellParamsYaml(nb::resolveAirbagParamsFile(""));
  const std::string text = nb::paperStudyMarkdown(nb::studyPaperEq24(params));
  std::cout << text;
  if (!out.empty()) {
    std::ofstream f(out);
    f << text;
    if (!f) throw std::runtime_error(out + ": cannot write");
  }
  return 0;
}

constexpr const char* kImportSynopsis =
    "usage: gap import MAPPING LOG... --out DIR\n"
    "Reads logs of another format with a column-mapping file (doc/formats/import_mapping.md):\n"
    "units (detected where the mapping gives candidates), derived flows, runs of whole cycles,\n"
    "fit/withheld roles; writes DIR/<run>.csv and DIR/dataset.yaml. Everything is checked first:\n"
    "a malformed log is named with its line and column, and nothing is written.";

struct ImportArgs {
  std::vector<std::string> inputs;  ///< MAPPING then the LOGs
  std::string out;
};

void defineImport(CLI::App& sub, ImportArgs* a) {
  tools::takeAll(sub.add_option("MAPPING LOG", a->inputs,
                                "the mapping file (e.g. config/import/respiraworks_net_flow.yaml), then one or "
                                "more log files"))
      ->type_name("FILE");
  sub.add_option("--out", a->out, "output directory (created; must not exist or be empty)")->type_name("DIR");
}

int runImport(const ImportArgs& a) {
  if (a.inputs.empty()) throw UsageError("MAPPING (a column-mapping file) is required");
  if (a.inputs.size() < 2) throw UsageError("at least one LOG is required");
  if (a.out.empty()) throw UsageError("--out DIR is required");
  const nb::ImportMapping mapping = nb::loadImportMapping(a.inputs.front());
  const std::vector<std::string> logs(a.inputs.begin() + 1, a.inputs.end());
  const std::vector<nb::ImportedLog> imported = nb::importLogsToDataset(mapping, logs, a.out);
  std::size_t runs = 0;
  for (const auto& log : imported) {
    for (const auto& note : log.notes) std::cout << note << "\n";
    for (const auto& r : log.runs)
      std::cout << "  " << r.name << "  " << r.size() << " samples, " << r.t_s.front() << "-" << r.t_s.back() << " s"
                << (r.role.empty() ? "" : ", " + r.role) << "\n";
    runs += log.runs.size();
  }
  std::cout << "wrote " << runs << " runs from " << imported.size() << " logs to " << a.out << "\n";
  return 0;
}

constexpr const char* kSynopsis =
    "usage: gap SUBCOMMAND [options]   (gap SUBCOMMAND --help for its options)\n"
    "Sim-to-real gap diagnosis of the airbag cell model.";

/// Every subcommand's arguments, filled by CLI11.
struct GapArgs {
  SynthArgs synth;
  AnalysisArgs calibrate, diagnose;
  std::string eq24_out;
  ImportArgs import;
};

/// The subcommands, each with its options and what runs it.
std::vector<std::pair<CLI::App*, std::function<int()>>> defineSubcommands(CLI::App& app, GapArgs* a) {
  CLI::App* synth = app.add_subcommand("synth", "write a synthetic dataset with planted effects");
  tools::setSynopsis(*synth, kSynthSynopsis);
  defineSynth(*synth, &a->synth);
  CLI::App* calibrate = app.add_subcommand("calibrate", "calibrate the model's own parameters on a dataset");
  tools::setSynopsis(*calibrate, kCalibrateSynopsis);
  defineCommon(*calibrate, &a->calibrate);
  calibrate->footer("parameters:\n" + calibrationParamText());
  CLI::App* diagnose = app.add_subcommand("diagnose", "diagnose the gap between a dataset of runs and the model");
  tools::setSynopsis(*diagnose, kDiagnoseSynopsis);
  defineDiagnose(*diagnose, &a->diagnose);
  CLI::App* eq24 = app.add_subcommand("eq24", "the paper's eq. 24 curve as data: where the model departs");
  tools::setSynopsis(*eq24, kEq24Synopsis);
  eq24->add_option("--out", a->eq24_out, "also write the markdown to FILE")->type_name("FILE");
  CLI::App* import = app.add_subcommand("import", "turn logs of another format into a dataset with a mapping file");
  tools::setSynopsis(*import, kImportSynopsis);
  defineImport(*import, &a->import);
  return {{synth, [a] { return runSynth(a->synth); }},
          {calibrate, [a] { return runCalibrate(a->calibrate); }},
          {diagnose, [a] { return runDiagnose(a->diagnose); }},
          {eq24, [a] { return runEq24(a->eq24_out); }},
          {import, [a] { return runImport(a->import); }}};
}

/// The subcommand named on the command line; a UsageError when there is none or it is unknown.
const CLI::App* chosenSubcommand(const CLI::App& app) {
  const std::vector<CLI::App*> chosen = app.get_subcommands();
  if (!chosen.empty()) return chosen.front();
  const std::vector<std::string> extras = app.remaining();
  if (extras.empty()) throw UsageError("missing subcommand");
  throw UsageError("unknown subcommand '" + extras.front() + "'");
}

/// "gap" or "gap SUBCOMMAND", as messages are prefixed.
std::string messagePrefix(const CLI::App& app) {
  const std::vector<CLI::App*> chosen = app.get_subcommands();
  return chosen.empty() ? "gap" : "gap " + chosen.front()->get_name();
}

}  // namespace

int main(int argc, char** argv) {
  // Ceres logs an error when a replay fails inside a step; the fit takes that as a refused step.
  FLAGS_minloglevel = google::GLOG_FATAL;
  CLI::App app(kSynopsis, "gap");
  tools::configureApp(app);
  GapArgs args;
  const auto subcommands = defineSubcommands(app, &args);
  if (argc == 2 && std::string(argv[1]) == "help") {
    std::cout << app.help();
    return 0;
  }
  const CLI::App* sub = nullptr;
  try {
    app.parse(argc, argv);
    sub = chosenSubcommand(app);
    tools::checkNoExtras(app);
  } catch (const CLI::CallForHelp&) {
    std::cout << app.help();
    return 0;
  } catch (const CLI::ParseError& e) {
    return tools::reportMistake(app, messagePrefix(app), tools::mistakeText(e));
  } catch (const UsageError& e) {
    return tools::reportMistake(app, messagePrefix(app), e.what());
  }
  const std::string name = messagePrefix(app);
  for (const auto& [command, run] : subcommands) {
    if (command != sub) continue;
    try {
      return run();
    } catch (const UsageError& e) {
      return tools::reportMistake(app, name, e.what());
    } catch (const std::exception& e) {
      std::cerr << name << ": " << e.what() << "\n";
      return 1;
    }
  }
  return 1;
}
