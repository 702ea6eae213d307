// report.json (doc/formats/gap_report.md), report.md and the traces behind the plots of a gap diagnosis.
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/discovery_terms.h"
#include "nursing_bed/core/gap/distortions.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/identifiability.h"
#include "nursing_bed/core/gap/validation.h"

namespace nursing_bed {
namespace {

using Json = nlohmann::ordered_json;  // keys in the order doc/formats/gap_report.md lists them

/// Shortest exact form of a finite number, "" otherwise (an empty CSV field).
std::string csvNumber(double v) {
  if (!std::isfinite(v)) return "";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

/// A number, or null where it is not finite (JSON has no NaN).
Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json numbers(const std::map<std::string, double>& params) {
  Json j = Json::object();
  for (const auto& [k, v] : params) j[k] = number(v);
  return j;
}

std::string fixed(double v, int digits) {
  if (!std::isfinite(v)) return "–";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

std::string general(double v, int digits = 3) {
  if (!std::isfinite(v)) return "–";
  std::ostringstream s;
  s << std::setprecision(digits) << v;
  return s.str();
}

std::string effectsText(const std::vector<std::string>& effects) {
  std::string s;
  for (std::size_t i = 0; i < effects.size(); ++i) s += (i ? " + " : "") + std::string("`") + effects[i] + "`";
  return s;
}

std::string paramsText(const std::map<std::string, double>& params) {
  std::string s;
  for (const auto& [k, v] : params) {
    std::string unit;
    for (const auto* catalog : {&effectCatalog(), &distortionCatalog(), &discoveryCatalog()})
      for (const auto& e : *catalog)
        if (const EffectParamSpec* p = e.param(k)) unit = p->unit == "-" ? "" : " " + p->unit;
    s += (s.empty() ? "" : ", ") + k + " = " + general(v) + unit;
  }
  return s;
}

double shrinkPercent(double before, double after) { return before > 0.0 ? 100.0 * (1.0 - after / before) : NAN; }

/// "; above the noise floor, 1.22 -> 0 floors (100 % smaller)": the gap a model can remove.
std::string aboveNoiseText(const DiagnosisReport& r) {
  const double before = r.withheldGapInFloors(false), after = r.withheldGapInFloors(true);
  if (!std::isfinite(before) || !std::isfinite(after) || !(before > 0.0)) return {};
  return "; above the noise floor (whitened chi2/n " + fixed(r.nominal_withheld_chi2_per_sample, 2) + " -> " +
         fixed(r.withheld_chi2_after, 2) + ") from " + fixed(before, 2) + " to " + fixed(after, 2) + " noise floors (" +
         fixed(shrinkPercent(before, after), 0) + " % smaller)";
}

/// The `validation` block of report.json: one object per ValidationRow.
Json validationJson(const std::vector<ValidationRow>& rows) {
  Json out = Json::array();
  for (const ValidationRow& v : rows)
    out.push_back({{"signal", v.signal},
                   {"phase", v.phase},
                   {"load_n", number(v.load_n)},
                   {"samples", v.samples},
                   {"e_mean", number(v.e_mean)},
                   {"e_rms", number(v.e_rms)},
                   {"u_data", number(v.u_data)},
                   {"u_num", number(v.u_num)},
                   {"u_input", number(v.u_input)},
                   {"u_val", number(v.u_val)}});
  return out;
}

/// The `calibration` block of report.json (doc/formats/gap_report.md).
Json calibrationJson(const CalibrationSummary& c) {
  Json parameters = Json::array();
  for (const CalibratedParam& p : c.parameters)
    parameters.push_back({{"name", p.name},
                          {"nominal", number(p.nominal)},
                          {"value", number(p.value)},
                          {"fitted", number(p.fitted)},
                          {"std_error", number(p.std_error)},
                          {"moved", p.moved}});
  Json matrix = Json::array();
  for (Eigen::Index a = 0; a < c.correlation.rows(); ++a) {
    Json row = Json::array();
    for (Eigen::Index b = 0; b < c.correlation.cols(); ++b) row.push_back(number(c.correlation(a, b)));
    matrix.push_back(row);
  }
  return {{"parameters", parameters},
          {"correlation", {{"names", c.correlation_names}, {"matrix", matrix}}},
          {"file", c.file},
          {"bic_delta", number(c.bic_delta)},
          {"withheld_nrmse_calibrated_only", number(c.withheld_nrmse)},
          {"withheld_chi2_per_sample", number(c.withheld_chi2_per_sample)},
          {"unidentifiable", c.unidentifiable},
          {"notes", c.notes}};
}

Json localizationJson(const std::vector<GapShare>& localization) {
  Json out = Json::array();
  for (const GapShare& g : localization)
    out.push_back({{"signal", g.signal},
                   {"phase", g.phase},
                   {"load_n", number(g.load_n)},
                   {"share", number(g.share)},
                   {"t_start_s", number(g.t_start_s)},
                   {"t_end_s", number(g.t_end_s)}});
  return out;
}

Json eventsJson(const std::vector<GapEvent>& events) {
  Json out = Json::array();
  for (const GapEvent& e : events)
    out.push_back({{"run", e.run},
                   {"signal", e.signal},
                   {"onset_s", number(e.onset_s)},
                   {"end_s", number(e.end_s)},
                   {"peak_rms", number(e.peak_rms)},
                   {"floor_rms", number(e.floor_rms)}});
  return out;
}

Json candidatesJson(const std::vector<CandidateFit>& candidates) {
  Json out = Json::array();
  for (const CandidateFit& c : candidates)
    out.push_back({{"effects", c.effects},
                   {"params", numbers(c.params)},
                   {"bic_delta", number(c.bic_delta)},
                   {"fit_nrmse", number(c.fit_nrmse)},
                   {"withheld_nrmse", number(c.withheld_nrmse)}});
  return out;
}

}  // namespace

Json confusionsJson(const std::vector<Confusion>& confusions) {
  Json j = Json::array();
  for (const auto& c : confusions) {
    Json e = {{"explanations", {c.a, c.b}},
              {"rival_params", numbers(c.b_params)},
              {"bic_delta", {number(c.bic_a), number(c.bic_b)}},
              {"withheld_chi2", {number(c.withheld_chi2_a), number(c.withheld_chi2_b)}},
              {"correlation", number(c.correlation)},
              {"fit_separation_chi2", number(c.fit_separation_chi2)},
              {"proposed_run", nullptr}};
    if (c.proposed)
      e["proposed_run"] = {{"load_n", c.load_n},
                           {"flow", c.flow},
                           {"rise_scale", c.rise_scale},
                           {"separation_chi2", number(c.separation_chi2)},
                           {"gap_synth_add_run", gap::addRunArgument(c)}};
    j.push_back(e);
  }
  return j;
}

std::string reportJson(const DiagnosisReport& r) {
  Json j;
  j["format"] = "nursing_bed_gap_report/1";
  j["dataset"] = r.dataset;
  j["runs"] = {{"fit", r.fit_runs}, {"withheld", r.withheld_runs}};
  j["noise"] = {{"p_gauge_pa", number(r.noise_p_pa)}, {"h_m", number(r.noise_h_m)}};
  j["localization"] = localizationJson(r.localization);
  j["events"] = eventsJson(r.events);
  j["validation"] = validationJson(r.validation);
  j["candidates"] = candidatesJson(r.candidates);
  if (r.calibration.done) j["calibration"] = calibrationJson(r.calibration);
  j["verdict"] = {{"effects", r.verdict_effects},
                  {"params", numbers(r.verdict_params)},
                  {"status", r.status},
                  {"discovered", r.discovered}};
  j["identifiability"] = confusionsJson(r.confusions);
  j["shrinkage"] = {
      {"withheld_nrmse_before", number(r.withheld_before)},
      {"withheld_nrmse_after", number(r.withheld_after)},
      {"by_signal",
       {{"pressure", {number(r.withheld_p_before), number(r.withheld_p_after)}},
        {"height", {number(r.withheld_h_before), number(r.withheld_h_after)}}}},
      {"withheld_chi2_per_sample", {number(r.nominal_withheld_chi2_per_sample), number(r.withheld_chi2_after)}},
      {"gap_in_noise_floors", {number(r.withheldGapInFloors(false)), number(r.withheldGapInFloors(true))}}};
  // Bytes that are not UTF-8 (a path from another system) are replaced, not an exception.
  return j.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

namespace {

/// report.md: the dataset and its roles.
void headerSection(std::ostream& m, const DiagnosisReport& r) {
  m << "# Sim-to-real gap diagnosis\n\n";
  m << "Dataset: `" << r.dataset << "` — " << r.fit_runs.size() + r.withheld_runs.size() << " runs, "
    << r.fit_runs.size() << " used to fit the candidate effects, " << r.withheld_runs.size()
    << " withheld to check them" << (r.roles_chosen ? " (the dataset gave no roles; the diagnosis chose them)" : "")
    << ". Diagnosed in " << fixed(r.elapsed_s, 1) << " s.\n\n";
}

/// "film_stiffness_scale 1 -> 1.15 (+- 0.01)" for every moved parameter.
std::string calibrationText(const CalibrationSummary& c) {
  std::string s;
  for (const auto& p : c.parameters)
    if (p.moved)
      s += (s.empty() ? "" : ", ") + p.name + " " + general(p.nominal, 4) + " -> " + general(p.value, 4) + " (+- " +
           general(p.std_error, 2) + ")";
  return s.empty() ? "no parameter" : s;
}

/// report.md: the calibration: which parameters moved, and what the runs cannot tell apart.
void calibrationSection(std::ostream& m, const DiagnosisReport& r) {
  const CalibrationSummary& c = r.calibration;
  if (!c.done) return;
  m << "## 0. The model's own parameters (calibration)\n\n"
    << "Fitted on the fit runs before any effect is blamed; a move counts when it exceeds 2 standard errors and "
       "pays for itself in BIC. Parameters that did not move keep their nominal value in `"
    << c.file << "`.\n\n| parameter | nominal | fitted | std. error | moved |\n|---|---|---|---|---|\n";
  for (const auto& p : c.parameters)
    m << "| " << p.name << " [" << p.unit << "] | " << general(p.nominal, 4) << " | " << general(p.fitted, 4) << " | "
      << general(p.std_error, 2) << " | " << (p.moved ? "**yes**" : "no") << " |\n";
  m << "\n";
  for (const auto& g : c.unidentifiable) {
    std::string names;
    for (const auto& n : g) names += (names.empty() ? "" : ", ") + n;
    m << "- The runs cannot tell apart: " << names << " (one of them is calibrated).\n";
  }
  for (const auto& note : c.notes) m << "- " << note << "\n";
  m << "- The calibrated model alone: withheld nrmse " << general(c.withheld_nrmse) << " (nominal "
    << general(r.withheld_before) << ").\n\n";
}

/// report.md: what the runs cannot tell from the verdict, and the run that would.
void identifiabilitySection(std::ostream& m, const DiagnosisReport& r) {
  if (r.confusions.empty()) return;
  m << "## What these runs cannot tell apart\n\n"
    << "Explanations within a few BIC of the verdict's on the fit runs that the withheld runs do not decide "
       "either, and the gap synth run on which the two, each replayed, differ most:\n\n"
    << "| verdict | rival | BIC (fit runs) | correlation | proposed run | chi2 apart there (here) |\n"
       "|---|---|---|---|---|---|\n";
  for (const auto& c : r.confusions)
    m << "| " << c.a << " | " << c.b << " (" << paramsText(c.b_params) << ") | " << general(c.bic_a, 5) << " / "
      << general(c.bic_b, 5) << " | " << fixed(c.correlation, 3) << " | "
      << (c.proposed ? "`--add-run " + gap::addRunArgument(c) + "`" : std::string("none in the grid")) << " | "
      << general(c.separation_chi2, 3) << " (" << general(c.fit_separation_chi2, 3) << ") |\n";
  m << "\n";
}

/// report.md: the verdict and the reasons behind it, and the noise.
void verdictSection(std::ostream& m, const DiagnosisReport& r) {
  m << "## Verdict\n\n";
  if (r.status == "explained") {
    m << "**Explained by " << effectsText(r.verdict_effects) << "** (" << paramsText(r.verdict_params) << "), ";
    for (const auto& d : r.verdict_distortions) m << "**" << d << "**, ";
    m << (r.calibration.anyMoved() ? "on top of the calibrated " + calibrationText(r.calibration) + ". "
                                   : "no model parameter needed recalibration. ");
    m << "On the withheld runs the normalised RMS residual falls from " << fixed(r.withheld_before, 3) << " to "
      << fixed(r.withheld_after, 3) << " (" << fixed(shrinkPercent(r.withheld_before, r.withheld_after), 0)
      << " % smaller)" << aboveNoiseText(r) << ".\n\n";
  } else if (r.status == "calibrated") {
    m << "**Calibrated: the model's own parameters were off; no missing physics is needed.** Recalibrating "
      << calibrationText(r.calibration) << " removes the gap; the calibrated parameter file is `" << r.calibration.file
      << "`. On the withheld runs the normalised RMS residual falls from " << fixed(r.withheld_before, 3) << " to "
      << fixed(r.withheld_after, 3) << ".\n\n";
  } else if (r.status == "discovered") {
    m << "**Discovered: no candidate effect explains the gap, but a correction to the model's balance equations "
         "does** ("
      << paramsText(r.verdict_params) << "):\n\n";
    for (const auto& d : r.discovered) m << "- **" << d << "**\n";
    m << "\n"
      << (r.calibration.anyMoved() ? "On top of the calibrated " + calibrationText(r.calibration) + ". " : "")
      << "On the withheld runs the normalised RMS residual falls from " << fixed(r.withheld_before, 3) << " to "
      << fixed(r.withheld_after, 3) << " (" << fixed(shrinkPercent(r.withheld_before, r.withheld_after), 0)
      << " % smaller)" << aboveNoiseText(r)
      << ". A discovered term names the form of what is missing, not its cause.\n\n";
  } else if (r.status == "none") {
    m << "**No significant gap.** The nominal model already fits the runs within the noise, and no candidate "
         "effect improves the fit by more than its extra parameters cost.\n\n";
  } else {
    m << "**Unexplained gap.** The model and the runs part by more than the noise, and no candidate effect (alone "
         "or in a pair) removes it with plausible parameters. Look for a physical effect outside the candidate "
         "list; the localisation below says where it acts.\n\n";
  }
  m << "How the decision was made:\n\n";
  for (const auto& line : r.reasons) m << "- " << line << "\n";
  m << "\nNoise (robust estimate from the runs): pressure " << general(r.noise_p_pa) << " Pa, height "
    << general(r.noise_h_m * 1e3) << " mm.\n\n";
}

/// report.md: where in time, from the re-anchored windows.
void eventsSection(std::ostream& m, const DiagnosisReport& r) {
  m << "### Where in time\n\n";
  m << "Each run cut into windows of 0.25 s from every cycle start (setpoint edge), the nominal model restarted at "
       "rest at the measured state at each window's start, so an early error does not carry over. An event is a "
       "stretch of windows whose RMS residual is above 3 noise floors and 3 times the median of the same window "
       "over the run's cycles (the model's own floor there; the noise for a run of fewer than 3 cycles).\n\n";
  if (r.events.empty()) {
    m << "No event.\n\n";
    return;
  }
  m << "| run | signal | onset [s] | end [s] | peak RMS [noise floors] | floor there |\n|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < r.events.size() && i < 40; ++i) {
    const GapEvent& e = r.events[i];
    m << "| " << e.run << " | " << e.signal << " | " << fixed(e.onset_s, 2) << " | " << fixed(e.end_s, 2) << " | "
      << general(e.peak_rms) << " | " << general(e.floor_rms) << " |\n";
  }
  if (r.events.size() > 40) m << "\n(" << r.events.size() - 40 << " more in report.json)\n";
  m << "\n";
}

/// report.md: the validation statement (ASME V&V 20) of the nominal model, pressure in kPa and
/// height in mm.
void validationSection(std::ostream& m, const DiagnosisReport& r) {
  if (r.validation.empty()) return;
  m << "### Validation statement\n\nIn the manner of ASME V&V 20: the comparison error E = S − D (simulated less "
       "measured) of the nominal model, its mean and RMS over the samples the fits use, against the validation "
       "uncertainty u_val = sqrt(u_D² + u_num² + u_input²): the data's (sensor noise), the replay's numerical "
       "(its accuracy, the timing of valve pulses) and the inputs' (the flow meter's noise integrated, the start "
       "height). Where E is within u_val the runs cannot show a model error there; beyond it, the model error is "
       "about E.\n\n";
  m << "| signal | phase | load [N] | samples | E mean | E RMS | u_D | u_num | u_input | u_val | E RMS / u_val "
       "|\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const ValidationRow& v : r.validation) {
    const bool p = v.signal == "pressure";
    const double k = p ? 1e-3 : 1e3;  // kPa, mm
    const int digits = p ? 3 : 2;
    m << "| " << v.signal << (p ? " [kPa]" : " [mm]") << " | " << v.phase << " | " << fixed(v.load_n, 1) << " | "
      << v.samples << " | " << fixed(k * v.e_mean, digits) << " | " << fixed(k * v.e_rms, digits) << " | "
      << fixed(k * v.u_data, digits) << " | " << fixed(k * v.u_num, digits) << " | " << fixed(k * v.u_input, digits)
      << " | " << fixed(k * v.u_val, digits) << " | " << gap::validationWords(v) << " |\n";
  }
  m << "\n";
}

/// report.md: answer 1: where the gap lies.
void whereSection(std::ostream& m, const DiagnosisReport& r) {
  m << "## 1. Where the model and the data part\n\n";
  m << "Each run was replayed through the nominal model with its measured inflow and load. The table splits the "
       "squared residual (each signal normalised by its measured range over all runs) by signal, phase and load; "
       "largest first (shares sum to 1).\n\n";
  m << "| signal | phase | load [N] | share | time in run [s] |\n|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < r.localization.size() && i < 12; ++i) {
    const GapShare& g = r.localization[i];
    m << "| " << g.signal << " | " << g.phase << " | " << fixed(g.load_n, 1) << " | " << fixed(g.share, 3) << " | "
      << fixed(g.t_start_s, 1) << " – " << fixed(g.t_end_s, 1) << " |\n";
  }
  m << "\nPhases: *deploy* = bag unfolding (height rising at low pressure), *pressurize* = inflating near full "
       "height, *hold* = inlet closed, *vent* = gas leaving through the inlet (samples after the plate has landed "
       "are left out).\n\n";
  validationSection(m, r);
  eventsSection(m, r);
}

/// report.md: answer 2: the candidates' fits.
void whichEffectSection(std::ostream& m, const DiagnosisReport& r) {
  m << "## 2. Which effect\n\n";
  m << "Every candidate (and the best one paired with each other, unless it fits within the noise alone) was fitted to "
       "the fit runs by Ceres (Levenberg-Marquardt "
       "on whole replays, started from a grid over the plausible range). BIC Δ < 0 means better than the "
       "nominal model after paying for the parameters; a candidate is significant below −"
    << general(r.options.significant_bic_drop)
    << ". chi2/n is the mean squared residual in units of the noise floor, decorrelated (1 = a model that fits "
       "within the noise).\n\n";
  m << "| effects | fitted parameters | BIC Δ | chi2/n | fit nrmse | withheld nrmse |\n|---|---|---|---|---|---|\n";
  m << "| nominal model | – | 0 | " << general(r.nominal_chi2_per_sample) << " | " << fixed(r.nominal_fit_nrmse, 4)
    << " | " << fixed(r.withheld_before, 4) << " |\n";
  for (const auto& c : r.candidates) {
    m << "| " << effectsText(c.effects) << (c.plausible ? "" : " (implausible)") << " | "
      << (c.ok ? paramsText(c.params) : "failed: " + c.message) << " | " << general(c.bic_delta, 4) << " | "
      << general(r.fit_samples > 0 ? c.chi2 / r.fit_samples : NAN) << " | " << fixed(c.fit_nrmse, 4) << " | "
      << fixed(c.withheld_nrmse, 4) << " |\n";
  }
}

/// report.md: answer 3: the withheld runs before and after.
void shrinkSection(std::ostream& m, const DiagnosisReport& r) {
  m << "\n## 3. How far the gap shrinks on withheld runs\n\n";
  if (r.withheld_runs.empty()) {
    m << "No run was withheld, so there is no independent check.\n\n";
  } else {
    m << "| signal | nrmse before | nrmse after | shrink |\n|---|---|---|---|\n";
    m << "| pressure | " << fixed(r.withheld_p_before, 4) << " | " << fixed(r.withheld_p_after, 4) << " | "
      << fixed(shrinkPercent(r.withheld_p_before, r.withheld_p_after), 0) << " % |\n";
    m << "| height | " << fixed(r.withheld_h_before, 4) << " | " << fixed(r.withheld_h_after, 4) << " | "
      << fixed(shrinkPercent(r.withheld_h_before, r.withheld_h_after), 0) << " % |\n";
    m << "| both (mean) | " << fixed(r.withheld_before, 4) << " | " << fixed(r.withheld_after, 4) << " | "
      << fixed(shrinkPercent(r.withheld_before, r.withheld_after), 0) << " % |\n";
    const double above_before = r.withheldGapInFloors(false), above_after = r.withheldGapInFloors(true);
    m << "| above the noise floor, in floors | " << fixed(above_before, 2) << " | " << fixed(above_after, 2) << " | "
      << fixed(shrinkPercent(above_before, above_after), 0) << " % |\n\n";
    if (r.status != "explained" && r.status != "discovered")
      m << "(Nothing was named, so \"after\" is the nominal model.)\n\n";
    m << "No model leaves less than the noise floor (the sensor noise and the replay's accuracy the fits "
         "whiten by): \"above the noise floor\" is sqrt(chi2/n − 1) of the whitened withheld residuals, the gap "
         "a model can remove, in floors.\n\n";
  }
  m << "nrmse = RMS(measured − simulated) / range of the measured signal, averaged over pressure and height.\n\n";
}

/// report.md: per-run numbers.
void runsSection(std::ostream& m, const DiagnosisReport& r) {
  m << "## Runs\n\n| run | role | load [N] | length [s] | noise p [Pa] | noise h [mm] | nrmse before | nrmse after |\n"
       "|---|---|---|---|---|---|---|---|\n";
  for (const auto& s : r.runs)
    m << "| " << s.name << " | " << s.role << " | " << fixed(s.load_n, 1) << " | " << fixed(s.duration_s, 1) << " | "
      << general(s.noise_p_pa) << " | " << general(s.noise_h_m * 1e3) << " | " << fixed(s.before.nrmse(), 4) << " | "
      << fixed(s.after.nrmse(), 4) << " |\n";
}

/// report.md: the plots written beside report.md.
void figuresSection(std::ostream& m, const DiagnosisReport& r) {
  const std::vector<std::string> causes = r.traces.empty() ? std::vector<std::string>{} : r.traces[0].causes;
  m << "\n## Figures\n\n";
  m << "- `traces.png`: measured pressure and height against the nominal model (dashed) and the model with the "
       "named effect (solid), phases shaded.\n";
  for (const std::string& c : causes)
    m << "- `cause_" << c << ".png`: the data, the model and the model with " << c << " alone.\n";
  m << "- `residual_by_phase.png`: the localisation shares, and the RMS residual per phase before and after.\n";
  m << "- `hp_loops.png`: height against pressure — the loops that friction and viscoelasticity open.\n\n";
  m << "![traces](traces.png)\n\n";
  for (const std::string& c : causes) m << "![" << c << "](cause_" << c << ".png)\n\n";
  m << "![residual by phase](residual_by_phase.png)\n\n![h(p) loops](hp_loops.png)\n";
}

}  // namespace

std::string reportMarkdown(const DiagnosisReport& r) {
  std::ostringstream m;
  headerSection(m, r);
  verdictSection(m, r);
  identifiabilitySection(m, r);
  calibrationSection(m, r);
  whereSection(m, r);
  whichEffectSection(m, r);
  shrinkSection(m, r);
  runsSection(m, r);
  figuresSection(m, r);
  return m.str();
}

void writeReportFiles(const std::string& dir, const DiagnosisReport& r) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(fs::path(dir) / "traces", ec);
  if (ec) throw std::runtime_error(dir + ": cannot create the output directory: " + ec.message());
  auto write = [](const fs::path& path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    out.close();
    if (!out) throw std::runtime_error(path.string() + ": cannot write");
  };
  // Traces of an earlier report in the same directory would be plotted with this one's.
  for (const auto& old : fs::directory_iterator(fs::path(dir) / "traces", ec))
    if (old.is_regular_file() && old.path().extension() == ".csv") fs::remove(old.path(), ec);
  write(fs::path(dir) / "report.json", reportJson(r));
  write(fs::path(dir) / "report.md", reportMarkdown(r));
  if (r.calibration.done && !r.calibrated_yaml.empty()) write(fs::path(dir) / r.calibration.file, r.calibrated_yaml);
  for (const auto& t : r.traces) {
    std::ostringstream s;
    s << "# run: " << t.name << "\n# role: " << t.role << "\n";
    for (const auto& run : r.runs)
      if (run.name == t.name)
        s << "# load_n: " << (std::isfinite(run.load_n) ? csvNumber(run.load_n) : std::string("null")) << "\n";
    s << "t_s,mdot_in_kg_s,p_meas_pa,h_meas_m,p_nominal_pa,h_nominal_m,p_after_pa,h_after_m";
    for (const std::string& c : t.causes) s << ",p_with_" << c << "_pa,h_with_" << c << "_m";
    s << ",phase\n";
    auto num = csvNumber;
    for (std::size_t i = 0; i < t.t_s.size(); ++i) {
      s << num(t.t_s[i]) << ',' << num(t.mdot_in_kg_s[i]) << ',' << num(t.p_meas_pa[i]) << ',' << num(t.h_meas_m[i])
        << ',' << num(t.p_nominal_pa[i]) << ',' << num(t.h_nominal_m[i]) << ',' << num(t.p_after_pa[i]) << ','
        << num(t.h_after_m[i]);
      for (std::size_t c = 0; c < t.causes.size(); ++c)
        s << ',' << num(i < t.p_cause_pa[c].size() ? t.p_cause_pa[c][i] : NAN) << ','
          << num(i < t.h_cause_m[c].size() ? t.h_cause_m[c][i] : NAN);
      s << ',' << phaseName(t.phases[i]) << "\n";
    }
    // The whole run name, made a file name: a bag's runs are "bag/topic/state", and every
    // run of a bag ends in the same "state".
    std::string stem = t.name;
    for (char& c : stem)
      if (c == '/' || c == ':' || c == '\\') c = '_';
    stem.erase(0, stem.find_first_not_of('_'));
    if (fs::path(stem).extension() != ".csv") stem += ".csv";
    write(fs::path(dir) / "traces" / stem, s.str());
  }
}

}  // namespace nursing_bed
