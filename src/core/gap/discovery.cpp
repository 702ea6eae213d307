#include "nursing_bed/core/gap/discovery.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <random>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/discovery_terms.h"

namespace nursing_bed {
namespace gap {
namespace {

/// Probe of a term's coefficient for its sensitivity, in units of its scale: small enough that
/// the residuals move linearly, large enough to stand above the replay's own numerical noise.
constexpr double kProbe = 0.1;
/// Blocks per fit run for the bootstrap: long enough to keep a phase (rise, hold, vent) together.
constexpr int kBlocksPerRun = 10;
constexpr std::uint32_t kResampleSeed = 1;

/// chi2 of the weighted linear model restricted to `set` at its least-squares coefficients.
double subsetChi2(const Eigen::MatrixXd& gram, const Eigen::VectorXd& b, double s0, const std::vector<int>& set,
                  Eigen::VectorXd* coefficients = nullptr) {
  const int k = static_cast<int>(set.size());
  if (k == 0) return s0;
  Eigen::MatrixXd g(k, k);
  Eigen::VectorXd bs(k);
  for (int i = 0; i < k; ++i) {
    bs(i) = b(set[i]);
    for (int j = 0; j < k; ++j) g(i, j) = gram(set[i], set[j]);
  }
  const Eigen::VectorXd c = -g.ldlt().solve(bs);
  if (coefficients) *coefficients = c;
  return s0 + bs.dot(c);
}

/// Residual slots of every fit run cut into kBlocksPerRun blocks, [begin, end).
std::vector<std::pair<int, int>> residualBlocks(const FitData& fit) {
  std::vector<std::pair<int, int>> blocks;
  int offset = 0;
  for (const auto& run : fit.runs) {
    const int samples = static_cast<int>(run.index.size());
    const int per_block = std::max(1, (samples + kBlocksPerRun - 1) / kBlocksPerRun);
    for (int s = 0; s < samples; s += per_block)
      blocks.emplace_back(offset + 2 * s, offset + 2 * std::min(samples, s + per_block));
    offset += 2 * samples;
  }
  return blocks;
}

/// The terms' effects at coefficients `values` (by parameter name).
std::vector<CellEffectPtr> termEffects(const ModelSpec& model, const std::map<std::string, double>& values) {
  return buildEffects(model, values);
}

double heldChi2(const FitData& held, const CellParams& cell, const std::vector<CellEffectPtr>& effects) {
  std::vector<double> r(held.residualCount());
  fitResiduals(held, cell, effects, r.data());
  return sumSquares(r);
}

/// What a refit of the stable terms left.
struct TermFit {
  ModelSpec model;
  FitOutcome outcome;
  std::map<std::string, double> values;
  double held_chi2 = NAN;
};

/// Fits `terms` together by replay from `starts` (fit coordinates).
TermFit fitTerms(const NoiseModel& noise, const CellParams& held_cell, const std::vector<std::string>& terms,
                 const std::map<std::string, double>& calibration, const std::vector<std::vector<double>>& starts,
                 const DiagnosisOptions& options) {
  TermFit f;
  f.model = makeModelSpec(terms);
  f.model.fixed_calibration = calibration;
  f.outcome = fitModel(noise.fit, f.model, starts, options.max_iterations);
  if (!f.outcome.ok) return f;
  f.values = valuesOf(f.model, f.outcome.u);
  f.held_chi2 = heldChi2(noise.held, held_cell, termEffects(f.model, f.values));
  return f;
}

/// How often each term is selected over the resamples: the best single (bestSingleTerm), then,
/// where that is the most selected single, forward selection linearised at its fit.
std::vector<int> selectionCounts(const NoiseModel& noise, const CellParams& cell, const std::vector<std::string>& names,
                                 const std::vector<SingleTermFit>& singles, const Eigen::VectorXd& r0, double penalty,
                                 const DiagnosisOptions& options) {
  const std::vector<Eigen::VectorXd> weights = blockBootstrap(residualBlocks(noise.fit), static_cast<int>(r0.size()),
                                                              options.discovery_resamples, kResampleSeed);
  std::vector<int> counts(names.size(), 0), first;
  for (const auto& w : weights) {
    first.push_back(bestSingleTerm(singles, r0, w, penalty));
    if (first.back() >= 0) ++counts[first.back()];
  }
  const int lead = static_cast<int>(std::max_element(counts.begin(), counts.end()) - counts.begin());
  if (counts[lead] == 0 || options.discovery_max_terms < 2) return counts;
  const auto lead_effect =
      std::make_shared<DiscoveredTermEffect>(*dictionaryTerm(names[lead]), singles[lead].coefficient);
  const Eigen::MatrixXd J = termSensitivities(noise.fit, cell, {lead_effect}, names, kProbe);
  for (std::size_t s = 0; s < weights.size(); ++s) {
    if (first[s] != lead) continue;
    for (int k : forwardSelect(J, singles[lead].residuals, weights[s], penalty, options.discovery_max_terms, {lead}))
      if (k != lead) ++counts[k];
  }
  return counts;
}

/// Index of the kept term whose removal costs the withheld runs least, and that cost.
std::pair<int, double> weakestTerm(const NoiseModel& noise, const CellParams& held_cell, const TermFit& f,
                                   double held_chi2_without_any) {
  if (f.model.effects.size() == 1) return {0, held_chi2_without_any - f.held_chi2};
  std::pair<int, double> weakest{-1, INFINITY};
  for (std::size_t j = 0; j < f.model.axes.size(); ++j) {
    std::map<std::string, double> without = f.values;
    without[f.model.axes[j].spec.name] = 0.0;
    const double cost = heldChi2(noise.held, held_cell, termEffects(f.model, without)) - f.held_chi2;
    if (cost < weakest.second) weakest = {static_cast<int>(j), cost};
  }
  return weakest;
}

}  // namespace

Eigen::MatrixXd termSensitivities(const FitData& fit, const CellParams& cell, const std::vector<CellEffectPtr>& base,
                                  const std::vector<std::string>& terms, double probe) {
  const int n = fit.residualCount();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, static_cast<int>(terms.size()));
  std::vector<double> at_base(n), up(n), down(n);
  if (!fitResiduals(fit, cell, base, at_base.data())) return J;
  auto with = [&base](const DictionaryTerm& term, double c) {
    std::vector<CellEffectPtr> effects = base;
    effects.push_back(std::make_shared<DiscoveredTermEffect>(term, c));
    return effects;
  };
  for (std::size_t j = 0; j < terms.size(); ++j) {
    const DictionaryTerm* term = dictionaryTerm(terms[j]);
    if (!term) throw std::invalid_argument("discovery: '" + terms[j] + "' is not a term of the dictionary");
    const double c = probe * term->scale;
    // One side may fail (a plate force along the motion undamps the plate): the other then
    // gives a one-sided difference.
    const bool ok_up = fitResiduals(fit, cell, with(*term, c), up.data());
    const bool ok_down = fitResiduals(fit, cell, with(*term, -c), down.data());
    if (!ok_up && !ok_down) continue;
    const double* hi = ok_up ? up.data() : at_base.data();
    const double* lo = ok_down ? down.data() : at_base.data();
    const double step = (ok_up ? probe : 0.0) + (ok_down ? probe : 0.0);
    for (int i = 0; i < n; ++i) J(i, static_cast<int>(j)) = (hi[i] - lo[i]) / step;
  }
  return J;
}

std::vector<int> forwardSelect(const Eigen::MatrixXd& J, const Eigen::VectorXd& r0, const Eigen::VectorXd& weight,
                               double penalty, int max_terms, const std::vector<int>& initial) {
  const Eigen::MatrixXd WJ = J.array().colwise() * weight.array();
  const Eigen::MatrixXd gram = J.transpose() * WJ;
  const Eigen::VectorXd b = WJ.transpose() * r0;
  const double s0 = r0.dot(r0.cwiseProduct(weight));
  const double n = std::max(1.0, weight.sum());
  std::vector<int> set = initial;
  double chi2 = subsetChi2(gram, b, s0, set);
  while (static_cast<int>(set.size()) < max_terms) {
    int best = -1;
    double best_chi2 = chi2;
    for (int k = 0; k < J.cols(); ++k) {
      if (std::find(set.begin(), set.end(), k) != set.end() || gram(k, k) <= 0.0) continue;
      std::vector<int> trial = set;
      trial.push_back(k);
      const double c = subsetChi2(gram, b, s0, trial);
      if (c < best_chi2) {
        best_chi2 = c;
        best = k;
      }
    }
    if (best < 0 || (chi2 - best_chi2) / std::max(1.0, best_chi2 / n) <= penalty) break;
    set.push_back(best);
    chi2 = best_chi2;
  }
  return set;
}

std::vector<Eigen::VectorXd> blockBootstrap(const std::vector<std::pair<int, int>>& blocks, int rows, int resamples,
                                            std::uint32_t seed) {
  std::vector<Eigen::VectorXd> weights;
  std::mt19937 rng(seed);
  for (int s = 0; s < resamples; ++s) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rows);
    if (!blocks.empty()) {
      std::uniform_int_distribution<std::size_t> pick(0, blocks.size() - 1);
      for (std::size_t k = 0; k < blocks.size(); ++k) {
        const auto& [begin, end] = blocks[pick(rng)];
        w.segment(begin, end - begin).array() += 1.0;
      }
    }
    weights.push_back(std::move(w));
  }
  return weights;
}

std::vector<SingleTermFit> fitSingleTerms(const FitData& fit, const CellParams& cell,
                                          const std::map<std::string, double>& calibration,
                                          const std::vector<std::string>& names, const DiagnosisOptions& options) {
  std::vector<SingleTermFit> out(names.size());
  const int n = fit.residualCount();
  parallelFor(static_cast<int>(names.size()), options.threads, [&](int j) {
    ModelSpec m = makeModelSpec({names[j]});
    m.fixed_calibration = calibration;
    const FitOutcome o = fitModel(fit, m, gridStarts(m), options.max_iterations);
    SingleTermFit& f = out[j];
    if (!o.ok) return;
    f.u = o.u[0];
    f.coefficient = m.axes[0].toValue(f.u);
    f.chi2 = o.chi2;
    const DictionaryTerm& term = *dictionaryTerm(names[j]);
    std::vector<double> at(n), next(n);
    const double du = kProbe / 2.0;  // the axis spans [-scale, scale]: u moves half as fast as c / scale
    bool ok = fitResiduals(fit, cell, {std::make_shared<DiscoveredTermEffect>(term, f.coefficient)}, at.data());
    double step = du;
    if (!fitResiduals(fit, cell, {std::make_shared<DiscoveredTermEffect>(term, m.axes[0].toValue(f.u + du))},
                      next.data())) {
      step = -du;  // the other side (a term along the motion may undamp the plate)
      ok = ok && fitResiduals(fit, cell, {std::make_shared<DiscoveredTermEffect>(term, m.axes[0].toValue(f.u - du))},
                              next.data());
    }
    if (!ok) return;
    f.residuals = Eigen::Map<const Eigen::VectorXd>(at.data(), n);
    f.slope = (Eigen::Map<const Eigen::VectorXd>(next.data(), n) - f.residuals) / step;
    f.ok = true;
  });
  return out;
}

int bestSingleTerm(const std::vector<SingleTermFit>& singles, const Eigen::VectorXd& r0, const Eigen::VectorXd& weight,
                   double penalty) {
  const double n = std::max(1.0, weight.sum());
  const double chi2_0 = r0.dot(r0.cwiseProduct(weight));
  int best = -1;
  double best_chi2 = chi2_0;
  for (std::size_t j = 0; j < singles.size(); ++j) {
    const SingleTermFit& f = singles[j];
    if (!f.ok) continue;
    const Eigen::VectorXd wg = f.slope.cwiseProduct(weight);
    const double gg = f.slope.dot(wg), gr = f.residuals.dot(wg);
    const double chi2 = f.residuals.dot(f.residuals.cwiseProduct(weight)) - (gg > 0.0 ? gr * gr / gg : 0.0);
    if (chi2 < best_chi2) {
      best_chi2 = chi2;
      best = static_cast<int>(j);
    }
  }
  if (best < 0 || (chi2_0 - best_chi2) / std::max(1.0, best_chi2 / n) <= penalty) return -1;
  return best;
}

namespace {

/// Fits the `stable` terms together, dropping (and saying so in `reasons`) the one whose removal
/// costs the withheld runs least while that is below min_withheld_gain; `stable` keeps the rest
/// (empty when none holds, or when a fit fails).
TermFit pruneTerms(const NoiseModel& noise, const CellParams& held_cell,
                   const std::map<std::string, double>& calibration, const std::vector<std::string>& names,
                   const std::vector<SingleTermFit>& singles, double held_base, const DiagnosisOptions& options,
                   const std::function<void(const std::string&)>& progress, std::vector<int>* stable,
                   std::vector<std::string>* reasons) {
  TermFit f;
  while (!stable->empty()) {
    std::vector<std::string> terms;
    // From each term's own fit, and from the best single's with the others at 0.
    std::vector<double> from_singles, from_best;
    const int best = *std::min_element(stable->begin(), stable->end(),
                                       [&](int a, int b) { return singles[a].chi2 < singles[b].chi2; });
    for (int j : *stable) {
      terms.push_back(names[j]);
      from_singles.push_back(singles[j].u);
      from_best.push_back(j == best ? singles[j].u : 0.5);
    }
    if (progress) progress("discovery: fitting " + joinNames(terms));
    f = fitTerms(noise, held_cell, terms, calibration, {from_best, from_singles}, options);
    if (!f.outcome.ok) {
      reasons->push_back("discovery: the fit of " + joinNames(terms) + " failed: " + f.outcome.message);
      stable->clear();
      return f;
    }
    const auto [weakest, cost] = weakestTerm(noise, held_cell, f, held_base);
    if (weakest < 0 || cost >= options.min_withheld_gain) break;
    reasons->push_back("discovery: " + terms[weakest] + " lowers the withheld runs' chi2 by only " + fmt(cost) +
                       " (at least " + fmt(options.min_withheld_gain) + "): dropped");
    stable->erase(stable->begin() + weakest);
  }
  return f;
}

/// The selection in words: how often each term was selected.
std::string selectionTally(const std::vector<std::string>& names, const std::vector<int>& counts, int resamples) {
  std::string tally;
  for (std::size_t j = 0; j < names.size(); ++j)
    if (counts[j] > 0) tally += (tally.empty() ? "" : ", ") + names[j] + " " + std::to_string(counts[j]);
  return "discovery: terms selected in the " + std::to_string(resamples) +
         " resamples: " + (tally.empty() ? std::string("none") : tally);
}

}  // namespace

DiscoveryResult discoverTerms(const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                              const std::map<std::string, double>& calibration, const DiagnosisOptions& options,
                              const std::function<void(const std::string&)>& progress) {
  auto say = [&](const std::string& line) {
    if (progress) progress(line);
  };
  DiscoveryResult out;
  out.resamples = options.discovery_resamples;
  const CellParams cell = applyCalibration(calibration, noise.fit.params);
  const CellParams held_cell = applyCalibration(calibration, noise.held.params);
  const int n = noise.fitResidualCount();
  const double log_n = std::log(static_cast<double>(n));
  std::vector<std::string> names;
  for (const auto& t : discoveryDictionary()) names.push_back(t.name);
  say("discovery: fitting each of the " + std::to_string(names.size()) + " terms of the dictionary alone");
  std::vector<double> base(noise.fit.residualCount());
  fitResiduals(noise.fit, cell, {}, base.data());
  const Eigen::VectorXd r0 = Eigen::Map<const Eigen::VectorXd>(base.data(), static_cast<int>(base.size()));
  const std::vector<SingleTermFit> singles = fitSingleTerms(noise.fit, cell, calibration, names, options);
  const double penalty = log_n + options.significant_bic_drop;
  const std::vector<int> counts = selectionCounts(noise, cell, names, singles, r0, penalty, options);
  const int needed = static_cast<int>(std::ceil(options.discovery_stability * out.resamples - 1e-9));
  std::vector<int> stable;
  for (std::size_t j = 0; j < names.size(); ++j) {
    out.selected[names[j]] = counts[j];
    if (counts[j] > 0 && counts[j] >= needed) stable.push_back(static_cast<int>(j));
  }
  out.reasons.push_back(selectionTally(names, counts, out.resamples));
  const auto most = std::max_element(counts.begin(), counts.end()) - counts.begin();
  if (stable.empty()) {
    out.reasons.push_back("discovery: no term of the dictionary is selected in " + std::to_string(needed) + " of " +
                          std::to_string(out.resamples) + " resamples (most often " + names[most] + ", " +
                          std::to_string(counts[most]) + "): nothing discovered");
    return out;
  }
  if (noise.heldResidualCount() == 0) {
    out.reasons.push_back("discovery: no withheld runs to prove a term on: nothing discovered");
    return out;
  }
  const double held_base = heldChi2(noise.held, held_cell, {});
  const TermFit f =
      pruneTerms(noise, held_cell, calibration, names, singles, held_base, options, progress, &stable, &out.reasons);
  if (stable.empty()) return out;
  out.model = f.model;
  out.chi2 = f.outcome.chi2;
  out.withheld_chi2_per_sample = f.held_chi2 / noise.heldResidualCount();
  const auto withheld = prepared.select(prepared.withheld);
  const CellParams final_cell = applyCalibration(calibration, params);
  out.withheld_nrmse_before = setResidual(withheld, final_cell, {}).total;
  out.withheld_nrmse_after = setResidual(withheld, final_cell, termEffects(f.model, f.values)).total;
  const double fit_base = r0.squaredNorm();
  const double k = static_cast<double>(stable.size());
  const bool significant =
      (fit_base - out.chi2) / std::max(1.0, out.chi2 / n) > k * log_n + options.significant_bic_drop;
  const double shrink = 1.0 - out.withheld_nrmse_after / out.withheld_nrmse_before;
  const bool holds =
      held_base - f.held_chi2 >= options.min_withheld_gain && shrink >= options.discovery_withheld_shrink;
  out.reasons.push_back("discovery: " + joinNames(f.model.effects) + " lowers chi2/n on the fit runs " +
                        fmt(fit_base / n) + " -> " + fmt(out.chi2 / n) + ", on the withheld runs " +
                        fmt(held_base / noise.heldResidualCount()) + " -> " + fmt(out.withheld_chi2_per_sample) +
                        ", withheld nrmse " + fmt(out.withheld_nrmse_before) + " -> " + fmt(out.withheld_nrmse_after) +
                        " (" + fmt(100.0 * shrink, 2) + " % smaller)");
  if (!significant || !holds) {
    out.reasons.push_back(std::string("discovery: ") +
                          (!significant ? "not significant on the fit runs" : "does not hold up on the withheld runs") +
                          ": nothing discovered");
    return out;
  }
  out.discovered = true;
  for (int j : stable) {
    FoundTerm t;
    t.name = names[j];
    t.parameter = effectSpec(t.name).params.front().name;
    t.coefficient = f.values.at(t.parameter);
    t.stable = counts[j];
    t.equation = termEquation(*dictionaryTerm(t.name), t.coefficient) + ", stable in " + std::to_string(t.stable) +
                 " of " + std::to_string(out.resamples) + " resamples";
    out.terms.push_back(t);
    out.reasons.push_back("discovered: " + t.equation);
  }
  return out;
}

}  // namespace gap
}  // namespace nursing_bed
