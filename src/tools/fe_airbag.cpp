// fe_airbag: the FE membrane model of one airbag (doc/fe_membrane.md).
//   fe_airbag verify    [--out DIR]                       sphere and tube against closed forms
//   fe_airbag hp        [--geometry G] [--elements N] [--loads L1,L2] [--pressures-kpa LO,HI,COUNT] [--vtk-all 1]
//   fe_airbag transient [--geometry G] [--elements N] [--load L] [--inflow-mass-kg M]
//   fe_airbag table     [--geometry G] [--elements N] [--table FILE] [--heights-mm LO,HI,COUNT]
//                       [--branch inflation|flat|equilibria]
//   fe_airbag reduced   [--inflow-mass-kg M] [--load L]          today's reduced model on the same axes
//   fe_airbag check     --table FILE [--geometry G] [--elements N]   cell on the table vs the FE h(p) CSVs
// G is pillows (two flat square pillows joined in the middle) or gusseted (--gusset-mm H
// overrides the 79 mm gusset height). Writes CSV, VTK
// (ParaView) and YAML into --out (default doc/fe); prints progress, wall time and memory.
// --threads T (default 1: OpenMP threads; use 2 on an idle two-core machine).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "nursing_bed/core/fe/airbag_fe.h"
#include "nursing_bed/core/fe/equilibrium_curve.h"
#include "nursing_bed/core/fe/fe_output.h"
#include "nursing_bed/core/fe/verification.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/paper_experiment.h"
#include "nursing_bed/core/physics/pillow_structure.h"
#include "nursing_bed/core/physics/tabulated_structure.h"
#include "nursing_bed/core/physics/units.h"
#include "tool_cli.h"

namespace nb = nursing_bed;
namespace fe = nursing_bed::fe;

namespace {

struct Args {
  std::string mode, geometry = "pillows", out = "doc/fe", table, branch = "inflation";
  int elements = 12;
  int threads = 1;
  std::vector<double> loads{0.6, 10.6, 15.6, 20.6};
  double damping = 1000.0, p_lo_kpa = 1.0, p_hi_kpa = 30.0, tolerance = 1e-4, inflow_mass_kg = 0.0, load = 0.6;
  int p_count = 24;
  bool vtk_all = false, and_back = false;
  double gusset_mm = -1.0;
  double h_lo_mm = 10.0, h_hi_mm = 130.0;
  int h_count = 13;
};

namespace tools = nursing_bed::tools;

std::vector<double> numbers(const std::string& s) {
  std::vector<double> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) v.push_back(std::stod(item));
  return v;
}

/// "a,b,c" given to `option` as finite numbers, `count` of them (0: any number); a
/// tools::UsageError naming the option and saying `shape` otherwise.
std::vector<double> numberList(const std::string& option, const std::string& text, std::size_t count,
                               const char* shape) {
  const tools::UsageError error(option + ": expected " + shape + ", got '" + text + "'");
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    std::size_t used = 0;
    double x = NAN;
    try {
      x = std::stod(item, &used);
    } catch (const std::exception&) {
      throw error;
    }
    if (used != item.size() || !std::isfinite(x)) throw error;
    v.push_back(x);
  }
  if (v.empty() || (count > 0 && v.size() != count)) throw error;
  return v;
}

/// The options as CLI11 takes them: lists and the VTK switch stay text until checkedArgs.
struct RawArgs {
  Args a;
  std::string loads, pressures_kpa, heights_mm, vtk_all, and_back;
};

constexpr const char* kSynopsis =
    "usage: fe_airbag MODE [options]   (the FE membrane model of one airbag, doc/fe_membrane.md)\n"
    "Writes CSV, VTK (ParaView) and YAML into --out; prints progress, wall time and memory.";

void defineModes(CLI::App& app, Args* a) {
  const std::pair<const char*, const char*> modes[] = {
      {"verify", "sphere and tube against closed forms"},
      {"hp", "h(p) per load (--loads, --pressures-kpa, --vtk-all 1)"},
      {"transient", "one inflation (--load, --inflow-mass-kg)"},
      {"table", "the structure table (--table, --heights-mm, --pressures-kpa, --branch)"},
      {"reduced", "today's reduced model on the same axes (--inflow-mass-kg, --load)"},
      {"check", "the cell on --table FILE against the FE h(p) CSVs of the same geometry and mesh"},
      {"foldcheck", "the cell on the fold table --table FILE against the FE's hp --and-back CSVs (3 mm)"},
  };
  for (const auto& [name, what] : modes) {
    CLI::App* mode = app.add_subcommand(name, what);
    mode->fallthrough();  // the options are the tool's: `fe_airbag hp --loads 10.6`
    mode->callback([a, mode_name = std::string(name)] { a->mode = mode_name; });
  }
  app.require_subcommand(1);
}

void defineOptions(CLI::App& app, RawArgs* r) {
  tools::configureApp(app);
  Args& a = r->a;
  defineModes(app, &a);
  app.add_option("--geometry", a.geometry, "pillows (two flat square pillows joined in the middle) or gusseted")
      ->check(CLI::IsMember({"pillows", "gusseted"}));
  app.add_option("--gusset-mm", a.gusset_mm, "gusset height [mm] (default: the geometry's 79 mm)")
      ->type_name("H")
      ->default_str("");
  app.add_option("--elements", a.elements, "elements per side")->type_name("N");
  app.add_option("--threads", a.threads, "OpenMP threads (2 on an idle two-core machine)")
      ->type_name("T")
      ->check(tools::positiveNumber());
  app.add_option("--out", a.out, "output directory (created)")->type_name("DIR");
  app.add_option("--table", a.table, "structure table YAML (table: written; check: read)")->type_name("FILE");
  app.add_option("--branch", a.branch, "the table's branch")->check(CLI::IsMember({"inflation", "flat", "equilibria"}));
  app.add_option("--loads", r->loads, "plate loads [N] (default 0.6,10.6,15.6,20.6)")->type_name("L1,L2,...");
  app.add_option("--load", a.load, "plate load of transient and reduced [N]")->type_name("L");
  app.add_option("--pressures-kpa", r->pressures_kpa, "gauge pressures (default 1,30,24)")->type_name("LO,HI,COUNT");
  app.add_option("--and-back", r->and_back, "1: h(p) up the pressures, then back down them (the deflation branch)")
      ->type_name("1");
  app.add_option("--heights-mm", r->heights_mm, "table heights (default 10,130,13)")->type_name("LO,HI,COUNT");
  app.add_option("--vtk-all", r->vtk_all, "1: a VTK file at every pressure (else the middle and last)")->type_name("1");
  app.add_option("--inflow-mass-kg", a.inflow_mass_kg, "paper-shaped inflow carrying this mass (0: the valve)")
      ->type_name("M");
  app.add_option("--tolerance", a.tolerance, "relaxation tolerance");
  app.add_option("--damping", a.damping, "relaxation damping [1/s]");
}

/// The text options as values; a tools::UsageError naming the option when one is malformed.
Args checkedArgs(const RawArgs& r) {
  Args a = r.a;
  if (!r.loads.empty()) a.loads = numberList("--loads", r.loads, 0, "numbers separated by commas");
  if (!r.pressures_kpa.empty()) {
    const auto p = numberList("--pressures-kpa", r.pressures_kpa, 3, "LO,HI,COUNT");
    a.p_lo_kpa = p[0], a.p_hi_kpa = p[1], a.p_count = static_cast<int>(p[2]);
  }
  if (!r.heights_mm.empty()) {
    const auto h = numberList("--heights-mm", r.heights_mm, 3, "LO,HI,COUNT");
    a.h_lo_mm = h[0], a.h_hi_mm = h[1], a.h_count = static_cast<int>(h[2]);
  }
  a.vtk_all = r.vtk_all == "1";
  a.and_back = r.and_back == "1";
  if ((a.mode == "check" || a.mode == "foldcheck") && a.table.empty())
    throw tools::UsageError(a.mode + " needs --table FILE");
  return a;
}

fe::AirbagFeOptions bagOptions(const Args& a) {
  fe::AirbagFeOptions o;
  o.geometry = a.geometry == "pillows" ? fe::AirbagGeometry::flatPillows() : fe::AirbagGeometry::gusseted();
  o.geometry.elements_per_side = a.elements;
  if (a.gusset_mm >= 0.0) o.geometry.gusset_height_m = 1e-3 * a.gusset_mm;
  o.relax.tolerance = a.tolerance;
  o.membrane.threads = a.threads;
  o.relax.damping_per_s = a.damping;
  return o;
}

std::string tag(const Args& a) {
  const std::string g = a.gusset_mm >= 0.0 ? "_g" + std::to_string(static_cast<int>(a.gusset_mm)) : "";
  return a.geometry + g + "_n" + std::to_string(a.elements);
}

double peakMemoryMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void verify(const Args& a) {
  std::ofstream f(a.out + "/verification.csv");
  f << "shape,resolution,elements,stretch,p_fe_pa,p_exact_pa,rel_error,converged\n";
  for (auto shape : {fe::VerificationCase::Shape::kSphere, fe::VerificationCase::Shape::kTube}) {
    const bool sphere = shape == fe::VerificationCase::Shape::kSphere;
    for (int res : sphere ? std::vector<int>{2, 3, 4} : std::vector<int>{24, 48, 96}) {
      fe::VerificationCase c;
      c.shape = shape;
      c.resolution = res;
      for (double s = 1.05; s < 2.21; s += 0.05) c.stretches.push_back(s);
      const auto pts = fe::runVerification(c, fe::FilmMaterial{});
      const int elements = sphere ? 20 << (2 * res) : 2 * res * 2;
      double worst = 0.0;
      for (const auto& p : pts) {
        f << (sphere ? "sphere," : "tube,") << res << ',' << elements << ',' << p.stretch << ',' << p.fe_pressure_pa
          << ',' << p.exact_pressure_pa << ',' << p.relative_error << ',' << p.converged << '\n';
        worst = std::max(worst, std::abs(p.relative_error));
      }
      std::printf("%s resolution %d (%d triangles): max |error| %.3f %%\n", sphere ? "sphere" : "tube", res, elements,
                  100 * worst);
    }
  }
}

void heightVsPressure(const Args& a) {
  fe::AirbagFe bag(bagOptions(a));
  std::printf("%s: %d nodes, %d triangles, explicit step %.3g s\n", bag.options().geometry.describe().c_str(),
              bag.model().nodeCount(), bag.model().mesh().triangleCount(), bag.model().stableTimeStep());
  for (double load : a.loads) {
    const auto start = std::chrono::steady_clock::now();
    bag.reset();
    std::vector<double> pressures;
    for (int i = 0; i < a.p_count; ++i)
      pressures.push_back(1e3 * (a.p_lo_kpa + (a.p_hi_kpa - a.p_lo_kpa) * i / (a.p_count - 1)));
    // Down again from the top in the same continuation: the states the bag keeps while venting.
    if (a.and_back) pressures.insert(pressures.end(), pressures.rbegin() + 1, pressures.rend());
    std::ostringstream name;
    name << a.out << "/hp_" << tag(a) << "_load_" << load << "N" << (a.and_back ? "_updown" : "");
    std::ofstream f(name.str() + ".csv");
    f << "p_gauge_pa,h_m,volume_m3,plate_force_n,max_stretch,wrinkled_fraction,rim_inset_m,converged,iterations,eq24_h_"
         "m\n";
    int k = 0;
    fe::heightVsPressure(&bag, load, pressures, [&](const fe::QuasiStaticPoint& p) {
      f << p.gauge_pressure_pa << ',' << p.height_m << ',' << p.volume_m3 << ',' << p.plate_force_n << ','
        << p.max_stretch << ',' << p.wrinkled_fraction << ',' << p.rim_inset_m << ',' << p.converged << ','
        << p.iterations << ',' << nb::paperEq24HeightM(p.gauge_pressure_pa) << '\n'
        << std::flush;
      std::printf("  load %.1f N  p %5.1f kPa  h %6.1f mm  %s (%d it)\n", load, p.gauge_pressure_pa / 1e3,
                  p.height_m * 1e3, p.converged ? "ok" : p.message.c_str(), p.iterations);
      std::fflush(stdout);
      ++k;
      if (a.vtk_all || k == static_cast<int>(pressures.size()) || k == static_cast<int>(pressures.size()) / 2) {
        fe::writeVtk(
            name.str() + "_p" + std::to_string(static_cast<int>(std::lround(p.gauge_pressure_pa / 100.0))) + "hPa.vtk",
            bag.model(), "FE airbag " + tag(a));
      }
    });
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("h(p) load %.1f N: %zu pressures, wall %.1f s, peak memory %.0f MB\n", load, pressures.size(), wall,
                peakMemoryMb());
  }
}

void transient(const Args& a) {
  fe::AirbagFe bag(bagOptions(a));
  fe::TransientSetup s;
  nb::TimeSeries inflow;
  if (a.inflow_mass_kg > 0.0) {
    inflow = nb::paperShapedInflow(a.inflow_mass_kg);
    s.prescribed_inflow = &inflow;
  }
  s.load_n = a.load;
  const auto start = std::chrono::steady_clock::now();
  std::ostringstream name;
  name << a.out << "/transient_" << tag(a) << "_load_" << a.load << "N";
  double next_vtk = 0.0;
  const fe::TransientResult r = fe::runTransient(&bag, s, [&](double done) {
    if (done >= next_vtk) {
      std::printf("  %3.0f %%  h %.1f mm\n", 100 * done, bag.model().plate().height_m * 1e3);
      std::fflush(stdout);
      fe::writeVtk(name.str() + "_t" + std::to_string(static_cast<int>(std::lround(done * 11))) + ".vtk", bag.model(),
                   "transient");
      next_vtk += 1.0 / 11.0;
    }
  });
  std::ofstream f(name.str() + ".csv");
  f << "t_s,inflow_kg_s,p_gauge_pa,h_m,volume_m3,mass_kg,t_gas_k,rim_inset_m\n";
  for (const auto& x : r.samples) {
    f << x.time_s << ',' << x.inflow_kg_s << ',' << x.gauge_pressure_pa << ',' << x.height_m << ',' << x.volume_m3
      << ',' << x.mass_kg << ',' << x.temperature_k << ',' << x.rim_inset_m << '\n';
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("transient %s: %s, %ld steps, wall %.1f s, peak memory %.0f MB\n", tag(a).c_str(), r.message.c_str(),
              r.steps, wall, peakMemoryMb());
  if (!r.ok) throw std::runtime_error(r.message);
}

// Every height where the table's plate force (plateForce: p A_eff + the film's own) equals the load (the FE bag snaps
// between branches: F(h) is not monotone there, and an h(p) continuation follows one of them).
std::vector<double> tableRoots(const nb::TabulatedStructure& cell, double p, double load) {
  std::vector<double> roots;
  const double q = p / 1e4;  // shape coordinate: the relaxed pressure in 10 kPa
  auto excess = [&](double h) { return cell.evaluate(h, &q).plateForce(p) - load; };
  const double h_max = cell.heightLimit(&q);
  double h0 = 0.0, f0 = excess(0.0);
  for (int i = 1; i <= 2000; ++i) {
    const double h1 = h_max * i / 2000.0, f1 = excess(h1);
    if ((f0 > 0.0) != (f1 > 0.0)) {
      double lo = h0, hi = h1;
      for (int k = 0; k < 60; ++k) ((excess(0.5 * (lo + hi)) > 0.0) == (f0 > 0.0) ? lo : hi) = 0.5 * (lo + hi);
      roots.push_back(0.5 * (lo + hi));
    }
    h0 = h1, f0 = f1;
  }
  if (roots.empty() && excess(0.0) <= 0.0) roots.push_back(0.0);  // the plate rests on the flat bag
  return roots;
}

// A cell run as the FE bag was: a CellModel on `structure` under `load`, its pressure held at
// each of `pressures` in turn (the supply at that pressure, the inlet open) until the plate rests
// (`calm_steps` x 0.05 s without motion at the pressure). It follows its own branch through the snaps, as the FE's
// pressure continuation does; NaN where it does not come to rest within 10 s.
std::vector<double> runningHeights(const nb::CellParams& params,
                                   const std::shared_ptr<const nb::CellStructure>& structure, double load,
                                   const std::vector<double>& pressures, int calm_steps) {
  nb::CellModel cell(params, structure);
  cell.reset(load);
  std::vector<double> heights;
  for (double p : pressures) {
    nb::CellInputs in;
    in.load_n = load;
    in.supply_pressure_pa = p;
    in.inlet_opening = 1.0;
    double settled = NAN;
    int calm = 0;
    for (double t = 0.0; t < 10.0 && std::isnan(settled); t += 0.05) {
      cell.advance(0.05, in);
      const nb::CellVariables& v = cell.variables();
      const bool at_rest = std::abs(v.velocity_m_s) < 1e-4 && std::abs(v.gauge_pressure_pa - p) < 1e-3 * p + 5.0;
      calm = at_rest ? calm + 1 : 0;
      if (calm >= calm_steps) settled = v.height_m;
    }
    heights.push_back(std::max(settled, 0.0));
  }
  return heights;
}

std::vector<double> runningCellHeights(const std::string& table_file,
                                       const std::shared_ptr<const nb::TabulatedStructure>& table, double load,
                                       const std::vector<double>& pressures) {
  nb::CellParams params;
  params.structure_type = "table";
  params.structure_table_file = table_file;  // named only: the loaded table is given, not read again per load
  return runningHeights(params, table, load, pressures, 1);
}

struct CheckCounts {
  int states = 0, own_root = 0, nearest_root = 0, running = 0;
};

// The cell's quasi-static h(p) on the FE table (physics' TabulatedStructure) against the FE's
// own h(p) (the hp CSVs of the same geometry and mesh): the cell's own root (a bisection), the
// table's equilibrium nearest the FE state, and the running cell.
void check(const Args& a) {
  const auto table = std::make_shared<const nb::TabulatedStructure>(nb::TabulatedStructure::load(a.table));
  const nb::TabulatedStructure& cell = *table;
  std::ofstream f(a.out + "/table_check_" + tag(a) + ".csv");
  f << "load_n,p_gauge_pa,h_fe_m,h_table_m,h_table_nearest_root_m,roots,h_cell_running_m\n";
  CheckCounts within;
  double worst = 0.0, worst_nearest = 0.0, worst_running = 0.0;
  auto near = [](double h, double h_fe) { return std::isfinite(h) && std::abs(h - h_fe) <= 2e-3; };
  for (double load : a.loads) {
    std::ostringstream name;
    name << a.out << "/hp_" << tag(a) << "_load_" << load << "N.csv";
    std::ifstream in(name.str());
    if (!in) throw std::runtime_error("cannot read " + name.str() + " (run the hp mode first)");
    std::string line;
    std::getline(in, line);
    std::vector<std::pair<double, double>> states;  // (p, h_fe), ascending in p as the FE ran
    while (std::getline(in, line)) {
      const auto v = numbers(line);
      if (v[0] < cell.table().pressures_pa.front() || v[7] == 0.0) continue;  // outside the table, or not converged
      states.emplace_back(v[0], v[1]);
    }
    std::vector<double> pressures;
    for (const auto& s : states) pressures.push_back(s.first);
    const std::vector<double> running = runningCellHeights(a.table, table, load, pressures);
    for (std::size_t k = 0; k < states.size(); ++k) {
      const auto [p, h_fe] = states[k];
      const nb::StructureEquilibrium eq = cell.equilibriumAtPressure(p, load);
      const std::vector<double> roots = tableRoots(cell, p, load);
      double nearest = NAN;
      for (double r : roots)
        if (!(std::abs(r - h_fe) >= std::abs(nearest - h_fe))) nearest = r;
      const double own = eq.converged ? eq.height_m : NAN;
      f << load << ',' << p << ',' << h_fe << ',' << own << ',' << nearest << ',' << roots.size() << ',' << running[k]
        << '\n';
      ++within.states;
      within.own_root += near(own, h_fe);
      within.nearest_root += near(nearest, h_fe);
      within.running += near(running[k], h_fe);
      if (std::isfinite(nearest)) worst_nearest = std::max(worst_nearest, std::abs(nearest - h_fe));
      if (std::isfinite(running[k])) worst_running = std::max(worst_running, std::abs(running[k] - h_fe));
      if (eq.converged) worst = std::max(worst, std::abs(eq.height_m - h_fe));
      else
        std::printf("  load %.1f N p %.1f kPa: the table cell has no equilibrium (outside its heights)\n", load,
                    p / 1e3);
    }
  }
  std::printf(
      "table cell vs FE h(p), within 2 mm of %d states: %d (cell's own root, max |dh| %.2f mm), %d (nearest of "
      "the table's equilibria, %.2f mm), %d (the running cell, pressure held step by step, %.2f mm)\n",
      within.states, within.own_root, worst * 1e3, within.nearest_root, worst_nearest * 1e3, within.running,
      worst_running * 1e3);
}

// The cell on a fold table (physics' FoldTableStructure) run through the FE's pressures up and
// back down (the hp --and-back CSVs), against the FE's heights: states within 3 mm, per load.
void foldCheck(const Args& a) {
  nb::CellParams params;
  params.structure_type = "fold_table";
  params.structure_table_file = a.table;
  // The FE's states reach 35 kPa, the relief's cracking pressure: the check is of the structure.
  params.relief_cracking_pressure_pa = 60e3;
  params.relief_full_open_pressure_pa = 70e3;
  const auto structure = nb::makeCellStructure(params);
  std::ofstream f(a.out + "/fold_check_" + tag(a) + ".csv");
  f << "load_n,direction,p_gauge_pa,h_fe_m,h_cell_m\n";
  int states = 0, within = 0;
  for (double load : a.loads) {
    std::ostringstream name;
    name << a.out << "/hp_" << tag(a) << "_load_" << load << "N_updown.csv";
    std::ifstream in(name.str());
    if (!in) throw std::runtime_error("cannot read " + name.str() + " (run hp --and-back 1 first)");
    std::string line;
    std::getline(in, line);
    std::vector<double> pressures, h_fe;
    while (std::getline(in, line)) {
      const auto v = numbers(line);
      if (v[7] == 0.0) continue;  // not converged
      pressures.push_back(v[0]), h_fe.push_back(v[1]);
    }
    const std::vector<double> h = runningHeights(params, structure, load, pressures, 2);  // 2: the fold settled too
    int ok = 0;
    double worst = 0.0;
    bool down = false;
    for (std::size_t k = 0; k < h.size(); ++k) {
      down = down || (k > 0 && pressures[k] < pressures[k - 1]);
      const double err = std::abs(h[k] - h_fe[k]);
      ok += err <= 3e-3;
      worst = std::max(worst, std::isfinite(err) ? err : 1.0);
      f << load << ',' << (down ? "down" : "up") << ',' << pressures[k] << ',' << h_fe[k] << ',' << h[k] << '\n';
    }
    std::printf("  load %.1f N: %d of %zu states within 3 mm, worst %.1f mm\n", load, ok, h.size(), worst * 1e3);
    std::fflush(stdout);
    states += static_cast<int>(h.size()), within += ok;
  }
  std::printf("fold table cell vs FE h(p) up and down: %d of %d states within 3 mm (%.1f %%)\n", within, states,
              100.0 * within / std::max(states, 1));
}

// Today's reduced model (PillowStructure, config defaults) on the same axes: h(p) per load
// and the unloaded transient with the same paper-shaped inflow.
void reduced(const Args& a) {
  const nb::CellParams params;
  const nb::PillowStructure pillow(params.structure);
  std::ofstream f(a.out + "/reduced_hp.csv");
  f << "load_n,p_gauge_pa,h_m,converged\n";
  for (double load : a.loads) {
    for (int i = 0; i < a.p_count; ++i) {
      const double p = 1e3 * (a.p_lo_kpa + (a.p_hi_kpa - a.p_lo_kpa) * i / (a.p_count - 1));
      const nb::StructureEquilibrium eq = pillow.equilibriumAtPressure(p, load);
      f << load << ',' << p << ',' << eq.height_m << ',' << eq.converged << '\n';
    }
  }
  {
    const nb::StructureEquilibrium full = pillow.equilibriumAtPressure(20e3, 0.6);
    const double rt = params.gas.gas_constant_j_kg_k * params.ambient_temperature_k;
    const double rest = pillow.evaluate(0.0, pillow.restShape().data()).volume_m3;
    std::printf("reduced model: unloaded at 20 kPa h %.1f mm, V %.3g m^3, air added %.3g kg (isothermal)\n",
                full.height_m * 1e3, full.eval.volume_m3,
                ((params.ambient_pressure_pa + 20e3) * full.eval.volume_m3 - params.ambient_pressure_pa * rest) / rt);
  }
  if (a.inflow_mass_kg > 0.0) {
    const nb::TimeSeries inflow = nb::paperShapedInflow(a.inflow_mass_kg);
    nb::InflationSetup setup;
    setup.load_n = a.load;
    setup.prescribed_inflow = &inflow;
    const nb::InflationTrace trace = nb::runInflation(params, setup);
    std::ostringstream name;
    name << a.out << "/reduced_transient_load_" << a.load << "N_mass_" << a.inflow_mass_kg * 1e3 << "g.csv";
    std::ofstream t(name.str());
    t << "t_s,inflow_kg_s,p_gauge_pa,h_m,volume_m3\n";
    for (const auto& x : trace.samples) {
      t << x.time_s << ',' << x.inflow_kg_s << ',' << x.gauge_pressure_pa << ',' << x.height_m << ',' << x.volume_m3
        << '\n';
    }
  }
}

// States of the inflation branch (the h(p) procedure: loaded plate, pressure raised step by
// step from the flat bag) for a spread of loads, per pressure.
struct BranchState {
  fe::LoadedState state;
  Eigen::Matrix3Xd positions;
};
using BranchStates = std::vector<std::vector<BranchState>>;

// Loads of the inflation branch [N]: 1.5-6 N apart (the table interpolates linearly between
// two; 8 and 25 N, which `check --loads 8,25` tries, are not among them), and one lighter than
// the plate (0.2 N) so that the plate-alone curve is not the table's edge.
const std::vector<double> kBranchLoadsN{0.2,  0.6,  1.5,  3.0,  4.5,  6.0,  10.6, 13.0,
                                        15.6, 18.0, 20.6, 23.0, 28.0, 33.0, 39.0, 45.0};

BranchStates inflationBranch(fe::AirbagFe* bag, const std::vector<double>& pressures) {
  BranchStates states(pressures.size());
  for (double load : kBranchLoadsN) {
    bag->reset();
    for (std::size_t j = 0; j < pressures.size(); ++j) {
      const fe::QuasiStaticPoint q = bag->solveLoaded(pressures[j], load);
      if (q.converged) states[j].push_back({{load, q.height_m, q.volume_m3}, bag->model().positions()});
    }
    std::printf("  inflation branch under %.1f N done\n", load);
    std::fflush(stdout);
  }
  return states;
}

// Starts the bag from the branch state nearest in height at this pressure, if one is near.
void startNearBranch(fe::AirbagFe* bag, const std::vector<BranchState>& at_pressure, double h) {
  if (at_pressure.empty()) return;
  const auto nearest = std::min_element(at_pressure.begin(), at_pressure.end(), [h](const auto& x, const auto& y) {
    return std::abs(x.state.height_m - h) < std::abs(y.state.height_m - h);
  });
  // Only a nearby branch state: lowering the plate far onto an inflated bag crushes it.
  if (std::abs(nearest->state.height_m - h) <= 2.0 * bag->options().geometry.elementSize())
    bag->model().setPositions(nearest->positions);
}

// One table state with the plate held at h (false when the solve did not converge; kept).
bool heldPlateState(fe::AirbagFe* bag, double h, double p, double* force_n, double* volume_m3) {
  fe::QuasiStaticPoint q = bag->solveAtHeight(h, p);
  if (!bag->model().positions().allFinite()) {  // diverged from the start it was given: from flat
    bag->reset();
    q = bag->solveAtHeight(h, p);
  }
  if (!q.converged) std::printf("  warning: h %.0f mm p %.1f kPa: %s\n", h * 1e3, p / 1e3, q.message.c_str());
  *force_n = q.plate_force_n;
  *volume_m3 = q.volume_m3;
  return q.converged;
}

// Table rows: the plate held at each height. "inflation" starts each state from the nearest
// inflation-branch state at that pressure (so the table lies on the branch the h(p) curves
// follow through the snaps); "flat" inflates each row from the flat bag; "equilibria" takes,
// between the lightest and the heaviest branch load's heights at a pressure, the branch's own
// equilibria (force = the load, interpolated in height between loads) and holds the plate
// only outside them. Through the snaps the bag held at (h, p) may sit in another fold than
// the loaded bag that passed there (hysteresis): the held-plate table then snaps later than
// the FE does; the equilibria are the states the loaded bag does pass through.
void table(const Args& a) {
  fe::AirbagFe bag(bagOptions(a));
  fe::StructureTable t;
  t.description = bag.options().geometry.describe() + ", " + a.branch + " branch";
  for (int i = 0; i < a.h_count; ++i)
    t.heights_m.push_back(1e-3 * (a.h_lo_mm + (a.h_hi_mm - a.h_lo_mm) * i / (a.h_count - 1)));
  for (int i = 0; i < a.p_count; ++i)
    t.pressures_pa.push_back(1e3 * (a.p_lo_kpa + (a.p_hi_kpa - a.p_lo_kpa) * i / (a.p_count - 1)));
  int unconverged = 0, from_equilibria = 0;
  const auto start = std::chrono::steady_clock::now();
  const BranchStates branch =
      a.branch == "flat" ? BranchStates(t.pressures_pa.size()) : inflationBranch(&bag, t.pressures_pa);
  std::vector<std::vector<fe::LoadedState>> curves(t.pressures_pa.size());
  if (a.branch == "equilibria") {
    for (std::size_t j = 0; j < curves.size(); ++j) {
      std::vector<fe::LoadedState> states;
      for (const BranchState& b : branch[j]) states.push_back(b.state);
      std::vector<std::string> left_out;
      curves[j] = fe::equilibriumCurve(states, &left_out);
      for (const std::string& why : left_out)
        std::printf("  p %.1f kPa: %s, left out\n", t.pressures_pa[j] / 1e3, why.c_str());
    }
  }
  for (double h : t.heights_m) {
    bag.reset();
    std::vector<double> v(t.pressures_pa.size()), force(t.pressures_pa.size());
    for (std::size_t j = 0; j < t.pressures_pa.size(); ++j) {
      if (fe::onEquilibriumCurve(curves[j], h, &force[j], &v[j])) {
        ++from_equilibria;
        continue;
      }
      startNearBranch(&bag, branch[j], h);
      if (!heldPlateState(&bag, h, t.pressures_pa[j], &force[j], &v[j])) ++unconverged;
    }
    std::printf("  table row h %.0f mm done\n", h * 1e3);
    std::fflush(stdout);
    t.volume_m3.push_back(v);
    t.plate_force_n.push_back(force);
  }
  if (a.branch == "equilibria") std::printf("  %d states from the branch's equilibria\n", from_equilibria);
  fe::writeStructureTable(a.table.empty() ? a.out + "/table_" + tag(a) + ".yaml" : a.table, t);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("table %s: %zu x %zu states, %d not converged (kept, flagged above), wall %.0f s\n", tag(a).c_str(),
              t.heights_m.size(), t.pressures_pa.size(), unconverged, wall);
}

}  // namespace

int main(int argc, char** argv) {
  RawArgs raw;
  CLI::App app(kSynopsis, "fe_airbag");
  defineOptions(app, &raw);
  const int parsed = tools::parseCommandLine(app, argc, argv);
  if (parsed != tools::kRun) return parsed;
  Args a;
  try {
    a = checkedArgs(raw);
  } catch (const tools::UsageError& e) {
    return tools::reportMistake(app, "fe_airbag", e.what());
  }
  try {
    std::filesystem::create_directories(a.out);
    if (a.mode == "verify") verify(a);
    else if (a.mode == "hp") heightVsPressure(a);
    else if (a.mode == "transient") transient(a);
    else if (a.mode == "table") table(a);
    else if (a.mode == "check") check(a);
    else if (a.mode == "foldcheck") foldCheck(a);
    else if (a.mode == "reduced") reduced(a);
  } catch (const std::exception& e) {
    std::cerr << "fe_airbag: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
