// gap SUBCOMMAND ...: the sim-to-real gap tools. Subcommands are entries of kSubcommands; each
// parses its own options and returns the exit code (0 ok, 1 failure while running, 2 bad
// command line). `gap synth` writes a synthetic dataset (doc/gap_effects.md); `gap diagnose`
// diagnoses a dataset (doc/gap_diagnosis.md); `gap import` turns logs of other formats into a
// dataset (doc/gap_import.md).
#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <filesystem>
#include <functional>
#include <fstream>
#include <set>

#include <glog/logging.h>

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/log_import.h"
#include "nursing_bed/core/gap/paper_study.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/ros/bag_runs.h"

namespace nb = nursing_bed;

namespace {

/// A command-line mistake: printed with the usage, exit code 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Subcommand {
  const char* name;
  const char* summary;
  const char* usage;
  int (*run)(const std::vector<std::string>& args);
};

constexpr const char* kSynthUsage =
    "usage: gap synth --out DIR [--effect NAME[:param=value,...]]... [--seed N]\n"
    "                 [--noise-scale S] [--protocol standard|small] [--airbag-param NAME=VALUE]...\n"
    "                 [--no-flow-meter] [--no-height]\n"
    "Simulates the run-data protocol (paper-shaped inflow, 60 s hold with the inlet closed,\n"
    "10 s vent through the inlet) on the cell model with the given 'truth' effects and\n"
    "realistic sensors, and writes DIR/<run>.csv, DIR/dataset.yaml and DIR/truth.json.\n"
    "  --out          output directory (created)\n"
    "  --effect       a truth effect, repeatable; parameters not given are drawn from the seed\n"
    "                 within their plausible range (e.g. --effect leak:leak_area_m2=1e-8)\n"
    "  --seed         random seed for drawn parameters and noise (default 1)\n"
    "  --noise-scale  multiplies every sensor noise and quantisation step (default 1; 0: exact)\n"
    "  --protocol     standard: 4 loads x 2 flows, 75.5 s at 100 Hz (default);\n"
    "                 small: 2 loads x 2 flows, 30 s hold, 50 Hz (for CI)\n"
    "  --airbag-param the rig's airbag differs from the model's file: a calibration parameter\n"
    "                 (gap calibrate --help) or a key of the file, e.g. film_stiffness_scale=1.15,\n"
    "                 structure/gusset_height_m=0.081 (repeatable; recorded in truth.json)\n"
    "  --no-flow-meter runs driven through the valves: valve_cmd and p_supply_gauge_pa, no\n"
    "                 mdot_in_kg_s (doc/formats/run_data.md)\n"
    "  --no-height    no height sensor: h_m left out\n";

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

double parseNumber(const std::string& option, const std::string& text) {
  double v = 0.0;
  const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || r.ec != std::errc() || r.ptr != text.data() + text.size() || !std::isfinite(v))
    throw UsageError(option + ": expected a number, got '" + text + "'");
  return v;
}

/// Walks a subcommand's arguments: `while (args.next()) { ... args.flag() ... args.value() }`.
class ArgWalker {
 public:
  explicit ArgWalker(const std::vector<std::string>& args) : args_(args) {}
  bool next() { return ++i_ < args_.size(); }
  const std::string& flag() const { return args_[i_]; }
  /// The value after the current option; a UsageError naming the option when there is none.
  std::string value() {
    if (i_ + 1 >= args_.size()) throw UsageError(flag() + " needs a value");
    return args_[++i_];
  }

 private:
  const std::vector<std::string>& args_;
  std::size_t i_ = static_cast<std::size_t>(-1);
};

int runSynth(const std::vector<std::string>& args) {
  nb::SynthOptions o;
  o.progress = &std::cout;
  ArgWalker walk(args);
  while (walk.next()) {
    const std::string& a = walk.flag();
    auto value = [&]() { return walk.value(); };
    if (a == "--help" || a == "-h") {
      std::cout << kSynthUsage << "effects and their parameters:\n" << effectList();
      return 0;
    } else if (a == "--out") {
      o.out_dir = value();
    } else if (a == "--effect") {
      const std::string v = value();
      try {
        o.effects.push_back(nb::parseEffectRequest(v));
      } catch (const std::invalid_argument& e) {
        throw UsageError(std::string("--effect ") + v + ": " + e.what());
      }
    } else if (a == "--seed") {
      const std::string v = value();
      const double s = parseNumber(a, v);
      if (s < 0.0 || s > 4294967295.0 || s != std::floor(s))
        throw UsageError("--seed: expected a whole number 0..4294967295, got '" + v + "'");
      o.seed = static_cast<std::uint32_t>(s);
    } else if (a == "--noise-scale") {
      const std::string v = value();
      o.noise_scale = parseNumber(a, v);
      if (o.noise_scale < 0.0) throw UsageError("--noise-scale: expected a number >= 0, got '" + v + "'");
    } else if (a == "--airbag-param") {
      const std::string v = value();
      const auto eq = v.find('=');
      if (eq == std::string::npos || eq == 0) throw UsageError("--airbag-param: expected NAME=VALUE, got '" + v + "'");
      o.airbag_params[v.substr(0, eq)] = parseNumber("--airbag-param " + v.substr(0, eq), v.substr(eq + 1));
    } else if (a == "--no-flow-meter") {
      o.flow_meter = false;
    } else if (a == "--no-height") {
      o.height_sensor = false;
    } else if (a == "--protocol") {
      o.protocol = value();
      if (o.protocol != "standard" && o.protocol != "small")
        throw UsageError("--protocol: expected standard or small, got '" + o.protocol + "'");
    } else {
      throw UsageError("unknown option '" + a + "'");
    }
  }
  if (o.out_dir.empty()) throw UsageError("--out DIR is required");
  try {
    nb::rigAirbag(o.params, o.airbag_params);
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
  }
  nb::synthesizeDataset(o);
  return 0;
}


constexpr const char* kDiagnoseUsage =
    "usage: gap diagnose DATASET --out DIR [--topic TOPIC] [--effects NAME,NAME...] [--threads N]\n"
    "                    [--params NAME,...] [--no-calibration] [--airbag FILE] [--no-plots]\n"
    "Replays every run of DATASET (a directory of run CSVs and/or bags, optional dataset.yaml)\n"
    "through the nominal cell model, localises the gap, fits every candidate effect (and pairs)\n"
    "on the fit runs, names the effect that explains the gap (or says none / unexplained) and\n"
    "checks it on the withheld runs. Writes DIR/report.json, DIR/report.md, DIR/traces/*.csv and\n"
    "the plots DIR/traces.png, residual_by_phase.png, hp_loops.png.\n"
    "  --out       output directory (created)\n"
    "  --topic     diagnose only the bag runs of this AirbagState topic (one cell of a bed bag);\n"
    "              CSV runs are left out then\n"
    "  --effects   candidates to try, comma-separated (default: all seven)\n"
    "  --threads   candidate fits in parallel (default 2)\n"
    "  --params    model parameters to calibrate first (gap calibrate --help; default: those the\n"
    "              runs can tell); --no-calibration: effects on top of the nominal model only\n"
    "  --airbag    the nominal parameter file (default: the one the dataset names)\n"
    "  --no-plots  skip the PNG plots (they need /usr/bin/python3 with matplotlib)\n";

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
    throw std::runtime_error(dataset + ": no bag run has the topic '" + topic + "' (topics:" +
                             (list.empty() ? std::string(" none, no bags") : list) + ")");
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

/// Options both calibrate and diagnose take; true when `a` was one of them.
struct CommonOptions {
  std::string dataset, out_dir, topic, airbag_override;
  bool plots = true;
};

bool commonOption(ArgWalker& walk, CommonOptions* c, nb::DiagnosisOptions* options) {
  const std::string& a = walk.flag();
  if (a == "--out") {
    c->out_dir = walk.value();
  } else if (a == "--topic") {
    c->topic = walk.value();
  } else if (a == "--airbag") {
    c->airbag_override = walk.value();
  } else if (a == "--params") {
    options->calibration_params = calibrationParamList(walk.value());
  } else if (a == "--threads") {
    const std::string v = walk.value();
    const double t = parseNumber(a, v);
    if (t < 1 || t > 64 || t != std::floor(t)) throw UsageError("--threads: expected a whole number 1..64, got '" + v + "'");
    options->threads = static_cast<int>(t);
  } else if (a == "--no-plots") {
    c->plots = false;
  } else if (!a.empty() && a[0] == '-') {
    throw UsageError("unknown option '" + a + "'");
  } else if (c->dataset.empty()) {
    c->dataset = a;
  } else {
    throw UsageError("one DATASET only, got '" + c->dataset + "' and '" + a + "'");
  }
  return true;
}

/// Reads the dataset and its airbag (or --airbag FILE), runs `analyse`, writes the report (and
/// the calibrated parameter file), plots, prints the verdict.
int analyseDataset(const CommonOptions& c, nb::DiagnosisOptions options, const char* name,
                   nb::DiagnosisReport (*analyse)(std::vector<nb::RunData>, const nb::CellParams&,
                                                  const nb::DiagnosisOptions&, const std::string&)) {
  if (c.dataset.empty()) throw UsageError("DATASET (a directory of runs) is required");
  if (c.out_dir.empty()) throw UsageError("--out DIR is required");
  std::string airbag;
  std::vector<nb::RunData> runs = datasetRuns(c.dataset, c.topic, &airbag);
  if (!c.airbag_override.empty()) airbag = c.airbag_override;
  const nb::CellParams params = nb::loadCellParamsYaml(airbag);
  std::cout << "gap " << name << ": " << runs.size() << " runs from " << c.dataset << ", airbag " << airbag << "\n";
  options.progress = [](const std::string& line) { std::cout << "  " << line << std::endl; };
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

constexpr const char* kCalibrateUsage =
    "usage: gap calibrate DATASET --out DIR [--params NAME,NAME...] [--airbag FILE] [--topic TOPIC]\n"
    "                     [--threads N] [--no-plots]\n"
    "Fits the model's own uncertain parameters on the fit runs of DATASET (the effects are not\n"
    "looked for) and writes DIR/calibrated_airbag.yaml (a complete parameter file: sim.launch\n"
    "cell_params:=..., the nodes and gap diagnose --airbag accept it), DIR/report.json (the\n"
    "calibration block: value, standard error, correlations, what the runs cannot tell apart),\n"
    "DIR/report.md, DIR/traces/*.csv and plots.\n"
    "  --params   parameters to calibrate (default: film_stiffness_scale, gusset_height_m,\n"
    "             dead_volume_m3, plate_mass_kg; plus inlet_area_m2, vent_area_m2,\n"
    "             regulator_time_constant_s for runs driven through the valves, no flow meter)\n"
    "  --airbag   the nominal parameter file (default: the one the dataset names)\n"
    "  --topic, --threads, --no-plots: as for gap diagnose\n";

int runCalibrate(const std::vector<std::string>& args) {
  CommonOptions c;
  nb::DiagnosisOptions options;
  ArgWalker walk(args);
  while (walk.next()) {
    if (walk.flag() == "--help" || walk.flag() == "-h") {
      std::cout << kCalibrateUsage << "parameters:\n" << calibrationParamText();
      return 0;
    }
    commonOption(walk, &c, &options);
  }
  return analyseDataset(c, options, "calibrate", nb::calibrateRuns);
}

int runDiagnose(const std::vector<std::string>& args) {
  CommonOptions c;
  nb::DiagnosisOptions options;
  ArgWalker walk(args);
  while (walk.next()) {
    const std::string& a = walk.flag();
    auto value = [&]() { return walk.value(); };
    if (a == "--help" || a == "-h") {
      std::cout << kDiagnoseUsage;
      return 0;
    } else if (a == "--no-calibration") {
      options.calibrate = false;
    } else if (a == "--effects") {
      options.candidates = nameList("--effects", value(), [](const std::string& name) {
        const auto known = nb::candidateEffectNames();
        if (std::find(known.begin(), known.end(), name) == known.end())
          throw UsageError("--effects: '" + name + "' is not a candidate effect; candidates:\n" + effectList());
      });
    } else {
      commonOption(walk, &c, &options);
    }
  }
  return analyseDataset(c, options, "diagnose", nb::diagnoseRuns);
}

constexpr const char* kEq24Usage =
    "usage: gap eq24 [--out FILE]\n"
    "The paper's eq. 24 curve (x read as bar) as measured quasi-static h(p) at its 10.4 N load:\n"
    "where the nominal model departs from it, what each candidate effect changes, and the guide\n"
    "friction that would be needed. Prints markdown (and writes it to FILE).\n";

int runEq24(const std::vector<std::string>& args) {
  std::string out;
  ArgWalker walk(args);
  while (walk.next()) {
    if (walk.flag() == "--help" || walk.flag() == "-h") {
      std::cout << kEq24Usage;
      return 0;
    } else if (walk.flag() == "--out") {
      out = walk.value();
    } else {
      throw UsageError("unknown argument '" + walk.flag() + "'");
    }
  }
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

constexpr const char* kImportUsage =
    "usage: gap import MAPPING LOG... --out DIR\n"
    "Reads logs of another format with a column-mapping file (doc/formats/import_mapping.md):\n"
    "units (detected where the mapping gives candidates), derived flows, runs of whole cycles,\n"
    "fit/withheld roles; writes DIR/<run>.csv and DIR/dataset.yaml. Everything is checked first:\n"
    "a malformed log is named with its line and column, and nothing is written.\n"
    "  MAPPING  the mapping file (e.g. config/import/respiraworks_net_flow.yaml)\n"
    "  LOG      one or more log files\n"
    "  --out    output directory (created; must not exist or be empty)\n";

int runImport(const std::vector<std::string>& args) {
  std::string mapping_path, out;
  std::vector<std::string> logs;
  ArgWalker walk(args);
  while (walk.next()) {
    const std::string& a = walk.flag();
    if (a == "--help" || a == "-h") {
      std::cout << kImportUsage;
      return 0;
    } else if (a == "--out") {
      out = walk.value();
    } else if (!a.empty() && a[0] == '-') {
      throw UsageError("unknown option '" + a + "'");
    } else if (mapping_path.empty()) {
      mapping_path = a;
    } else {
      logs.push_back(a);
    }
  }
  if (mapping_path.empty()) throw UsageError("MAPPING (a column-mapping file) is required");
  if (logs.empty()) throw UsageError("at least one LOG is required");
  if (out.empty()) throw UsageError("--out DIR is required");
  const nb::ImportMapping mapping = nb::loadImportMapping(mapping_path);
  const std::vector<nb::ImportedLog> imported = nb::importLogsToDataset(mapping, logs, out);
  std::size_t runs = 0;
  for (const auto& log : imported) {
    for (const auto& note : log.notes) std::cout << note << "\n";
    for (const auto& r : log.runs)
      std::cout << "  " << r.name << "  " << r.size() << " samples, " << r.t_s.front() << "-" << r.t_s.back() << " s"
                << (r.role.empty() ? "" : ", " + r.role) << "\n";
    runs += log.runs.size();
  }
  std::cout << "wrote " << runs << " runs from " << imported.size() << " logs to " << out << "\n";
  return 0;
}

const Subcommand kSubcommands[] = {
    {"synth", "write a synthetic dataset with planted effects", kSynthUsage, runSynth},
    {"calibrate", "calibrate the model's own parameters on a dataset", kCalibrateUsage, runCalibrate},
    {"diagnose", "diagnose the gap between a dataset of runs and the model", kDiagnoseUsage, runDiagnose},
    {"eq24", "the paper's eq. 24 curve as data: where the model departs", kEq24Usage, runEq24},
    {"import", "turn logs of another format into a dataset with a mapping file", kImportUsage, runImport},
};

void printUsage(std::ostream& out) {
  out << "usage: gap SUBCOMMAND [options]   (gap SUBCOMMAND --help for its options)\n"
      << "Sim-to-real gap diagnosis of the airbag cell model.\n"
      << "subcommands:\n";
  for (const auto& s : kSubcommands)
    out << "  " << s.name << std::string(10 - std::string(s.name).size(), ' ') << s.summary << "\n";
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    printUsage(std::cerr);
    std::cerr << "gap: missing subcommand\n";
    return 2;
  }
  // Ceres logs an error when a replay fails inside a step; the fit takes that as a refused step.
  FLAGS_minloglevel = google::GLOG_FATAL;
  const std::string command = argv[1];
  if (command == "--help" || command == "-h" || command == "help") {
    printUsage(std::cout);
    return 0;
  }
  const std::vector<std::string> args(argv + 2, argv + argc);
  for (const auto& s : kSubcommands) {
    if (command != s.name) continue;
    try {
      return s.run(args);
    } catch (const UsageError& e) {
      std::cerr << s.usage << "gap " << s.name << ": " << e.what() << "\n";
      return 2;
    } catch (const std::exception& e) {
      std::cerr << "gap " << s.name << ": " << e.what() << "\n";
      return 1;
    }
  }
  printUsage(std::cerr);
  std::cerr << "gap: unknown subcommand '" << command << "'\n";
  return 2;
}
