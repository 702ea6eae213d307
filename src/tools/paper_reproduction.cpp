// paper_reproduction --out DIR: runs the paper's inflation experiments (Xiao et al. 2022,
// sections 2.2, 4.2, 5) on our cell model and writes traces, plots and summary.json.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/paper_experiment.h"
#include "tool_cli.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

namespace tools = nursing_bed::tools;
using Json = nlohmann::ordered_json;

constexpr const char* kSynopsis =
    "usage: paper_reproduction --out DIR [--params FILE.yaml] [--valve-pa P0,P1,P2,P3]\n"
    "                          [--inflow valve|paper_curve] [--no-plot]\n"
    "Runs the paper's inflations at loads 0.6, 10.6, 15.6, 20.6 N (10/15/20 N plus the 0.6 N\n"
    "plate) and writes DIR/inflation_load_<L>N.csv, DIR/characteristic.csv, DIR/summary.json\n"
    "and PNG plots (h(t), p(t), inflow(t), h(p) beside the paper's eq. 24 with x read as bar).";

struct Options {
  std::string out_dir;
  std::string params_file;  ///< empty: the package's config/airbag_tpu_double_100.yaml
  std::string valve_text;   ///< --valve-pa as given; empty: the defaults below
  std::vector<double> valve_pa{20.0e3, 22.0e3, 25.0e3, 28.0e3};
  std::string inflow = "valve";
  bool paper_curve = false;
  bool no_plot = false;
};

void defineOptions(CLI::App& app, Options* o) {
  tools::configureApp(app);
  app.add_option("--out", o->out_dir, "output directory (created)")->type_name("DIR")->required();
  app.add_option("--params", o->params_file, "cell parameter YAML")->type_name("FILE.yaml");
  app.add_option("--valve-pa", o->valve_text,
                 "pressure-reducing valve settings per load, gauge Pa (default 20000,22000,25000,28000: "
                 "raised with load as in the paper)")
      ->type_name("P0,P1,P2,P3");
  app.add_option("--inflow", o->inflow,
                 "valve: inflow results from the regulator and inlet valve; paper_curve: a given "
                 "paper-shaped curve (peak 1 s, zero at 5.5 s) carrying the mass the unloaded valve run "
                 "took, the paper's way of driving its model")
      ->type_name("valve|paper_curve");
  app.add_flag("--no-plot", o->no_plot, "skip the PNG plots");
}

std::vector<double> parseList(const std::string& text) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    std::size_t used = 0;
    const double v = std::stod(item, &used);
    if (used != item.size() || !std::isfinite(v) || v <= 0.0) throw std::invalid_argument(item);
    out.push_back(v);
  }
  return out;
}

/// The values CLI11 took as text, checked; a tools::UsageError naming the option otherwise.
void checkOptions(Options* o) {
  if (!o->valve_text.empty()) {
    try {
      o->valve_pa = parseList(o->valve_text);
    } catch (const std::exception&) {
      throw tools::UsageError("--valve-pa: expected 4 positive numbers separated by commas, got '" + o->valve_text +
                              "'");
    }
    if (o->valve_pa.size() != nb::kPaperLoadsN.size())
      throw tools::UsageError("--valve-pa: expected 4 values (one per load), got " +
                              std::to_string(o->valve_pa.size()));
  }
  if (o->inflow != "valve" && o->inflow != "paper_curve")
    throw tools::UsageError("--inflow: expected 'valve' or 'paper_curve', got '" + o->inflow + "'");
  o->paper_curve = o->inflow == "paper_curve";
  if (o->params_file.empty()) o->params_file = nb::defaultCellParamsFile();
}

std::string loadTag(double load_n) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << load_n;
  return s.str();
}

void writeTrace(const fs::path& path, const nb::InflationTrace& trace) {
  std::ofstream f(path);
  f << "# paper_reproduction: load " << trace.setup.load_n << " N, valve " << trace.setup.valve_pressure_pa
    << " Pa gauge, inlet closes at " << trace.setup.inflation_end_s << " s\n";
  f << "t_s,inflow_kg_s,p_gauge_pa,h_m,volume_m3,mass_kg,t_gas_k\n";
  f << std::setprecision(9);
  for (const auto& s : trace.samples)
    f << s.time_s << ',' << s.inflow_kg_s << ',' << s.gauge_pressure_pa << ',' << s.height_m << ',' << s.volume_m3
      << ',' << s.mass_kg << ',' << s.temperature_k << '\n';
}

/// A number as the console table prints it (10 significant digits).
std::string shortText(double v) {
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

/// A number for summary.json: null where it is not finite (JSON has no NaN).
Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

/// Given-curve mode: the paper-shaped inflow carrying the mass the unloaded valve run took.
nb::TimeSeries givenInflow(const nb::CellParams& params, const Options& opt) {
  nb::InflationSetup probe;
  probe.load_n = nb::kPaperLoadsN[0];
  probe.valve_pressure_pa = opt.valve_pa[0];
  const nb::InflationTrace t = nb::runInflation(params, probe);
  return nb::paperShapedInflow(t.samples.back().mass_kg - t.samples.front().mass_kg);
}

/// One load's inflation: its trace written, its row printed, its summary entry returned and its
/// squared eq. 24 residuals added to `pooled_sq` (loaded runs only).
Json runLoad(const nb::CellParams& params, const Options& opt, std::size_t i, const nb::TimeSeries* given,
             const fs::path& out, std::vector<double>* pooled_sq) {
  nb::InflationSetup setup;
  setup.load_n = nb::kPaperLoadsN[i];
  setup.valve_pressure_pa = opt.valve_pa[i];
  if (opt.paper_curve) setup.prescribed_inflow = given;
  const nb::InflationTrace trace = nb::runInflation(params, setup);
  writeTrace(out / ("inflation_load_" + loadTag(setup.load_n) + "N.csv"), trace);

  std::vector<double> p_bar, h_mm;
  nb::risingHeightVsPressure(trace, &p_bar, &h_mm);
  const std::vector<double> quartic = nb::polyfit(p_bar, h_mm, 4);
  int used = 0;
  std::vector<double> sq;
  const double rms = nb::eq24RmsMm(trace, 10e3, 28e3, &used, &sq);
  if (setup.load_n > 1.0) pooled_sq->insert(pooled_sq->end(), sq.begin(), sq.end());
  // Pressure where the plate starts to rise (h > 1 mm).
  double p_rise_start = NAN;
  for (const auto& s : trace.samples)
    if (s.height_m > 1e-3) {
      p_rise_start = s.gauge_pressure_pa;
      break;
    }
  std::printf("%7.1f  %11.1f  %13.2f  %11.2f  %15.2f  %13s\n", setup.load_n, setup.valve_pressure_pa / 1e3,
              nb::mToMm(trace.finalHeightM()), trace.maxPressurePa() / 1e3, trace.peakInflowTimeS(),
              std::isfinite(rms) ? shortText(std::round(rms * 100) / 100).c_str() : "n/a");
  Json quartic_json = Json::array();
  for (std::size_t k = 0; k < 5; ++k) quartic_json.push_back(number(quartic[k]));
  return {{"load_n", number(setup.load_n)},
          {"valve_pressure_pa", number(setup.valve_pressure_pa)},
          {"height_at_end_m", number(trace.finalHeightM())},
          {"max_pressure_pa", number(trace.maxPressurePa())},
          {"pressure_at_rise_start_pa", number(p_rise_start)},
          {"pressure_at_end_pa", number(trace.samples.back().gauge_pressure_pa)},
          {"peak_inflow_time_s", number(trace.peakInflowTimeS())},
          {"injected_mass_kg", number(trace.samples.back().mass_kg - trace.samples.front().mass_kg)},
          {"eq24_rms_mm", number(rms)},
          {"eq24_points", used},
          {"quartic_mm_vs_bar", quartic_json}};
}

/// Quasi-static h(p, load) characteristic of the structure the parameters select (the paper's
/// section 5 relation).
void writeCharacteristic(const nb::CellParams& params, const fs::path& out) {
  const auto structure = nb::makeCellStructure(params);
  std::ofstream f(out / "characteristic.csv");
  f << "# quasi-static plate height vs gauge pressure per load (film relaxed, plate at rest)\n";
  f << "p_gauge_pa";
  for (double load : nb::kPaperLoadsN) f << ",h_m_load_" << loadTag(load) << "N";
  f << ",h_m_paper_eq24\n" << std::setprecision(9);
  for (double p = 250.0; p <= 30000.0 + 1e-9; p += 250.0) {
    f << p;
    for (double load : nb::kPaperLoadsN) f << ',' << structure->equilibriumAtPressure(p, load).height_m;
    f << ',' << nb::paperEq24HeightM(p) << '\n';
  }
}

void writeSummary(const fs::path& path, const Options& opt, double pooled_rms_mm, const Json& loads) {
  Json j;
  j["source"] = "Xiao et al., Med. Biol. Eng. Comput. 2022 (paper_reproduction)";
  j["inflow_mode"] = opt.paper_curve ? "paper_curve" : "valve";
  j["eq24_x_unit"] = "bar (0.1 MPa); the paper's MPa reading gives h of -790 to -600 mm";
  j["eq24_range_pa"] = {10000, 28000};
  j["eq24_rms_mm"] = number(pooled_rms_mm);
  j["loads"] = loads;
  std::ofstream(path) << j.dump(2) << "\n";
}

bool plot(const fs::path& out) {
  const std::string cmd =
      "/usr/bin/python3 '" + nb::findPackageFile("scripts/plot_reproduction.py") + "' '" + out.string() + "'";
  if (std::system(cmd.c_str()) == 0) return true;
  std::cerr << "paper_reproduction: plotting failed (" << cmd << ")\n";
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CLI::App app(kSynopsis, "paper_reproduction");
  defineOptions(app, &opt);
  const int parsed = tools::parseCommandLine(app, argc, argv);
  if (parsed != tools::kRun) return parsed;
  nb::CellParams params;
  try {
    checkOptions(&opt);
    params = nb::loadCellParamsYaml(opt.params_file);
  } catch (const std::exception& e) {
    return tools::reportMistake(app, "paper_reproduction", e.what());
  }
  const fs::path out(opt.out_dir);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) {
    std::cerr << "paper_reproduction: cannot create " << out << ": " << ec.message() << "\n";
    return 1;
  }

  const nb::TimeSeries given_inflow = opt.paper_curve ? givenInflow(params, opt) : nb::TimeSeries();
  std::vector<double> pooled_sq;
  Json loads = Json::array();
  std::cout << "load [N]  valve [kPa]  h(5.5 s) [mm]  p_max [kPa]  inflow peak [s]  eq24 RMS [mm]\n";
  for (std::size_t i = 0; i < nb::kPaperLoadsN.size(); ++i)
    loads.push_back(runLoad(params, opt, i, &given_inflow, out, &pooled_sq));
  writeCharacteristic(params, out);

  double pooled = 0.0;
  for (double s : pooled_sq) pooled += s;
  pooled = pooled_sq.empty() ? NAN : std::sqrt(pooled / pooled_sq.size());
  writeSummary(out / "summary.json", opt, pooled, loads);
  std::printf("eq. 24 RMS over 10-28 kPa, loaded runs pooled: %.2f mm\n", pooled);

  if (!opt.no_plot && !plot(out)) return 1;
  std::cout << "wrote " << out.string() << "\n";
  return 0;
}
