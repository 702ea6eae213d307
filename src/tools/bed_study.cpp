// bed_study --out DIR: what the posture plans do to the default patient, simulated offline in
// simulated time (the same pieces as sim.launch, without ROS): 180 AirbagCells with their
// controllers, the bed manager's plans, and the body model coupled to the cells the way the
// simulator node couples them. Writes DIR/bed_study.json and prints the tables of
// doc/bed_study.md: peak interface pressures on the flat bed, the share of time each region
// spends above 32 mmHg under alternating 1-in-2 and 1-in-3 with the tissue-load metrics per
// region (core TissueLoadMeter), the body roll per requested turn angle, and the CPR time from
// every plan. With --plans, only the support table: the chosen plans side by side on the same
// patient (tissue-load metrics per region over a long run).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/bed/tissue_load.h"
#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/units.h"
#include "tool_cli.h"

namespace nb = nursing_bed;

namespace {

constexpr double kPlateWeightN = 0.6;
constexpr double kBodyStepS = 0.02;   // the simulator node's rate (50 Hz)
constexpr double kPlanStepS = 0.1;    // the bed manager's rate (10 Hz)
constexpr double kLoadFilterS = 0.1;  // the simulator node's load filter
constexpr int kMeterEvery = 25;       // body steps per tissue-load sample (2 Hz)

// The bed: cells, body and the running plan, stepped together in simulated time.
class Bed {
 public:
  Bed(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell,
      const nb::PatientParams& patient = nb::PatientParams{})
      : grid_(grid), config_(config), body_(patient, grid) {
    nb::AirbagCellParams p;
    p.cell = cell;
    for (int i = 0; i < grid.cells(); ++i) {
      cells_.push_back(std::make_unique<nb::AirbagCell>(p));
      cells_.back()->resetToHeight(config.nominal_height_m, kPlateWeightN);
    }
    loads_.assign(grid.cells(), 0.0);
    const auto rows = body_.footprintRows();
    footprint_.first_row = rows.front();
    footprint_.last_row = rows.back();
  }

  const nb::BodyFootprint& footprint() const { return footprint_; }

  void start(const nb::PlanRequest& request) {
    std::string why;
    plan_ = nb::makePlan(request, config_, grid_, footprint_, &why);
    if (!plan_) throw std::runtime_error(why);
    plan_start_ = t_;
    vented_ = false;
    last_sent_.assign(grid_.cells(), NAN);
  }

  /// Runs `duration` seconds; calls `observe` after every body step.
  template <typename Observe>
  void run(double duration, Observe observe) {
    const double end = t_ + duration;
    while (t_ < end - 1e-9) {
      if (plan_ && std::fmod(t_ + 1e-9, kPlanStepS) < kBodyStepS) applyPlan();
      t_ += kBodyStepS;
      heights_.resize(grid_.cells());
      for (int i = 0; i < grid_.cells(); ++i) {
        cells_[i]->advanceTo(t_);
        heights_[i] = std::max(0.0, cells_[i]->variables().height_m);
      }
      state_ = body_.solve(heights_);
      const double a = kBodyStepS / kLoadFilterS;
      for (int i = 0; i < grid_.cells(); ++i) {
        loads_[i] += a * (state_.cell_load_n[i] - loads_[i]);
        cells_[i]->setLoad(kPlateWeightN + loads_[i]);
      }
      observe(t_);
    }
  }
  void run(double duration) {
    run(duration, [](double) {});
  }
  /// Total area of the body's contact points on the last solve [m^2].
  double contactAreaM2() const {
    double area = 0.0;
    for (const nb::ContactPoint& p : body_.contactMap(heights_))
      if (p.pressure_pa > 0.0) area += p.area_m2;
    return area;
  }
  /// The running plan's phase.
  std::string phase() const { return plan_ ? plan_->targets(t_ - plan_start_).phase : ""; }

  const nb::BodyState& body() const { return state_; }
  /// The default regions' loads on the last solve.
  std::vector<nb::RegionLoad> regionLoads() const {
    return nb::measureRegions(body_.contactMap(heights_), nb::defaultTissueRegions(), body_.params().height_m);
  }
  const nb::BodyModel& model() const { return body_; }
  double maxHeight() const {
    double h = 0.0;
    for (const auto& c : cells_) h = std::max(h, c->variables().height_m);
    return h;
  }
  double time() const { return t_; }
  /// Time since the running plan started [s].
  double planElapsed() const { return t_ - plan_start_; }
  /// The height last sent to each cell (NaN: none since the plan started) [m].
  const std::vector<double>& sentTargets() const { return last_sent_; }

 private:
  // What a bed senses, as the bed manager gets it: each cell's gauge pressure and the load its
  // controller estimates from it (plate weight included), no simulator truth.
  nb::SensedCells sensed() const {
    nb::SensedCells s;
    for (const auto& c : cells_) {
      s.gauge_pressure_pa.push_back(c->measurement().gauge_pressure_pa);
      s.load_n.push_back(c->loadEstimate());
    }
    return s;
  }

  void applyPlan() {
    const nb::PlanTargets tg = plan_->sensedTargets(t_ - plan_start_, sensed());
    for (int i = 0; i < grid_.cells(); ++i) {
      if (tg.vent_all) {
        if (!vented_) cells_[i]->requestVent(t_);
      } else if (!(std::fabs(tg.heights_m[i] - last_sent_[i]) < 1e-6)) {
        cells_[i]->requestHeight(tg.heights_m[i], t_);
        last_sent_[i] = tg.heights_m[i];
      }
    }
    vented_ = tg.vent_all;
  }

  nb::BedGrid grid_;
  nb::PlanConfig config_;
  nb::BodyModel body_;
  nb::BodyFootprint footprint_;
  std::vector<std::unique_ptr<nb::AirbagCell>> cells_;
  std::vector<double> loads_, last_sent_, heights_;
  std::unique_ptr<nb::PosturePlan> plan_;
  nb::BodyState state_;
  double t_ = 0.0, plan_start_ = 0.0;
  bool vented_ = false;
};

double mmhg(double pa) { return nb::paToMmHg(pa); }

namespace tools = nursing_bed::tools;
using Json = nlohmann::ordered_json;

/// A number for bed_study.json: null where it is not finite (JSON has no NaN).
Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json regions(double sacrum, double heels, double occiput) {
  return {{"sacrum", number(sacrum)}, {"heels", number(heels)}, {"occiput", number(occiput)}};
}

/// Every region's snapshot: peak and mean pressure, contact area, force, bottoming-out margin.
Json regionSnapshot(const std::vector<nb::RegionLoad>& loads) {
  Json out = Json::object();
  std::printf("  %-17s %10s %10s %10s %8s %10s\n", "region", "peak mmHg", "mean mmHg", "area cm^2", "force N",
              "margin mm");
  for (std::size_t r = 0; r < loads.size(); ++r) {
    const nb::RegionLoad& l = loads[r];
    const std::string& name = nb::defaultTissueRegions()[r].name;
    std::printf("  %-17s %10.1f %10.1f %10.0f %8.1f %10.1f\n", name.c_str(), mmhg(l.peak_pressure_pa),
                mmhg(l.mean_pressure_pa), 1e4 * l.contact_area_m2, l.force_n, 1e3 * l.margin_m);
    out[name] = {{"peak_mmhg", number(mmhg(l.peak_pressure_pa))},
                 {"mean_mmhg", number(mmhg(l.mean_pressure_pa))},
                 {"contact_area_cm2", number(1e4 * l.contact_area_m2)},
                 {"force_n", number(l.force_n)},
                 {"margin_mm", number(1e3 * l.margin_m)}};
  }
  return out;
}

/// Every region's accumulated metrics: share of the time above the threshold, dose per hour,
/// highest peak, lowest margin.
Json regionDoses(const nb::TissueLoadMeter& meter) {
  Json out = Json::object();
  std::printf("  %-17s %10s %12s %14s %14s\n", "region", "share >32", "dose per h", "max peak mmHg", "min margin mm");
  for (std::size_t r = 0; r < meter.regions().size(); ++r) {
    const nb::RegionDose& d = meter.doses()[r];
    const double share = d.time_above_s / meter.observedS(), per_hour = d.dose * 3600.0 / meter.observedS();
    std::printf("  %-17s %9.0f%% %12.4f %14.1f %14.1f\n", meter.regions()[r].name.c_str(), 100 * share, per_hour,
                mmhg(d.max_peak_pressure_pa), 1e3 * d.min_margin_m);
    out[meter.regions()[r].name] = {{"share_above_threshold", number(share)},
                                    {"dose_per_hour", number(per_hour)},
                                    {"max_peak_mmhg", number(mmhg(d.max_peak_pressure_pa))},
                                    {"mean_peak_mmhg", number(mmhg(d.peak_integral_pa_s / meter.observedS()))},
                                    {"min_margin_mm", number(1e3 * d.min_margin_m)}};
  }
  return out;
}

/// 1. Flat bed: peaks after settling.
Json flatBed(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell,
             const nb::PatientParams& patient) {
  Bed bed(grid, config, cell, patient);
  bed.start({"flat", {}, {}});
  bed.run(15.0);
  const nb::BodyState& s = bed.body();
  std::printf(
      "flat bed (%.2f m): peak point pressure sacrum %.1f, heels %.1f, occiput %.1f mmHg; "
      "cell-averaged %.1f, %.1f, %.1f mmHg\n",
      config.nominal_height_m, mmhg(s.peak_pressure_pa.sacrum), mmhg(s.peak_pressure_pa.heels),
      mmhg(s.peak_pressure_pa.occiput), mmhg(s.peak_cell_pressure_pa.sacrum), mmhg(s.peak_cell_pressure_pa.heels),
      mmhg(s.peak_cell_pressure_pa.occiput));
  return {{"peak_mmhg",
           regions(mmhg(s.peak_pressure_pa.sacrum), mmhg(s.peak_pressure_pa.heels), mmhg(s.peak_pressure_pa.occiput))},
          {"cell_peak_mmhg", regions(mmhg(s.peak_cell_pressure_pa.sacrum), mmhg(s.peak_cell_pressure_pa.heels),
                                     mmhg(s.peak_cell_pressure_pa.occiput))},
          {"regions", regionSnapshot(bed.regionLoads())}};
}

/// 2. Share of time above 32 mmHg per region under `plan` ("flat", "1in2", "1in3"), at the
/// tissue over each loaded cell: a region's share is the mean, over the cells of its rows that
/// carry it, of the time the highest point pressure over that cell exceeds 32 mmHg (a location
/// relieved while its cell is low counts as relieved even when the region's other cells carry
/// more). The flat bed is the reference.
Json shareAbove32(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell, double period_s,
                  const std::string& plan) {
  Bed bed(grid, config, cell);
  bed.start({"flat", {{"height_m", "0.12"}}, {}});
  bed.run(15.0);
  if (plan != "flat") bed.start({"alternating", {{"pattern", plan}, {"period_s", std::to_string(period_s)}}, {}});
  const std::vector<int> rows[3] = {bed.model().pelvisRows(), bed.model().heelRows(), bed.model().headRows()};
  std::vector<double> above(grid.cells(), 0.0), loaded(grid.cells(), 0.0);
  int samples = 0;
  nb::TissueLoadMeter meter(nb::TissueLoadParams{}, nb::defaultTissueRegions());
  const double threshold_pa = meter.params().threshold_pa;  // 32 mmHg
  bed.run(plan == "flat" ? 60.0 : period_s, [&](double) {
    const std::vector<double>& peak = bed.body().cell_peak_pressure_pa;
    for (int i = 0; i < grid.cells(); ++i) {
      above[i] += peak[i] > threshold_pa;
      loaded[i] += peak[i] > 0.0;
    }
    ++samples;
    // The regions at 2 Hz, as the simulator samples them: loads that change over seconds.
    if (samples % kMeterEvery == 0) meter.sample(bed.regionLoads(), kMeterEvery * kBodyStepS);
  });
  double share[3] = {0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    int cells = 0;
    for (int r : rows[k])
      for (int c = 0; c < grid.cols; ++c)
        if (loaded[grid.id(r, c)] > 0.5 * samples) {  // the region rests on this cell
          share[k] += above[grid.id(r, c)] / samples;
          ++cells;
        }
    share[k] = cells ? share[k] / cells : NAN;
  }
  std::printf("%s: share of time above 32 mmHg at the loaded tissue: sacrum %.0f %%, heels %.0f %%, occiput %.0f %%\n",
              plan == "flat"
                  ? "flat bed (0.12 m)"
                  : ("alternating " + plan + ", period " + std::to_string(static_cast<int>(period_s)) + " s").c_str(),
              100 * share[0], 100 * share[1], 100 * share[2]);
  Json out = regions(share[0], share[1], share[2]);
  out["regions"] = regionDoses(meter);
  return out;
}

/// 3. Lateral turn: body roll at the end of the ramp (+ 10 s) per requested angle.
Json lateralTurns(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell,
                  const nb::PatientParams& patient) {
  Json turns = Json::array();
  for (int angle = 5; angle <= 30; angle += 5) {
    Bed bed(grid, config, cell, patient);
    bed.start({"flat", {}, {}});
    bed.run(10.0);
    const double ramp = std::max(config.turn_ramp_s, angle / config.max_tilt_rate_deg_s);
    bed.start({"lateral_turn",
               {{"side", "left"}, {"angle_deg", std::to_string(angle)}, {"ramp_s", std::to_string(ramp)}},
               {}});
    bed.run(ramp + 10.0);
    const double roll_deg = bed.body().roll_rad * 180.0 / nb::kPi;
    std::printf("lateral turn left %2d deg: body roll %.1f deg (after the %.0f s ramp + 10 s)\n", angle, roll_deg,
                ramp);
    turns.push_back({{"requested_deg", angle}, {"body_roll_deg", number(roll_deg)}});
  }
  return turns;
}

/// 4. CPR from every plan: time until every cell is below 10 mm.
Json cprTimes(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell) {
  const std::vector<std::pair<std::string, nb::PlanRequest>> from = {
      {"flat", {"flat", {}, {}}},
      {"max_inflate", {"max_inflate", {}, {}}},
      {"alternating_1in2", {"alternating", {{"pattern", "1in2"}}, {}}},
      {"lateral_turn_30", {"lateral_turn", {{"side", "right"}, {"angle_deg", "30"}}, {}}},
  };
  Json seconds_from = Json::object();
  for (const auto& [label, request] : from) {
    Bed bed(grid, config, cell);
    bed.start(request);
    bed.run(label == "lateral_turn_30" ? 40.0 : 15.0);
    bed.start({"cpr", {}, {}});
    double below_at = NAN;
    bed.run(20.0, [&](double t) {
      if (std::isnan(below_at) && bed.maxHeight() < 0.010) below_at = t;
    });
    const double seconds = below_at - (bed.time() - 20.0);
    std::printf("CPR from %s: every cell below 10 mm after %.2f s\n", label.c_str(), seconds);
    seconds_from[label] = number(seconds);
  }
  return seconds_from;
}

/// The requests of the plans the support table can compare.
const std::map<std::string, nb::PlanRequest>& comparablePlans() {
  static const std::map<std::string, nb::PlanRequest> plans = {
      {"flat", {"flat", {}, {}}},
      {"alternating_1in2", {"alternating", {{"pattern", "1in2"}}, {}}},
      {"alternating_1in3", {"alternating", {{"pattern", "1in3"}}, {}}},
      {"lateral_turn_30", {"lateral_turn", {{"side", "left"}, {"angle_deg", "30"}, {"return", "no"}}, {}}},
      {"adaptive", {"adaptive", {}, {}}},
      {"adaptive_turn_30", {"adaptive", {{"side", "left"}, {"angle_deg", "30"}}, {}}},
  };
  return plans;
}

/// One line of the --trace CSV (live_support.py --trace writes the same columns): the plan's
/// elapsed time and phase, each region's peak now [mmHg], each cell's target [m].
void traceLine(std::ostream& out, const Bed& bed, std::string phase, const std::vector<nb::RegionLoad>& loads) {
  if (out.tellp() == 0) {
    out << "elapsed_s,phase";
    for (const nb::TissueRegion& r : nb::defaultTissueRegions()) out << ",peak_mmhg_" << r.name;
    for (std::size_t i = 0; i < bed.sentTargets().size(); ++i) out << ",target_m_" << i;
    out << "\n";
  }
  std::replace(phase.begin(), phase.end(), ',', ';');
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", bed.planElapsed());
  out << buf << "," << phase;
  for (const nb::RegionLoad& l : loads) {
    std::snprintf(buf, sizeof buf, ",%.2f", mmhg(l.peak_pressure_pa));
    out << buf;
  }
  for (double h : bed.sentTargets()) {
    std::snprintf(buf, sizeof buf, ",%.5f", h);
    out << buf;
  }
  out << "\n";
}

/// 5. One plan on the patient: settled on the flat bed, then `warmup_s` under the plan (its
/// transition), then `duration_s` measured: per region the highest peak, the share of time
/// above 32 mmHg, the dose per hour, the lowest margin; the body's mean contact area. With
/// `trace`, a traceLine() each second of the measured time. `plan_args` are added to the plan's
/// request (the plan refuses what it does not know).
Json supportRow(const nb::BedGrid& grid, const nb::PlanConfig& config, const nb::CellParams& cell,
                const nb::PatientParams& patient, const std::string& name, double warmup_s, double duration_s,
                const std::map<std::string, std::string>& plan_args, std::ostream* trace = nullptr) {
  Bed bed(grid, config, cell, patient);
  bed.start({"flat", {}, {}});
  bed.run(15.0);
  nb::PlanRequest request = comparablePlans().at(name);
  for (const auto& [key, value] : plan_args) request.args[key] = value;
  bed.start(request);
  bed.run(warmup_s);
  nb::TissueLoadMeter meter(nb::TissueLoadParams{}, nb::defaultTissueRegions());
  double area_sum = 0.0;
  int samples = 0;
  std::map<std::string, double> phase_s;
  bed.run(duration_s, [&](double) {
    if (++samples % kMeterEvery != 0) return;
    const std::vector<nb::RegionLoad> loads = bed.regionLoads();
    const std::string phase = bed.phase();
    meter.sample(loads, kMeterEvery * kBodyStepS);
    if (trace && samples % (2 * kMeterEvery) == 0) traceLine(*trace, bed, phase, loads);
    area_sum += bed.contactAreaM2();
    phase_s[phase] += kMeterEvery * kBodyStepS;
  });
  const double area_cm2 = 1e4 * area_sum / (samples / kMeterEvery);
  std::printf("%s (%.0f s after a %.0f s warm-up): body contact area %.0f cm^2\n", name.c_str(), duration_s, warmup_s,
              area_cm2);
  Json out = {{"contact_area_cm2", number(area_cm2)}, {"regions", regionDoses(meter)}};
  for (const auto& [phase, seconds] : phase_s) out["phase_s"][phase] = number(seconds);
  return out;
}

/// What --plans runs: the plans, their timing, the body, extra request arguments, a trace file.
struct SupportOptions {
  std::vector<std::string> plans;
  double duration_s = 3600.0, warmup_s = 300.0;
  nb::PatientParams body;
  bool articulated = false;
  std::map<std::string, std::string> plan_args;
  std::string trace_path;
};

/// The support table of `o.plans` into OUT_DIR/bed_study_support.json; the exit code.
int supportTable(const SupportOptions& o, const std::string& out_dir, const nb::CellParams& cell) {
  nb::PatientParams patient = o.body;
  patient.articulated = o.articulated;
  Json study;
  study["patient"] = o.articulated ? "articulated" : "free segments";
  study["mass_kg"] = patient.mass_kg;
  study["height_m"] = patient.height_m;
  study["warmup_s"] = o.warmup_s;
  study["duration_s"] = o.duration_s;
  if (!o.plan_args.empty()) study["plan_args"] = o.plan_args;
  std::ofstream trace;
  if (!o.trace_path.empty()) {
    trace.open(o.trace_path);
    if (!trace) {
      std::cerr << "bed_study: --trace " << o.trace_path << ": cannot write\n";
      return 2;
    }
  }
  try {
    for (const std::string& name : o.plans)
      study["plans"][name] = supportRow(nb::BedGrid{}, nb::PlanConfig{}, cell, patient, name, o.warmup_s, o.duration_s,
                                        o.plan_args, trace.is_open() ? &trace : nullptr);
  } catch (const std::runtime_error& e) {  // the plan refused its request (e.g. a bad --plan-args key)
    std::cerr << "bed_study: " << e.what() << "\n";
    return 2;
  }
  std::ofstream(std::filesystem::path(out_dir) / "bed_study_support.json") << study.dump(2) << "\n";
  std::cout << "wrote " << out_dir << "/bed_study_support.json\n";
  return 0;
}

/// KEY=VALUE items into *out; false (and the reason on stderr) for an item without a key or '='.
bool keyValues(const std::vector<std::string>& items, std::map<std::string, std::string>* out) {
  for (const std::string& item : items) {
    const auto kv = tools::splitKeyValue(item);
    if (!kv) {
      std::cerr << "bed_study: --plan-args: '" << item << "' is not KEY=VALUE\n";
      return false;
    }
    (*out)[kv->first] = kv->second;
  }
  return true;
}

constexpr const char* kSynopsis =
    "usage: bed_study --out DIR [--params FILE] [--supply PA] [--period S] [--articulated] [--plans LIST [--duration "
    "S] [--warmup S]\n"
    "                 [--mass-kg M] [--height-m H] [--plan-args K=V,...] [--trace CSV]]\n"
    "Simulates the default patient on the 20 x 9 bed of the default cells (--params) under every plan (several "
    "minutes) and writes\n"
    "DIR/bed_study.json; with --articulated, the articulated patient on the flat bed and in the\n"
    "lateral turns only (DIR/bed_study_articulated.json). With --plans (comma-separated: flat,\n"
    "alternating_1in2, alternating_1in3, lateral_turn_30, adaptive, adaptive_turn_30: adaptive with\n"
    "a 30 deg left turn), only the support table of those plans (DIR/bed_study_support.json), on\n"
    "the articulated patient with --articulated, for a body of --mass-kg and --height-m (default\n"
    "70 kg, 1.70 m); --trace, with one plan, a CSV of its region peaks and cell targets each second.";

/// The whole study (or, articulated, the flat bed and the turns) into out_dir; the exit code.
int wholeStudy(const std::string& out_dir, const nb::CellParams& cell, bool articulated, double period_s) {
  const nb::BedGrid grid;
  const nb::PlanConfig config;
  Json study;
  if (articulated) {
    nb::PatientParams patient;
    patient.articulated = true;
    study["flat"] = flatBed(grid, config, cell, patient);
    study["lateral_turn"] = lateralTurns(grid, config, cell, patient);
    std::ofstream(std::filesystem::path(out_dir) / "bed_study_articulated.json") << study.dump(2) << "\n";
    std::cout << "wrote " << out_dir << "/bed_study_articulated.json\n";
    return 0;
  }
  study["flat"] = flatBed(grid, config, cell, nb::PatientParams{});
  Json& share = study["share_above_32mmhg"];
  for (const std::string plan : {"flat", "1in2", "1in3"})
    share[plan] = shareAbove32(grid, config, cell, period_s, plan);
  study["lateral_turn"] = lateralTurns(grid, config, cell, nb::PatientParams{});
  study["cpr_seconds"] = cprTimes(grid, config, cell);
  std::ofstream(std::filesystem::path(out_dir) / "bed_study.json") << study.dump(2) << "\n";
  std::cout << "wrote " << out_dir << "/bed_study.json\n";
  return 0;
}

/// The cells' parameters: `path` with the bed's supply; false (the reason printed) when invalid.
bool loadCell(const std::string& path, double supply_pa, nb::CellParams* cell) {
  try {
    *cell = nb::loadCellParamsYaml(path);
    cell->supply_pressure_pa = supply_pa;
    if (const std::string error = cell->validate(); !error.empty()) throw std::invalid_argument(error);
  } catch (const std::exception& e) {
    std::cerr << "bed_study: --params " << path << ": " << e.what() << "\n";
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string out_dir;
  double period_s = 600.0;
  std::string params_path = nb::defaultCellParamsFile();
  double supply_pa = 30000.0;
  CLI::App app(kSynopsis, "bed_study");
  tools::configureApp(app);
  app.add_option("--out", out_dir, "output directory (created)")->type_name("DIR")->required();
  app.add_option("--period", period_s, "period of the alternating plans [s]")
      ->type_name("S")
      ->check(tools::positiveNumber());
  bool articulated = false;
  app.add_flag("--articulated", articulated, "the articulated patient: flat bed and lateral turns only");
  std::vector<std::string> plans;
  double duration_s = 3600.0, warmup_s = 300.0;
  std::vector<std::string> plan_names;
  for (const auto& p : comparablePlans()) plan_names.push_back(p.first);
  app.add_option("--plans", plans, "only the support table, for these plans")
      ->delimiter(',')
      ->type_name("LIST")
      ->check(CLI::IsMember(plan_names));
  app.add_option("--duration", duration_s, "support table: measured time per plan [s]")
      ->type_name("S")
      ->check(tools::positiveNumber());
  app.add_option("--warmup", warmup_s, "support table: time under the plan before measuring [s]")
      ->type_name("S")
      ->check(CLI::NonNegativeNumber);
  std::string trace_path;
  std::vector<std::string> plan_arg_list;
  app.add_option("--plan-args", plan_arg_list, "support table: KEY=VALUE arguments added to every plan's request")
      ->delimiter(',')
      ->type_name("LIST");
  app.add_option("--trace", trace_path,
                 "support table of one plan: a CSV of region peaks and cell targets, once a second")
      ->type_name("CSV");
  nb::PatientParams body;
  app.add_option("--mass-kg", body.mass_kg, "support table: the patient's mass [kg]")->type_name("M");
  app.add_option("--height-m", body.height_m, "support table: the patient's stature [m]")->type_name("H");
  app.add_option("--params", params_path, "the cells' parameter file (default the package's default cell)")
      ->type_name("FILE")
      ->check(CLI::ExistingFile);
  app.add_option("--supply", supply_pa, "the bed's supply pressure, gauge [Pa] (default 30000, as sim.launch)")
      ->type_name("PA")
      ->check(tools::positiveNumber());
  const int parsed = tools::parseCommandLine(app, argc, argv);
  if (parsed != tools::kRun) return parsed;
  nb::CellParams cell;
  if (!loadCell(params_path, supply_pa, &cell)) return 2;
  if (!trace_path.empty() && plans.size() != 1) {
    std::cerr << "bed_study: --trace needs exactly one plan in --plans\n";
    return 2;
  }
  std::map<std::string, std::string> plan_args;
  if (!keyValues(plan_arg_list, &plan_args)) return 2;
  if (const nb::Status valid = body.validate(); !valid.ok()) {
    std::cerr << "bed_study: --mass-kg / --height-m: " << valid.message() << "\n";
    return 2;
  }

  std::filesystem::create_directories(out_dir);
  if (!plans.empty())
    return supportTable({plans, duration_s, warmup_s, body, articulated, plan_args, trace_path}, out_dir, cell);
  return wholeStudy(out_dir, cell, articulated, period_s);
}
