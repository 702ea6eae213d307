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

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/paper_experiment.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

constexpr const char* kUsage =
    "usage: paper_reproduction --out DIR [--params FILE.yaml] [--valve-pa P0,P1,P2,P3]\n"
    "                          [--inflow valve|paper_curve] [--no-plot]\n"
    "Runs the paper's inflations at loads 0.6, 10.6, 15.6, 20.6 N (10/15/20 N plus the 0.6 N\n"
    "plate) and writes DIR/inflation_load_<L>N.csv, DIR/characteristic.csv, DIR/summary.json\n"
    "and PNG plots (h(t), p(t), inflow(t), h(p) beside the paper's eq. 24 with x read as bar).\n"
    "  --params      cell parameter YAML (default: config/airbag_tpu_double_100.yaml)\n"
    "  --valve-pa    pressure-reducing valve settings per load, gauge Pa\n"
    "                (default 20000,22000,25000,28000: raised with load as in the paper)\n"
    "  --inflow      valve: inflow results from the regulator and inlet valve (default);\n"
    "                paper_curve: a given paper-shaped curve (peak 1 s, zero at 5.5 s) carrying\n"
    "                the mass the unloaded valve run took, the paper's way of driving its model\n";

struct Options {
  std::string out_dir;
  std::string params_file;  ///< empty: the package's config/airbag_tpu_double_100.yaml
  std::vector<double> valve_pa{20.0e3, 22.0e3, 25.0e3, 28.0e3};
  bool paper_curve = false;
  bool plot = true;
};

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

// Returns false (after printing why) when the command line is bad.
bool parseArgs(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(std::string(name) + " needs a value");
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--out") {
      o->out_dir = value("--out");
    } else if (a == "--params") {
      o->params_file = value("--params");
    } else if (a == "--valve-pa") {
      const std::string v = value("--valve-pa");
      try {
        o->valve_pa = parseList(v);
      } catch (const std::exception&) {
        throw std::invalid_argument("--valve-pa: expected 4 positive numbers separated by commas, got '" + v + "'");
      }
      if (o->valve_pa.size() != nb::kPaperLoadsN.size())
        throw std::invalid_argument("--valve-pa: expected 4 values (one per load), got " +
                                    std::to_string(o->valve_pa.size()));
    } else if (a == "--inflow") {
      const std::string v = value("--inflow");
      if (v != "valve" && v != "paper_curve")
        throw std::invalid_argument("--inflow: expected 'valve' or 'paper_curve', got '" + v + "'");
      o->paper_curve = v == "paper_curve";
    } else if (a == "--no-plot") {
      o->plot = false;
    } else {
      throw std::invalid_argument("unknown argument '" + a + "'");
    }
  }
  if (o->out_dir.empty()) throw std::invalid_argument("--out DIR is required");
  if (o->params_file.empty()) o->params_file = nb::findPackageFile("config/airbag_tpu_double_100.yaml");
  return true;
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
    f << s.time_s << ',' << s.inflow_kg_s << ',' << s.gauge_pressure_pa << ',' << s.height_m << ','
      << s.volume_m3 << ',' << s.mass_kg << ',' << s.temperature_k << '\n';
}

std::string jsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  nb::CellParams params;
  try {
    parseArgs(argc, argv, &opt);
    params = nb::loadCellParamsYaml(opt.params_file);
  } catch (const std::exception& e) {
    std::cerr << "paper_reproduction: " << e.what() << "\n" << kUsage;
    return 2;
  }
  const fs::path out(opt.out_dir);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) {
    std::cerr << "paper_reproduction: cannot create " << out << ": " << ec.message() << "\n";
    return 1;
  }

  // Given-curve mode: the paper-shaped inflow carries the mass the unloaded valve run took.
  nb::TimeSeries given_inflow;
  if (opt.paper_curve) {
    nb::InflationSetup probe;
    probe.load_n = nb::kPaperLoadsN[0];
    probe.valve_pressure_pa = opt.valve_pa[0];
    const nb::InflationTrace t = nb::runInflation(params, probe);
    given_inflow = nb::paperShapedInflow(t.samples.back().mass_kg - t.samples.front().mass_kg);
  }

  std::vector<nb::InflationTrace> traces;
  std::vector<double> pooled_sq;
  std::ostringstream loads_json;
  std::cout << "load [N]  valve [kPa]  h(5.5 s) [mm]  p_max [kPa]  inflow peak [s]  eq24 RMS [mm]\n";
  for (std::size_t i = 0; i < nb::kPaperLoadsN.size(); ++i) {
    nb::InflationSetup setup;
    setup.load_n = nb::kPaperLoadsN[i];
    setup.valve_pressure_pa = opt.valve_pa[i];
    if (opt.paper_curve) setup.prescribed_inflow = &given_inflow;
    const nb::InflationTrace trace = nb::runInflation(params, setup);
    writeTrace(out / ("inflation_load_" + loadTag(setup.load_n) + "N.csv"), trace);

    std::vector<double> p_bar, h_mm;
    nb::risingHeightVsPressure(trace, &p_bar, &h_mm);
    const std::vector<double> quartic = nb::polyfit(p_bar, h_mm, 4);
    int used = 0;
    std::vector<double> sq;
    const double rms = nb::eq24RmsMm(trace, 10e3, 28e3, &used, &sq);
    if (setup.load_n > 1.0) pooled_sq.insert(pooled_sq.end(), sq.begin(), sq.end());
    // Pressure where the plate starts to rise (h > 1 mm) and at the end of inflation.
    double p_rise_start = NAN;
    for (const auto& s : trace.samples)
      if (s.height_m > 1e-3) {
        p_rise_start = s.gauge_pressure_pa;
        break;
      }
    std::printf("%7.1f  %11.1f  %13.2f  %11.2f  %15.2f  %13s\n", setup.load_n, setup.valve_pressure_pa / 1e3,
                nb::mToMm(trace.finalHeightM()), trace.maxPressurePa() / 1e3, trace.peakInflowTimeS(),
                std::isfinite(rms) ? jsonNumber(std::round(rms * 100) / 100).c_str() : "n/a");

    loads_json << (i ? ",\n" : "") << "    {\"load_n\": " << jsonNumber(setup.load_n)
               << ", \"valve_pressure_pa\": " << jsonNumber(setup.valve_pressure_pa)
               << ", \"height_at_end_m\": " << jsonNumber(trace.finalHeightM())
               << ", \"max_pressure_pa\": " << jsonNumber(trace.maxPressurePa())
               << ", \"pressure_at_rise_start_pa\": " << jsonNumber(p_rise_start)
               << ", \"pressure_at_end_pa\": " << jsonNumber(trace.samples.back().gauge_pressure_pa)
               << ", \"peak_inflow_time_s\": " << jsonNumber(trace.peakInflowTimeS())
               << ", \"injected_mass_kg\": " << jsonNumber(trace.samples.back().mass_kg - trace.samples.front().mass_kg)
               << ", \"eq24_rms_mm\": " << jsonNumber(rms) << ", \"eq24_points\": " << used
               << ", \"quartic_mm_vs_bar\": [" << jsonNumber(quartic[0]) << ", " << jsonNumber(quartic[1]) << ", "
               << jsonNumber(quartic[2]) << ", " << jsonNumber(quartic[3]) << ", " << jsonNumber(quartic[4]) << "]}";
    traces.push_back(trace);
  }

  // Quasi-static h(p, load) characteristic of the structure (the paper's section 5 relation).
  {
    nb::PillowStructure structure(params.structure);
    std::ofstream f(out / "characteristic.csv");
    f << "# quasi-static plate height vs gauge pressure per load (film relaxed, plate at rest)\n";
    f << "p_gauge_pa";
    for (double load : nb::kPaperLoadsN) f << ",h_m_load_" << loadTag(load) << "N";
    f << ",h_m_paper_eq24\n" << std::setprecision(9);
    for (double p = 250.0; p <= 30000.0 + 1e-9; p += 250.0) {
      f << p;
      for (double load : nb::kPaperLoadsN) f << ',' << structure.equilibriumAtPressure(p, load).height_m;
      f << ',' << nb::paperEq24HeightM(p) << '\n';
    }
  }

  double pooled = 0.0;
  for (double s : pooled_sq) pooled += s;
  pooled = pooled_sq.empty() ? NAN : std::sqrt(pooled / pooled_sq.size());
  {
    std::ofstream f(out / "summary.json");
    f << "{\n  \"source\": \"Xiao et al., Med. Biol. Eng. Comput. 2022 (paper_reproduction)\",\n"
      << "  \"inflow_mode\": \"" << (opt.paper_curve ? "paper_curve" : "valve") << "\",\n"
      << "  \"eq24_x_unit\": \"bar (0.1 MPa); the paper's MPa reading gives h of -790 to -600 mm\",\n"
      << "  \"eq24_range_pa\": [10000, 28000],\n"
      << "  \"eq24_rms_mm\": " << jsonNumber(pooled) << ",\n"
      << "  \"loads\": [\n" << loads_json.str() << "\n  ]\n}\n";
  }
  std::printf("eq. 24 RMS over 10-28 kPa, loaded runs pooled: %.2f mm\n", pooled);

  if (opt.plot) {
    const std::string cmd = "/usr/bin/python3 '" + nb::findPackageFile("scripts/plot_reproduction.py") + "' '" +
                            out.string() + "'";
    if (std::system(cmd.c_str()) != 0) {
      std::cerr << "paper_reproduction: plotting failed (" << cmd << ")\n";
      return 1;
    }
  }
  std::cout << "wrote " << out.string() << "\n";
  return 0;
}
