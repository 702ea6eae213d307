// Discovery for what no candidate explains (doc/gap_diagnosis.md, "Discovery"): a sparse
// correction to the cell model's balance equations from the dictionary of discovery_terms.h,
// its terms chosen by their stability across resamples of the fit runs, fitted by replay
// (fitModel) and kept only where the withheld runs confirm them.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"

namespace nursing_bed {
namespace gap {

/// A term the discovery kept.
struct FoundTerm {
  std::string name;          ///< dictionary effect name (discovery_terms.h)
  std::string parameter;     ///< its coefficient's parameter name
  double coefficient = 0.0;  ///< SI, in the term's unit
  int stable = 0;            ///< resamples that selected it
  std::string equation;      ///< "plate force: −420 N·s²/m² · |v|v, stable in 19 of 20 resamples"
};

struct DiscoveryResult {
  bool discovered = false;
  int resamples = 0;
  std::map<std::string, int> selected;  ///< every dictionary term: resamples that selected it
  std::vector<FoundTerm> terms;         ///< the kept terms (empty: nothing discovered)
  ModelSpec model;                      ///< the kept terms on the baseline calibration
  double chi2 = NAN;                    ///< fit runs, whitened, summed, with the terms
  double withheld_chi2_per_sample = NAN;
  double withheld_nrmse_before = NAN, withheld_nrmse_after = NAN;  ///< baseline model, with the terms
  std::vector<std::string> reasons;                                ///< the decision in words
};

/// How each dictionary term moves the whitened residuals of the model `cell` with `base`
/// effects: column j is d r / d u_j with u_j the term's coefficient over its scale, by central
/// differences of replays at u_j = +-probe (one-sided where one side's replay fails; zeros where
/// both fail).
Eigen::MatrixXd termSensitivities(const FitData& fit, const CellParams& cell, const std::vector<CellEffectPtr>& base,
                                  const std::vector<std::string>& terms, double probe);

/// Forward selection on the linearised residuals r0 + J c, each row weighted by `weight`,
/// starting from the columns `initial`: the column that lowers the weighted chi2 most joins
/// while that drop, counted in units of chi2/n where that is above 1, exceeds `penalty`; at
/// most `max_terms` in all. Indices into J's columns, `initial` first.
std::vector<int> forwardSelect(const Eigen::MatrixXd& J, const Eigen::VectorXd& r0, const Eigen::VectorXd& weight,
                               double penalty, int max_terms, const std::vector<int>& initial = {});

/// Row weights of `resamples` block bootstraps: each draws as many blocks ([begin, end) rows)
/// as there are, with replacement; a row's weight is how often it was drawn.
std::vector<Eigen::VectorXd> blockBootstrap(const std::vector<std::pair<int, int>>& blocks, int rows, int resamples,
                                            std::uint32_t seed);

/// A single term fitted alone by replay, and the residuals' local linear model there.
struct SingleTermFit {
  double u = 0.5;             ///< fit coordinate (0.5: coefficient 0)
  double coefficient = 0.0;   ///< SI
  double chi2 = NAN;          ///< whitened, summed, at the fit
  Eigen::VectorXd residuals;  ///< at the fit
  Eigen::VectorXd slope;      ///< d residuals / d u at the fit (u = coefficient / scale)
  bool ok = false;
};

/// Every term of `names` fitted alone by replay on the model `cell` (the nominal cell with
/// `calibration`), with its local linear model.
std::vector<SingleTermFit> fitSingleTerms(const FitData& fit, const CellParams& cell,
                                          const std::map<std::string, double>& calibration,
                                          const std::vector<std::string>& names, const DiagnosisOptions& options);

/// The term (index into `singles`) that, refitted on the weighted rows through its local linear
/// model, leaves the least weighted chi2, if it lowers the baseline's (`r0`) by more than
/// `penalty` (counted as in forwardSelect); -1 otherwise.
int bestSingleTerm(const std::vector<SingleTermFit>& singles, const Eigen::VectorXd& r0, const Eigen::VectorXd& weight,
                   double penalty);

/// The discovery on top of the model with calibration `calibration` (the verdict's). Each term
/// is fitted alone by replay; in each resample the best of them (bestSingleTerm) is selected,
/// and further terms by forward selection on the residuals linearised at the most selected
/// one's fit. The terms selected in at least options.discovery_stability of the resamples are
/// fitted together by replay; a term is dropped while leaving it out costs the withheld runs less than
/// min_withheld_gain of chi2; what is left is discovered when it is significant on the fit runs
/// (as a candidate must be) and on the withheld runs lowers chi2 by min_withheld_gain and the
/// nrmse by discovery_withheld_shrink. Never discovers without withheld runs.
DiscoveryResult discoverTerms(const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                              const std::map<std::string, double>& calibration, const DiagnosisOptions& options,
                              const std::function<void(const std::string&)>& progress);

}  // namespace gap
}  // namespace nursing_bed
