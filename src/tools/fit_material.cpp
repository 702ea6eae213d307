// fit_material: least-squares Yeoh constants (paper eq. 7-10) from a uniaxial tensile CSV.
//
// Usage: fit_material INPUT.csv [--out DIR] [--no-plot] [--unweighted]
// Writes DIR/yeoh_fit.yaml, DIR/yeoh_fit.csv and (unless --no-plot) DIR/yeoh_fit.png.

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/material_fit.h"
#include "nursing_bed/core/physics/units.h"
#include "tool_cli.h"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitOutputFailed = 1;
constexpr int kExitBadInput = 2;
constexpr int kExitInvalidMaterial = 3;

const char* const kPython = "/usr/bin/python3";
const char* const kPlotScript = "scripts/plot_material_fit.py";  ///< in the package folder (package_path.h)

namespace tools = nursing_bed::tools;

constexpr const char* kSynopsis =
    "usage: fit_material INPUT.csv [--out DIR] [--no-plot] [--unweighted]\n"
    "Fits the Yeoh constants C10, C20, C30 (paper eq. 7-10) by linear least squares to a\n"
    "uniaxial tensile curve and writes DIR/yeoh_fit.yaml, DIR/yeoh_fit.csv and\n"
    "DIR/yeoh_fit.png.";

constexpr const char* kExitCodes =
    "Exit codes: 0 ok; 1 an output could not be written; 2 bad arguments or input (nothing\n"
    "written); 3 the fitted constants fail YeohMaterial::validate() (yeoh_fit.csv and the\n"
    "plot are written for diagnosis, yeoh_fit.yaml is not).";

struct Options {
  std::vector<std::string> inputs;  ///< exactly one, checked after parsing (named in the error)
  std::string out_dir = ".";
  bool no_plot = false;
  bool unweighted = false;
};

void defineOptions(CLI::App& app, Options* o) {
  tools::configureApp(app);
  tools::takeAll(
      app.add_option(
          "INPUT.csv", o->inputs,
          "'#' comment lines, then a header with one of 'stretch' or 'strain' (engineering strain) and one of "
          "'stress_pa' or 'stress_mpa' (engineering stress); other columns are ignored"))
      ->type_name("FILE");
  app.add_option("--out", o->out_dir, "output directory, created if missing")->type_name("DIR");
  app.add_flag("--no-plot", o->no_plot, std::string("do not run ") + kPlotScript);
  app.add_flag("--unweighted", o->unweighted,
               "ordinary least squares in Pa instead of the default residuals relative to the measured "
               "stress (which keep the small-stretch region, and so C10, from being swamped by the large "
               "stresses at high stretch)");
  app.footer(kExitCodes);
}

/// The one input file; a tools::UsageError when there is none or more than one.
std::string inputFile(const Options& o) {
  if (o.inputs.empty()) throw tools::UsageError("no input file");
  if (o.inputs.size() > 1)
    throw tools::UsageError("more than one input file ('" + o.inputs[0] + "', '" + o.inputs[1] + "')");
  return o.inputs[0];
}

const char* weightingName(nursing_bed::FitWeighting w) {
  return w == nursing_bed::FitWeighting::kRelative ? "residuals relative to the measured stress"
                                                   : "unweighted residuals [Pa]";
}

void writeYaml(const std::string& path, const nursing_bed::YeohFit& fit, const std::string& source) {
  const auto& m = fit.material;
  std::ostringstream valid;
  valid << std::setprecision(10) << "Valid for stretch " << fit.min_stretch << " to " << fit.max_stretch << " ("
        << fit.num_points << " points).";
  YAML::Emitter y;
  y.SetDoublePrecision(10);
  y << YAML::Comment(
      std::string("Yeoh constants (paper eq. 7: W = C10 (I1-3) + C20 (I1-3)^2 + C30 (I1-3)^3) fitted by\n"
                  "fit_material by linear least squares to the uniaxial engineering stress (eq. 8-10),\n") +
      weightingName(fit.weighting) + ".\n" + valid.str() + "\nTensile data file the constants were fitted to.");
  y << YAML::BeginMap << YAML::Key << "source" << YAML::Value << YAML::DoubleQuoted << source;
  const struct {
    const char* comment;
    const char* key;
    double value;
  } rows[] = {
      {"C10: first Yeoh constant; small-strain shear modulus = 2*C10 [Pa]", "c10_pa", m.c10_pa},
      {"C20: second Yeoh constant; (I1-3)^2 term, softening when negative [Pa]", "c20_pa", m.c20_pa},
      {"C30: third Yeoh constant; (I1-3)^3 term, stiffening at large stretch [Pa]", "c30_pa", m.c30_pa},
      {"Standard errors of C10, C20, C30 from the residual variance [Pa]", "c10_stderr_pa", fit.c10_stderr_pa},
      {nullptr, "c20_stderr_pa", fit.c20_stderr_pa},
      {nullptr, "c30_stderr_pa", fit.c30_stderr_pa},
      {"Coefficient of determination of the engineering stress [-]", "r_squared", fit.r_squared},
      {"Root-mean-square residual of the engineering stress [Pa]", "rms_residual_pa", fit.rms_residual_pa},
      {"Largest absolute residual of the engineering stress [Pa]", "max_abs_residual_pa", fit.max_abs_residual_pa},
      {"Root-mean-square residual relative to the measured stress [-]", "rms_relative_residual",
       fit.rms_relative_residual},
  };
  for (const auto& r : rows) {
    if (r.comment) y << YAML::Newline << YAML::Comment(r.comment);
    y << YAML::Key << r.key << YAML::Value << r.value;
  }
  y << YAML::EndMap;
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << y.c_str() << "\n";
  out.flush();
  if (!out) throw std::runtime_error(path + ": write failed");
}

/// Runs the plot script without a shell; true on exit status 0.
bool runPlot(const std::string& csv, const std::string& png, const std::string& title) {
  std::string script;
  try {
    script = nursing_bed::findPackageFile(kPlotScript);
  } catch (const std::exception& e) {
    std::cerr << "fit_material: " << e.what() << "\n";
    return false;
  }
  std::vector<std::string> args = {kPython, script, csv, png, title};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::cout.flush();
  const pid_t pid = fork();
  if (pid < 0) return false;
  if (pid == 0) {
    execv(kPython, argv.data());
    std::perror(kPython);
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) return false;
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

std::string fmt(double v, int precision, bool fixed = true) {
  std::ostringstream s;
  if (fixed) s << std::fixed;
  s << std::setprecision(precision) << v;
  return s.str();
}

void printFit(const std::string& input, const nursing_bed::YeohFit& fit) {
  using nursing_bed::paToMpa;
  const auto& m = fit.material;
  std::cout << "Yeoh fit (paper eq. 7-10) to " << input << ": " << fit.num_points << " points, stretch "
            << fmt(fit.min_stretch, 3) << " to " << fmt(fit.max_stretch, 3) << "\n  (" << weightingName(fit.weighting)
            << ")\n";
  const struct {
    const char* name;
    double value_pa, stderr_pa;
  } rows[] = {
      {"C10", m.c10_pa, fit.c10_stderr_pa}, {"C20", m.c20_pa, fit.c20_stderr_pa}, {"C30", m.c30_pa, fit.c30_stderr_pa}};
  for (const auto& r : rows)
    std::cout << "  " << r.name << " = " << std::setw(9) << fmt(paToMpa(r.value_pa), 5) << " +/- "
              << fmt(paToMpa(r.stderr_pa), 5) << " MPa   (" << fmt(r.value_pa, 0) << " +/- " << fmt(r.stderr_pa, 0)
              << " Pa)\n";
  std::cout << "  R^2 = " << fmt(fit.r_squared, 6) << "\n  RMS residual = " << fmt(fit.rms_residual_pa, 0) << " Pa ("
            << fmt(paToMpa(fit.rms_residual_pa), 4) << " MPa), max |residual| = " << fmt(fit.max_abs_residual_pa, 0)
            << " Pa (" << fmt(paToMpa(fit.max_abs_residual_pa), 4)
            << " MPa)\n  RMS relative residual = " << fmt(100.0 * fit.rms_relative_residual, 2) << " %\n"
            << "  small-strain Young's modulus E = 6 C10 = " << fmt(paToMpa(m.youngsModulus()), 3) << " MPa\n";
}

/// The plot of the fit; kExitOk, or kExitOutputFailed when the script failed.
int plotFit(const std::string& csv_path, const std::string& png_path, const nursing_bed::YeohFit& fit) {
  using nursing_bed::paToMpa;
  const auto& m = fit.material;
  const std::string title = "Yeoh fit: C10 = " + fmt(paToMpa(m.c10_pa), 3) +
                            " MPa, C20 = " + fmt(paToMpa(m.c20_pa), 3) + " MPa, C30 = " + fmt(paToMpa(m.c30_pa), 4) +
                            " MPa, R$^2$ = " + fmt(fit.r_squared, 5);
  if (runPlot(csv_path, png_path, title)) {
    std::cout << "wrote " << png_path << "\n";
    return kExitOk;
  }
  std::cerr << "fit_material: plotting with " << kPython << " " << kPlotScript << " failed; no " << png_path
            << " (use --no-plot to skip)\n";
  return kExitOutputFailed;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app(kSynopsis, "fit_material");
  defineOptions(app, &o);
  const int parsed = tools::parseCommandLine(app, argc, argv);
  if (parsed != tools::kRun) return parsed;
  std::string input;
  nursing_bed::YeohFitOptions options;
  if (o.unweighted) options.weighting = nursing_bed::FitWeighting::kNone;

  // Read and fit before touching the output directory.
  nursing_bed::TensileData data;
  nursing_bed::YeohFit fit;
  try {
    input = inputFile(o);
    data = nursing_bed::readTensileCsv(input);
    fit = nursing_bed::fitYeoh(data, options);
  } catch (const tools::UsageError& e) {
    return tools::reportMistake(app, "fit_material", e.what());
  } catch (const std::exception& e) {
    std::cerr << "fit_material: " << e.what() << "\n";
    return kExitBadInput;
  }
  printFit(input, fit);

  const std::filesystem::path dir(o.out_dir);
  const std::string yaml_path = (dir / "yeoh_fit.yaml").string();
  const std::string csv_path = (dir / "yeoh_fit.csv").string();
  const std::string png_path = (dir / "yeoh_fit.png").string();
  try {
    std::filesystem::create_directories(dir);
    writeYeohFitCsv(csv_path, data, fit);
    std::cout << "wrote " << csv_path << "\n";
    if (fit.validation.empty()) {
      writeYaml(yaml_path, fit, input);
      std::cout << "wrote " << yaml_path << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "fit_material: " << e.what() << "\n";
    return kExitOutputFailed;
  }

  const int rc = o.no_plot ? kExitOk : plotFit(csv_path, png_path, fit);
  if (!fit.validation.empty()) {
    std::cerr << "fit_material: the fitted constants are not usable: " << fit.validation << "\n  " << yaml_path
              << " not written"
              << (std::filesystem::exists(yaml_path) ? " (the older one there is left as it was)" : "")
              << "; check the data and its stretch range\n";
    return kExitInvalidMaterial;
  }
  return rc;
}
