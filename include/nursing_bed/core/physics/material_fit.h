// Least-squares fit of the Yeoh constants (paper eq. 7-10) to a uniaxial tensile curve.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/yeoh.h"

namespace nursing_bed {

/// A uniaxial tensile curve: stretch [-] and engineering (nominal) stress [Pa], same length.
struct TensileData {
  std::vector<double> stretch;    ///< l = 1 + engineering strain [-], each > 0
  std::vector<double> stress_pa;  ///< engineering stress = force / undeformed area [Pa]
  std::string source;             ///< where the data came from (file path), for reports
};

/**
 * Reads a uniaxial tensile CSV.
 *
 * Blank lines and lines starting with `#` are skipped; the first other line is the header.
 * Columns (any order, others ignored, names trimmed and case-insensitive): exactly one of
 * `stretch` [-] or `strain` (engineering strain = stretch - 1) and exactly one of `stress_pa`
 * or `stress_mpa` (engineering stress). Every data row must have as many fields as the header;
 * the used fields must be finite numbers, every stretch > 0, at least 4 rows, and some
 * stretch > 1. Throws std::runtime_error naming the file, line and column of the first problem;
 * nothing is returned half-read.
 */
TensileData readTensileCsv(const std::string& path);

/// How the residuals of the fit are weighted.
enum class FitWeighting {
  /// Residuals relative to the measured stress, w_i = 1 / max(|sigma_i|, floor): right for the
  /// roughly proportional noise of tensile tests, and keeps the small-stretch region (which sets
  /// C10) from being swamped by the large stresses at high stretch.
  kRelative,
  /// Ordinary (unweighted) least squares in Pa: dominated by the largest stresses.
  kNone,
};

struct YeohFitOptions {
  FitWeighting weighting = FitWeighting::kRelative;
  /// kRelative: floor of the weighting stress as a fraction of the largest |stress| [-], so
  /// points near zero stress (stretch ~ 1) do not get unbounded weight.
  double relative_floor = 1e-3;
};

/// A Yeoh fit and its quality.
struct YeohFit {
  YeohMaterial material;             ///< fitted C10, C20, C30 [Pa]
  double c10_stderr_pa = 0.0;        ///< standard error of C10 [Pa]
  double c20_stderr_pa = 0.0;        ///< standard error of C20 [Pa]
  double c30_stderr_pa = 0.0;        ///< standard error of C30 [Pa]
  double r_squared = 0.0;            ///< coefficient of determination [-]; NaN if stress is constant
  double rms_residual_pa = 0.0;      ///< sqrt(mean squared residual) [Pa]
  double max_abs_residual_pa = 0.0;  ///< largest |measured - fitted| [Pa]
  /// sqrt(mean((residual / max(|measured|, floor))^2)) with the kRelative floor [-]
  double rms_relative_residual = 0.0;
  std::size_t num_points = 0;
  double min_stretch = 0.0;  ///< range of the data, i.e. where the fit is valid [-]
  double max_stretch = 0.0;
  std::string validation;                            ///< material.validate(): empty when the constants are usable
  FitWeighting weighting = FitWeighting::kRelative;  ///< how the residuals were weighted
};

/**
 * Linear least squares of the uniaxial engineering stress (eq. 8-10), which is linear in the
 * constants: sigma = a C10 + 2 a x C20 + 3 a x^2 C30 with a = 2 (l - l^-2), x = I1 - 3,
 * I1 = l^2 + 2/l. Rows weighted as `options.weighting` says, columns scaled to unit norm, solved
 * with column-pivoted Householder QR. Standard errors are sqrt(diag(s^2 (A_w^T A_w)^-1)) with
 * s^2 = |weighted residual|^2 / (n - 3); R^2, RMS and max residual are of the unweighted
 * stress [Pa].
 * Throws std::invalid_argument when the data cannot determine three constants (sizes differ,
 * fewer than 4 points, non-finite values, stretch <= 0, or fewer than 3 distinct I1 != 3).
 */
YeohFit fitYeoh(const TensileData& data, const YeohFitOptions& options = YeohFitOptions());

/// Writes `stretch,stress_pa_measured,stress_pa_fitted` for plotting; throws std::runtime_error
/// when the file cannot be written.
void writeYeohFitCsv(const std::string& path, const TensileData& data, const YeohFit& fit);

}  // namespace nursing_bed
