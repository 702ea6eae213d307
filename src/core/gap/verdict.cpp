// decideVerdict(): the decision of doc/gap_diagnosis.md ("Decisions") over fitted candidates.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "nursing_bed/core/gap/diagnosis_stages.h"

namespace nursing_bed {
namespace {

using gap::fmt;
using gap::joinNames;

/// The tests a candidate must pass, against the nominal model's score.
class VerdictRules {
 public:
  VerdictRules(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
               const DiagnosisOptions& options)
      : candidates_(candidates),
        nominal_(nominal),
        options_(options),
        n_(nominal.fit_residuals),
        held_before_(nominal.withheld_residuals > 0 ? nominal.withheld_chi2_per_sample
                                                    : std::numeric_limits<double>::quiet_NaN()) {}

  bool anythingWithheld() const { return std::isfinite(held_before_); }
  double heldBefore() const { return held_before_; }
  double chi2nNominal() const { return nominal_.chi2 / n_; }
  int fitResiduals() const { return n_; }

  /// Lowers BIC and chi2/n enough, with plausible parameters.
  bool significant(const CandidateFit& c) const { return c.plausible && significantAtAnyMagnitude(c); }
  /// Lowers BIC and chi2/n enough, whatever its parameters.
  bool significantAtAnyMagnitude(const CandidateFit& c) const {
    return c.ok && c.bic_delta < -options_.significant_bic_drop && drop(c) >= options_.min_chi2_drop;
  }
  /// Leaves the fit runs within the noise, or removes nearly all of the nominal excess.
  bool fitsFitRuns(const CandidateFit& c) const {
    return c.chi2 / n_ <= options_.explained_chi2 ||
           c.chi2 / n_ - 1.0 <= (1.0 - options_.explained_excess_removed) * (chi2nNominal() - 1.0);
  }
  /// Holds up on the withheld runs: within the noise (or most of their gap removed), and their
  /// held-out likelihood rises by min_withheld_gain.
  bool fitsWithheld(const CandidateFit& c) const {
    if (!anythingWithheld()) return true;
    const double after = c.withheld_chi2_per_sample;
    const bool within = after <= options_.withheld_chi2 ||
                        (after - 1.0) <= (1.0 - options_.withheld_gap_removed) * (held_before_ - 1.0);
    return within && (held_before_ - after) * nominal_.withheld_residuals >= options_.min_withheld_gain;
  }
  bool explainsAlone(const CandidateFit& c) const { return significant(c) && fitsFitRuns(c) && fitsWithheld(c); }
  /// A single that would explain the gap but for its magnitude, leaving both the fit runs and the
  /// withheld runs within the noise (not only most of a deep gap removed): where nothing
  /// plausible explains it, the runs prove the magnitude. Needs withheld runs.
  bool explainsBeyondPlausible(const CandidateFit& c) const {
    const double held = c.withheld_chi2_per_sample;
    return c.beyond_plausible && c.effects.size() == 1 && anythingWithheld() && significantAtAnyMagnitude(c) &&
           c.chi2 / n_ <= options_.explained_chi2 && held <= options_.withheld_chi2 &&
           (held_before_ - held) * nominal_.withheld_residuals >= options_.min_withheld_gain;
  }

  /// A pair only where it beats the better of its two singles significantly, and neither single
  /// explains the gap alone (the simpler answer first) -- unless that single explains it only by
  /// removing most of a deep gap (chi2/n above explained_chi2) while the pair takes the rest
  /// (leaves the fit runs within the noise, or removes explained_excess_removed of what the
  /// single leaves above it) and lowers the withheld runs' chi2 by min_withheld_gain more: two
  /// effects whose single fits each bend to the other's signature (a flow meter's bias and a
  /// sensor lag: in a gap 1.16e5 deep the bias alone left chi2/n 174, the pair 1.51) -- or
  /// where the withheld runs need the pair (withheldRunsNeedThePair()).
  bool pairEarnsItsPlace(const CandidateFit& pair) const {
    bool first = true;
    for (const CandidateFit& c : candidates_) {
      if (!c.ok || c.effects.size() != 1) continue;
      if (std::find(pair.effects.begin(), pair.effects.end(), c.effects[0]) == pair.effects.end()) continue;
      if (explainsAlone(c) && !pairWithinNoiseWhereSingleIsNot(c, pair) && !withheldRunsNeedThePair(c, pair))
        return false;
      if (first && (c.bic_delta - pair.bic_delta < options_.significant_bic_drop ||
                    (c.chi2 - pair.chi2) / n_ < options_.min_chi2_drop))
        return false;
      first = false;
    }
    return true;
  }
  bool pairWithinNoiseWhereSingleIsNot(const CandidateFit& single, const CandidateFit& pair) const {
    const double held_gain =
        (single.withheld_chi2_per_sample - pair.withheld_chi2_per_sample) * nominal_.withheld_residuals;
    const double single_n = single.chi2 / n_, pair_n = pair.chi2 / n_;
    const bool takes_the_rest = pair_n <= options_.explained_chi2 ||
                                pair_n - 1.0 <= (1.0 - options_.explained_excess_removed) * (single_n - 1.0);
    return single_n > options_.explained_chi2 && takes_the_rest &&
           (!anythingWithheld() || held_gain >= options_.min_withheld_gain);
  }
  /// The withheld runs show what a single within the noise on the fit runs misses
  /// (DiagnosisOptions::pair_withheld_share): it leaves their chi2 more than 3 sd of chi2 above
  /// the noise and the pair removes that share of it. A single that only removes most of a deep
  /// gap is judged by pairWithinNoiseWhereSingleIsNot().
  bool withheldRunsNeedThePair(const CandidateFit& single, const CandidateFit& pair) const {
    if (!anythingWithheld() || single.chi2 / n_ > options_.explained_chi2) return false;
    const double n_held = nominal_.withheld_residuals;
    const double excess = (single.withheld_chi2_per_sample - 1.0) * n_held;
    const double gain = (single.withheld_chi2_per_sample - pair.withheld_chi2_per_sample) * n_held;
    return excess > 3.0 * std::sqrt(2.0 * n_held) && gain >= options_.min_withheld_gain &&
           gain >= options_.pair_withheld_share * excess;
  }
  /// Why `pair` was named over a single that explains the gap alone, in words; empty if not so.
  std::string pairNeededInWords(const CandidateFit& pair) const {
    for (const CandidateFit& c : candidates_) {
      if (!c.ok || c.effects.size() != 1 || !explainsAlone(c) || !withheldRunsNeedThePair(c, pair)) continue;
      if (std::find(pair.effects.begin(), pair.effects.end(), c.effects[0]) == pair.effects.end()) continue;
      const double n_held = nominal_.withheld_residuals;
      return c.effects[0] + " alone leaves the withheld runs' chi2 " +
             fmt((c.withheld_chi2_per_sample - 1.0) * n_held, 4) +
             " above their noise (3 sd: " + fmt(3.0 * std::sqrt(2.0 * n_held), 3) + "); " + joinNames(pair.effects) +
             " lowers it by " + fmt((c.withheld_chi2_per_sample - pair.withheld_chi2_per_sample) * n_held, 4) +
             ": the withheld runs need the pair";
    }
    return {};
  }
  bool admissible(const CandidateFit& c) const {
    return significant(c) && (c.effects.size() == 1 || pairEarnsItsPlace(c));
  }

 private:
  double drop(const CandidateFit& c) const { return (nominal_.chi2 - c.chi2) / n_; }

  const std::vector<CandidateFit>& candidates_;
  const NominalScore& nominal_;
  const DiagnosisOptions& options_;
  const int n_;
  const double held_before_;
};

std::string rulesInWords(const DiagnosisOptions& o) {
  return "a candidate is significant when BIC drops by more than " + fmt(o.significant_bic_drop) +
         " and chi2/n by at least " + fmt(o.min_chi2_drop) + "; it explains the gap when it leaves " +
         "chi2/n <= " + fmt(o.explained_chi2) + " on the fit runs (or removes " +
         fmt(100.0 * o.explained_excess_removed) + " % of the excess over 1), <= " + fmt(o.withheld_chi2) +
         " on the withheld runs (or removes " + fmt(100.0 * o.withheld_gap_removed) +
         " %) and lowers their chi2 by at least " + fmt(o.min_withheld_gain);
}

/// One significant candidate's line: its scores and whether it explains the gap.
std::string candidateInWords(const CandidateFit& c, const VerdictRules& rules, const NominalScore& nominal) {
  const int n = nominal.fit_residuals, n_held = nominal.withheld_residuals;
  std::ostringstream e;
  e << joinNames(c.effects) << ": BIC " << fmt(c.bic_delta, 4) << ", chi2/n " << fmt(c.chi2 / n) << " on the fit runs";
  if (rules.anythingWithheld())
    e << ", " << fmt(c.withheld_chi2_per_sample) << " on the withheld runs (chi2 "
      << fmt(rules.heldBefore() * n_held, 5) << " -> " << fmt(c.withheld_chi2_per_sample * n_held, 5) << ", nrmse "
      << fmt(nominal.withheld_nrmse) << " -> " << fmt(c.withheld_nrmse) << ")";
  const bool fit_ok = rules.fitsFitRuns(c), held_ok = rules.fitsWithheld(c);
  e << (fit_ok && held_ok ? ": explains the gap"
        : !fit_ok         ? ": leaves too much on the fit runs"
                          : ": does not hold up on the withheld runs");
  return e.str();
}

/// Candidates in BIC order; the first that is significant and holds up (fits the fit runs
/// within the noise, and the withheld runs too, better than the nominal model) wins. -1: none.
int firstThatExplains(const std::vector<CandidateFit>& candidates, const VerdictRules& rules,
                      const NominalScore& nominal, std::vector<std::string>* reasons) {
  int significant_count = 0;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const CandidateFit& c = candidates[i];
    if (!rules.admissible(c)) continue;
    ++significant_count;
    reasons->push_back(candidateInWords(c, rules, nominal));
    if (rules.fitsFitRuns(c) && rules.fitsWithheld(c)) {
      const std::string needed = c.effects.size() > 1 ? rules.pairNeededInWords(c) : std::string();
      if (!needed.empty()) reasons->push_back(needed);
      return static_cast<int>(i);
    }
    if (significant_count >= 4) break;  // the rest fit worse still
  }
  if (significant_count == 0) reasons->push_back("no candidate improves the fit significantly");
  return -1;
}

/// Where nothing plausible explains the gap: the first single in BIC order that does but for its
/// magnitude (VerdictRules::explainsBeyondPlausible()), named with that said. -1: none.
int firstBeyondPlausible(const std::vector<CandidateFit>& candidates, const VerdictRules& rules,
                         std::vector<std::string>* reasons) {
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const CandidateFit& c = candidates[i];
    if (!rules.explainsBeyondPlausible(c)) continue;
    std::ostringstream e;
    e << joinNames(c.effects) << " (";
    for (auto p = c.params.begin(); p != c.params.end(); ++p)
      e << (p == c.params.begin() ? "" : ", ") << p->first << " = " << fmt(p->second, 3);
    e << ") lies beyond its plausible range, and alone leaves the fit runs and the withheld runs within the noise "
         "(chi2/n "
      << fmt(c.chi2 / rules.fitResiduals()) << " and " << fmt(c.withheld_chi2_per_sample)
      << "): named; the magnitude is unusual, check that channel or part of the rig";
    reasons->push_back(e.str());
    return static_cast<int>(i);
  }
  return -1;
}

/// A near tie on the fit runs: a candidate (no more effects than the winner) that also explains
/// the gap and fits the fit runs about as well; the withheld runs decide. Returns the winner.
int settleNearTies(const std::vector<CandidateFit>& candidates, int winner, const VerdictRules& rules,
                   const NominalScore& nominal, const DiagnosisOptions& options, std::vector<std::string>* reasons) {
  if (winner < 0 || !rules.anythingWithheld()) return winner;
  const CandidateFit& w = candidates[winner];
  const int n_held = nominal.withheld_residuals;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const CandidateFit& c = candidates[i];
    if (static_cast<int>(i) == winner || c.effects.size() > w.effects.size()) continue;
    if (!(std::fabs(c.bic_delta - w.bic_delta) < options.near_tie_bic)) continue;
    if (!rules.explainsAlone(c) || (c.effects.size() > 1 && !rules.pairEarnsItsPlace(c))) continue;
    const double gain = (w.withheld_chi2_per_sample - c.withheld_chi2_per_sample) * n_held;
    std::ostringstream e;
    e << joinNames(w.effects) << " and " << joinNames(c.effects) << " fit the fit runs about equally well (BIC "
      << fmt(w.bic_delta, 5) << " and " << fmt(c.bic_delta, 5) << "); on the withheld runs their chi2 is "
      << fmt(w.withheld_chi2_per_sample * n_held, 5) << " and " << fmt(c.withheld_chi2_per_sample * n_held, 5);
    if (gain >= options.min_withheld_gain) {
      e << ": the withheld runs decide for " << joinNames(c.effects);
      reasons->push_back(e.str());
      return static_cast<int>(i);
    }
    e << ": "
      << (gain <= -options.min_withheld_gain
              ? "the withheld runs confirm " + joinNames(w.effects)
              : "the withheld runs do not tell them apart either; " + joinNames(w.effects) + " by BIC");
    reasons->push_back(e.str());
  }
  return winner;
}

}  // namespace

Verdict decideVerdict(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
                      const DiagnosisOptions& options) {
  Verdict v;
  const VerdictRules rules(candidates, nominal, options);
  v.reasons.push_back(rulesInWords(options));
  v.winner = firstThatExplains(candidates, rules, nominal, &v.reasons);
  v.winner = settleNearTies(candidates, v.winner, rules, nominal, options, &v.reasons);
  if (v.winner < 0) v.winner = firstBeyondPlausible(candidates, rules, &v.reasons);
  if (v.winner >= 0) {
    v.status = "explained";
  } else if (rules.chi2nNominal() <= options.within_noise_chi2) {
    v.status = "none";
    v.reasons.push_back(
        "the nominal model fits within the noise, and no candidate both improves it significantly "
        "and holds up on the withheld runs");
  } else {
    v.status = "unexplained";
    v.reasons.push_back("a significant gap that no candidate accounts for");
  }
  return v;
}

}  // namespace nursing_bed
