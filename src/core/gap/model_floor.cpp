// decideVerdictAboveFloor(): the verdict for a model that never fits to the noise
// (doc/gap_real_recordings.md, "The model-form floor").
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/gap/diagnosis_stages.h"

namespace nursing_bed {
namespace {

using gap::fmt;
using gap::joinNames;

/// The floor and a candidate's standing above it.
struct FloorScore {
  double fit_floor = 1.0;   ///< calibrated nominal chi2/n on the fit runs (>= 1)
  double held_floor = 1.0;  ///< the same on the withheld runs (>= 1)
  int n = 1;

  /// BIC change with chi2 counted in floor units (the penalty, k ln n, unchanged).
  double scaledBic(const CandidateFit& c, const NominalScore& nominal) const {
    const double chi2_change = c.chi2 - nominal.chi2;
    return chi2_change / fit_floor + (c.bic_delta - chi2_change);
  }
  /// Share of the calibrated model's chi2 the candidate removes on the fit runs.
  double fitRemoved(const CandidateFit& c, const NominalScore& nominal) const {
    return nominal.chi2 > 0.0 ? 1.0 - c.chi2 / nominal.chi2 : 0.0;
  }
  /// The same on the withheld runs (NaN without withheld runs).
  double heldRemoved(const CandidateFit& c, const NominalScore& nominal) const {
    if (nominal.withheld_residuals == 0 || !(nominal.withheld_chi2_per_sample > 0.0)) return NAN;
    return 1.0 - c.withheld_chi2_per_sample / nominal.withheld_chi2_per_sample;
  }
};

std::string pct(double share) { return fmt(100.0 * share, 3) + " %"; }

}  // namespace

bool modelFloorApplies(const DiagnosisOptions& options,
                       const std::vector<const std::map<std::string, std::string>*>& metas) {
  if (options.model_floor == "on") return true;
  if (options.model_floor == "off") return false;
  if (options.model_floor != "auto")
    throw std::invalid_argument("model_floor must be auto, on or off, got '" + options.model_floor + "'");
  return !metas.empty() &&
         std::all_of(metas.begin(), metas.end(), [](const auto* m) { return m && m->count("import_mapping") > 0; });
}

Verdict decideVerdictAboveFloor(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
                                const DiagnosisOptions& options) {
  Verdict v;
  FloorScore f;
  f.n = std::max(1, nominal.fit_residuals);
  f.fit_floor = std::max(1.0, nominal.chi2 / f.n);
  const bool held = nominal.withheld_residuals > 0;
  f.held_floor = held ? std::max(1.0, nominal.withheld_chi2_per_sample) : 1.0;
  v.reasons.push_back("model-form floor: the calibrated model stays at chi2/n " + fmt(f.fit_floor) +
                      " on the fit runs" + (held ? ", " + fmt(f.held_floor) + " on the withheld runs" : "") +
                      "; chi2 counted in units of it, a candidate is named when it lowers BIC by more than " +
                      fmt(options.significant_bic_drop) + " and removes at least " + pct(options.floor_removed) +
                      " of it on the fit" + (held ? " and the withheld" : "") + " runs");
  int shown = 0;
  for (std::size_t pass = 1; pass <= 2 && v.winner < 0; ++pass)
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const CandidateFit& c = candidates[i];
      if (!c.ok || !c.plausible || c.effects.size() != pass) continue;
      const double bic = f.scaledBic(c, nominal);
      if (!(bic < -options.significant_bic_drop)) continue;
      const double fit_share = f.fitRemoved(c, nominal), held_share = f.heldRemoved(c, nominal);
      const bool fit_ok = fit_share >= options.floor_removed;
      const bool held_ok = !held || (held_share >= options.floor_removed &&
                                     (nominal.withheld_chi2_per_sample - c.withheld_chi2_per_sample) *
                                             nominal.withheld_residuals / f.held_floor >=
                                         options.min_withheld_gain);
      if (shown++ < 4) {
        std::ostringstream e;
        e << joinNames(c.effects) << ": BIC " << fmt(bic, 4) << " in floor units; removes " << pct(fit_share)
          << " of the floor's chi2 on the fit runs";
        if (held) e << ", " << pct(held_share) << " on the withheld runs";
        e << (fit_ok && held_ok ? ": named" : ": too little");
        v.reasons.push_back(e.str());
      }
      if (fit_ok && held_ok) {
        v.winner = static_cast<int>(i);
        break;
      }
    }
  if (v.winner >= 0) {
    const CandidateFit& w = candidates[v.winner];
    v.status = "explained";
    v.reasons.push_back("what remains: chi2/n " + fmt(w.chi2 / f.n) + " on the fit runs" +
                        (held ? ", " + fmt(w.withheld_chi2_per_sample) + " on the withheld runs" : "") +
                        ", the model's form (see the localisation)");
  } else {
    v.status = "none";
    v.reasons.push_back("no candidate removes enough beyond the model-form floor: what remains (chi2/n " +
                        fmt(f.fit_floor) + ") is the model's form, not a named effect (see the localisation)");
  }
  return v;
}

}  // namespace nursing_bed
