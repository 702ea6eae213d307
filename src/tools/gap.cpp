// gap SUBCOMMAND ...: the sim-to-real gap tools. Subcommands are entries of kSubcommands; each
// parses its own options and returns the exit code (0 ok, 1 failure while running, 2 bad
// command line). `gap synth` writes a synthetic dataset (doc/gap_effects.md).
#include <charconv>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap_effects.h"
#include "nursing_bed/core/gap_synth.h"

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
    "                 [--noise-scale S] [--protocol standard|small]\n"
    "Simulates the run-data protocol (paper-shaped inflow, 60 s hold with the inlet closed,\n"
    "10 s vent through the inlet) on the cell model with the given 'truth' effects and\n"
    "realistic sensors, and writes DIR/<run>.csv, DIR/dataset.yaml and DIR/truth.json.\n"
    "  --out          output directory (created)\n"
    "  --effect       a truth effect, repeatable; parameters not given are drawn from the seed\n"
    "                 within their plausible range (e.g. --effect leak:leak_area_m2=1e-8)\n"
    "  --seed         random seed for drawn parameters and noise (default 1)\n"
    "  --noise-scale  multiplies every sensor noise and quantisation step (default 1; 0: exact)\n"
    "  --protocol     standard: 4 loads x 2 flows, 75.5 s at 100 Hz (default);\n"
    "                 small: 2 loads x 2 flows, 30 s hold, 50 Hz (for CI)\n";

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

int runSynth(const std::vector<std::string>& args) {
  nb::SynthOptions o;
  o.progress = &std::cout;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args.size()) throw UsageError(a + " needs a value");
      return args[++i];
    };
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
    } else if (a == "--protocol") {
      o.protocol = value();
      if (o.protocol != "standard" && o.protocol != "small")
        throw UsageError("--protocol: expected standard or small, got '" + o.protocol + "'");
    } else {
      throw UsageError("unknown option '" + a + "'");
    }
  }
  if (o.out_dir.empty()) throw UsageError("--out DIR is required");
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

const Subcommand kSubcommands[] = {
    {"synth", "write a synthetic dataset with planted effects", kSynthUsage, runSynth},
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
