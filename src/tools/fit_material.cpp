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

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/material_fit.h"
#include "nursing_bed/core/physics/units.h"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitOutputFailed = 1;
constexpr int kExitBadInput = 2;
constexpr int kExitInvalidMaterial = 3;

const char* const kPython = "/usr/bin/python3";
const char* const kPlotScript = "scripts/plot_material_fit.py";  ///< in the package folder (package_path.h)

void printUsage(std::ostream& out) {
  out << "Usage: fit_material INPUT.csv [--out DIR] [--no-plot] [--unweighted]\n"
         "\n"
         "Fits the Yeoh constants C10, C20, C30 (paper eq. 7-10) by linear least squares to a\n"
         "uniaxial tensile curve and writes DIR/yeoh_fit.yaml, DIR/yeoh_fit.csv and\n"
         "DIR/yeoh_fit.png.\n"
         "\n"
         "INPUT.csv   '#' comment lines, then a header with one of 'stretch' or 'strain'\n"
         "            (engineering strain) and one of 'stress_pa' or 'stress_mpa' (engineering\n"
         "            stress); other columns are ignored.\n"
         "--out DIR   output directory, created if missing (default: current directory)\n"
         "--no-plot   do not run " << kPlotScript << "\n"
         "--unweighted  ordinary least squares in Pa instead of the default residuals relative\n"
         "            to the measured stress (which keep the small-stretch region, and so C10,\n"
         "            from being swamped by the large stresses at high stretch)\n"
         "\n"
         "Exit codes: 0 ok; 1 an output could not be written; 2 bad arguments or input (nothing\n"
         "written); 3 the fitted constants fail YeohMaterial::validate() (yeoh_fit.csv and the\n"
         "plot are written for diagnosis, yeoh_fit.yaml is not).\n";
}

const char* weightingName(nursing_bed::FitWeighting w) {
  return w == nursing_bed::FitWeighting::kRelative ? "residuals relative to the measured stress"
                                                   : "unweighted residuals [Pa]";
}

std::string yamlQuoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

void writeYaml(const std::string& path, const nursing_bed::YeohFit& fit,
               const std::string& source) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  const auto& m = fit.material;
  out << std::setprecision(10);
  out << "# Yeoh constants (paper eq. 7: W = C10 (I1-3) + C20 (I1-3)^2 + C30 (I1-3)^3) fitted by\n"
         "# fit_material by linear least squares to the uniaxial engineering stress (eq. 8-10),\n"
      << "# " << weightingName(fit.weighting) << ".\n"
      << "# Valid for stretch " << fit.min_stretch << " to " << fit.max_stretch << " ("
      << fit.num_points << " points).\n"
      << "# Tensile data file the constants were fitted to.\n"
      << "source: " << yamlQuoted(source) << "\n"
      << "# C10: first Yeoh constant; small-strain shear modulus = 2*C10 [Pa]\n"
      << "c10_pa: " << m.c10_pa << "\n"
      << "# C20: second Yeoh constant; (I1-3)^2 term, softening when negative [Pa]\n"
      << "c20_pa: " << m.c20_pa << "\n"
      << "# C30: third Yeoh constant; (I1-3)^3 term, stiffening at large stretch [Pa]\n"
      << "c30_pa: " << m.c30_pa << "\n"
      << "# Standard errors of C10, C20, C30 from the residual variance [Pa]\n"
      << "c10_stderr_pa: " << fit.c10_stderr_pa << "\n"
      << "c20_stderr_pa: " << fit.c20_stderr_pa << "\n"
      << "c30_stderr_pa: " << fit.c30_stderr_pa << "\n"
      << "# Coefficient of determination of the engineering stress [-]\n"
      << "r_squared: " << fit.r_squared << "\n"
      << "# Root-mean-square residual of the engineering stress [Pa]\n"
      << "rms_residual_pa: " << fit.rms_residual_pa << "\n"
      << "# Largest absolute residual of the engineering stress [Pa]\n"
      << "max_abs_residual_pa: " << fit.max_abs_residual_pa << "\n"
      << "# Root-mean-square residual relative to the measured stress [-]\n"
      << "rms_relative_residual: " << fit.rms_relative_residual << "\n";
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

}  // namespace

int main(int argc, char** argv) {
  using nursing_bed::paToMpa;
  std::string input;
  std::string out_dir = ".";
  bool plot = true;
  nursing_bed::YeohFitOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      printUsage(std::cout);
      return kExitOk;
    } else if (arg == "--no-plot") {
      plot = false;
    } else if (arg == "--unweighted") {
      options.weighting = nursing_bed::FitWeighting::kNone;
    } else if (arg == "--out") {
      if (i + 1 >= argc) {
        std::cerr << "fit_material: --out needs a directory\n";
        printUsage(std::cerr);
        return kExitBadInput;
      }
      out_dir = argv[++i];
    } else if (arg.size() > 1 && arg[0] == '-') {
      std::cerr << "fit_material: unknown option '" << arg << "'\n";
      printUsage(std::cerr);
      return kExitBadInput;
    } else if (input.empty()) {
      input = arg;
    } else {
      std::cerr << "fit_material: more than one input file ('" << input << "', '" << arg
                << "')\n";
      printUsage(std::cerr);
      return kExitBadInput;
    }
  }
  if (input.empty()) {
    std::cerr << "fit_material: no input file\n";
    printUsage(std::cerr);
    return kExitBadInput;
  }

  // Read and fit before touching the output directory.
  nursing_bed::TensileData data;
  nursing_bed::YeohFit fit;
  try {
    data = nursing_bed::readTensileCsv(input);
    fit = nursing_bed::fitYeoh(data, options);
  } catch (const std::exception& e) {
    std::cerr << "fit_material: " << e.what() << "\n";
    return kExitBadInput;
  }

  const auto& m = fit.material;
  std::cout << "Yeoh fit (paper eq. 7-10) to " << input << ": " << fit.num_points
            << " points, stretch " << fmt(fit.min_stretch, 3) << " to " << fmt(fit.max_stretch, 3)
            << "\n  (" << weightingName(fit.weighting) << ")\n";
  const struct {
    const char* name;
    double value_pa, stderr_pa;
  } rows[] = {{"C10", m.c10_pa, fit.c10_stderr_pa},
              {"C20", m.c20_pa, fit.c20_stderr_pa},
              {"C30", m.c30_pa, fit.c30_stderr_pa}};
  for (const auto& r : rows)
    std::cout << "  " << r.name << " = " << std::setw(9) << fmt(paToMpa(r.value_pa), 5)
              << " +/- " << fmt(paToMpa(r.stderr_pa), 5) << " MPa   (" << fmt(r.value_pa, 0)
              << " +/- " << fmt(r.stderr_pa, 0) << " Pa)\n";
  std::cout << "  R^2 = " << fmt(fit.r_squared, 6) << "\n  RMS residual = "
            << fmt(fit.rms_residual_pa, 0) << " Pa (" << fmt(paToMpa(fit.rms_residual_pa), 4)
            << " MPa), max |residual| = " << fmt(fit.max_abs_residual_pa, 0) << " Pa ("
            << fmt(paToMpa(fit.max_abs_residual_pa), 4) << " MPa)\n  RMS relative residual = "
            << fmt(100.0 * fit.rms_relative_residual, 2) << " %\n"
            << "  small-strain Young's modulus E = 6 C10 = "
            << fmt(paToMpa(m.youngsModulus()), 3) << " MPa\n";

  const std::filesystem::path dir(out_dir);
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

  int rc = kExitOk;
  if (plot) {
    const std::string title = "Yeoh fit: C10 = " + fmt(paToMpa(m.c10_pa), 3) +
                              " MPa, C20 = " + fmt(paToMpa(m.c20_pa), 3) +
                              " MPa, C30 = " + fmt(paToMpa(m.c30_pa), 4) +
                              " MPa, R$^2$ = " + fmt(fit.r_squared, 5);
    if (runPlot(csv_path, png_path, title)) {
      std::cout << "wrote " << png_path << "\n";
    } else {
      std::cerr << "fit_material: plotting with " << kPython << " " << kPlotScript
                << " failed; no " << png_path << " (use --no-plot to skip)\n";
      rc = kExitOutputFailed;
    }
  }
  if (!fit.validation.empty()) {
    std::cerr << "fit_material: the fitted constants are not usable: " << fit.validation
              << "\n  " << yaml_path << " not written"
              << (std::filesystem::exists(yaml_path) ? " (the older one there is left as it was)"
                                                     : "")
              << "; check the data and its stretch range\n";
    return kExitInvalidMaterial;
  }
  return rc;
}
