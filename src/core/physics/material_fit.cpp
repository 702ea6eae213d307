#include "nursing_bed/core/physics/material_fit.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/number_text.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace {

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  const auto begin = s.find_first_not_of(ws);
  if (begin == std::string::npos) return "";
  const auto end = s.find_last_not_of(ws);
  return s.substr(begin, end - begin + 1);
}

std::vector<std::string> splitCsv(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ',')) fields.push_back(trim(field));
  if (!line.empty() && line.back() == ',') fields.emplace_back();  // trailing empty field
  return fields;
}

std::string headerName(const std::string& field) {
  std::string name = field;
  if (name.size() >= 2 && name.front() == '"' && name.back() == '"') name = trim(name.substr(1, name.size() - 2));
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return name;
}

/// Index of whichever of the two names the header has; -1 if neither. Throws if both or repeated.
int findColumn(const std::vector<std::string>& names, const std::string& a, const std::string& b,
               const std::string& where) {
  int found = -1;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i] != a && names[i] != b) continue;
    if (found >= 0) {
      const std::string& first = names[static_cast<std::size_t>(found)];
      if (first == names[i]) throw std::runtime_error(where + ": column '" + first + "' appears twice in the header");
      throw std::runtime_error(where + ": both '" + first + "' and '" + names[i] + "' columns in the header; keep one");
    }
    found = static_cast<int>(i);
  }
  return found;
}

}  // namespace

TensileData readTensileCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open tensile data file");

  TensileData data;
  data.source = path;
  std::vector<std::string> names;
  int stretch_col = -1;
  int stress_col = -1;
  bool strain_given = false;  // column is engineering strain, not stretch
  double stress_scale = 1.0;  // to Pa

  std::string raw;
  int line_no = 0;
  while (std::getline(in, raw)) {
    ++line_no;
    const std::string line = trim(raw);
    if (line.empty() || line.front() == '#') continue;
    const std::string where = path + ":" + std::to_string(line_no);
    const std::vector<std::string> fields = splitCsv(line);

    if (names.empty()) {  // header
      for (const auto& f : fields) names.push_back(headerName(f));
      stretch_col = findColumn(names, "stretch", "strain", where);
      stress_col = findColumn(names, "stress_pa", "stress_mpa", where);
      std::string found;
      for (const auto& n : names) found += (found.empty() ? "" : ", ") + ("'" + n + "'");
      if (stretch_col < 0)
        throw std::runtime_error(where + ": header has no 'stretch' or 'strain' column (found " + found + ")");
      if (stress_col < 0)
        throw std::runtime_error(where +
                                 ": header has no 'stress_pa' or 'stress_mpa' column "
                                 "(found " +
                                 found + ")");
      strain_given = names[static_cast<std::size_t>(stretch_col)] == "strain";
      if (names[static_cast<std::size_t>(stress_col)] == "stress_mpa") stress_scale = mpaToPa(1.0);
      continue;
    }

    if (fields.size() != names.size())
      throw std::runtime_error(where + ": " + std::to_string(fields.size()) + " fields, but the header has " +
                               std::to_string(names.size()));
    double values[2] = {0.0, 0.0};
    const int cols[2] = {stretch_col, stress_col};
    for (int k = 0; k < 2; ++k) {
      const auto c = static_cast<std::size_t>(cols[k]);
      if (!parseFiniteNumber(fields[c], &values[k]))
        throw std::runtime_error(where + ": column '" + names[c] + "': '" + fields[c] + "' is not a finite number");
    }
    const double stretch = strain_given ? 1.0 + values[0] : values[0];
    if (!(stretch > 0.0)) {
      std::ostringstream msg;
      msg << where << ": column '" << names[static_cast<std::size_t>(stretch_col)] << "': stretch must be > 0, got "
          << stretch;
      if (strain_given) msg << " (strain " << values[0] << ")";
      throw std::runtime_error(msg.str());
    }
    data.stretch.push_back(stretch);
    data.stress_pa.push_back(values[1] * stress_scale);
  }
  if (in.bad()) throw std::runtime_error(path + ": read error");

  if (names.empty()) throw std::runtime_error(path + ": no header line (file empty?)");
  if (data.stretch.size() < 4)
    throw std::runtime_error(path + ": " + std::to_string(data.stretch.size()) +
                             " data rows, need at least 4 to fit three constants");
  const double max_stretch = *std::max_element(data.stretch.begin(), data.stretch.end());
  if (!(max_stretch > 1.0)) {
    std::ostringstream msg;
    msg << path << ": no stretch > 1 in column '" << names[static_cast<std::size_t>(stretch_col)]
        << "' (largest stretch " << max_stretch << "); not a tensile curve";
    throw std::runtime_error(msg.str());
  }
  return data;
}

namespace {

/// Design matrix of the uniaxial nominal stress (eq. 8-10), one column per constant, and the
/// measured stresses.
void yeohDesign(const TensileData& data, Eigen::MatrixXd* a_mat, Eigen::VectorXd* b) {
  const std::size_t n = data.stretch.size();
  a_mat->resize(static_cast<Eigen::Index>(n), 3);
  b->resize(static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    const double l = data.stretch[i];
    const double s = data.stress_pa[i];
    if (!std::isfinite(l) || !std::isfinite(s) || !(l > 0.0))
      throw std::invalid_argument("fitYeoh: point " + std::to_string(i) + " has a non-finite value or stretch <= 0");
    const double x = l * l + 2.0 / l - 3.0;      // I1 - 3
    const double a = 2.0 * (l - 1.0 / (l * l));  // dI1/dl
    const auto r = static_cast<Eigen::Index>(i);
    (*a_mat)(r, 0) = a;
    (*a_mat)(r, 1) = 2.0 * a * x;
    (*a_mat)(r, 2) = 3.0 * a * x * x;
    (*b)(r) = s;
  }
}

/// Row weights that make residuals relative to the measured stress (floored at
/// relative_floor times the largest stress).
Eigen::VectorXd relativeWeights(const Eigen::VectorXd& b, const YeohFitOptions& options) {
  if (!(options.relative_floor > 0.0) || !std::isfinite(options.relative_floor))
    throw std::invalid_argument("fitYeoh: relative_floor must be positive");
  const double floor_pa = options.relative_floor * b.cwiseAbs().maxCoeff();
  Eigen::VectorXd w_rel = Eigen::VectorXd::Ones(b.size());
  if (floor_pa > 0.0)
    for (Eigen::Index i = 0; i < w_rel.size(); ++i) w_rel(i) = 1.0 / std::max(std::abs(b(i)), floor_pa);
  return w_rel;
}

/// Residual figures of the fitted constants `c` on the unweighted data.
void residualStatistics(const TensileData& data, const Eigen::MatrixXd& a_mat, const Eigen::VectorXd& b,
                        const Eigen::VectorXd& w_rel, const Eigen::Vector3d& c, YeohFit* fit) {
  const std::size_t n = data.stretch.size();
  const Eigen::VectorXd residual = b - a_mat * c;
  const double ssr = residual.squaredNorm();
  const double sst = (b.array() - b.mean()).square().sum();
  fit->r_squared = sst > 0.0 ? 1.0 - ssr / sst : std::numeric_limits<double>::quiet_NaN();
  fit->rms_residual_pa = std::sqrt(ssr / static_cast<double>(n));
  fit->max_abs_residual_pa = residual.cwiseAbs().maxCoeff();
  fit->rms_relative_residual = std::sqrt(residual.cwiseProduct(w_rel).squaredNorm() / static_cast<double>(n));
  fit->min_stretch = *std::min_element(data.stretch.begin(), data.stretch.end());
  fit->max_stretch = *std::max_element(data.stretch.begin(), data.stretch.end());
}

/// Standard errors of the constants from the covariance s^2 (A_w^T A_w)^-1; with A_s P = Q R:
/// (A_s^T A_s)^-1 = P R^-1 R^-T P^T, A_w = A_s D (D = diag(scale)).
void standardErrors(const Eigen::ColPivHouseholderQR<Eigen::MatrixXd>& qr, const Eigen::Vector3d& scale,
                    const Eigen::MatrixXd& a_w, const Eigen::VectorXd& b_w, const Eigen::Vector3d& c, YeohFit* fit) {
  const auto n = static_cast<double>(a_w.rows());
  const Eigen::Matrix3d r_mat = qr.matrixR().topLeftCorner(3, 3).triangularView<Eigen::Upper>();
  const Eigen::Matrix3d r_inv = r_mat.triangularView<Eigen::Upper>().solve(Eigen::Matrix3d::Identity());
  const Eigen::Matrix3d perm = qr.colsPermutation();
  Eigen::Matrix3d cov = perm * r_inv * r_inv.transpose() * perm.transpose();
  cov = scale.cwiseInverse().asDiagonal() * cov * scale.cwiseInverse().asDiagonal();
  cov *= (b_w - a_w * c).squaredNorm() / (n - 3.0);
  fit->c10_stderr_pa = std::sqrt(cov(0, 0));
  fit->c20_stderr_pa = std::sqrt(cov(1, 1));
  fit->c30_stderr_pa = std::sqrt(cov(2, 2));
}

}  // namespace

YeohFit fitYeoh(const TensileData& data, const YeohFitOptions& options) {
  const std::size_t n = data.stretch.size();
  if (data.stress_pa.size() != n) throw std::invalid_argument("fitYeoh: stretch and stress_pa differ in length");
  if (n < 4) throw std::invalid_argument("fitYeoh: need at least 4 points, got " + std::to_string(n));

  Eigen::MatrixXd a_mat;
  Eigen::VectorXd b;
  yeohDesign(data, &a_mat, &b);
  // Row weights: residuals relative to the measured stress, or plain Pa.
  const Eigen::VectorXd w_rel = relativeWeights(b, options);
  const Eigen::VectorXd w =
      options.weighting == FitWeighting::kRelative ? w_rel : Eigen::VectorXd::Ones(static_cast<Eigen::Index>(n));
  const Eigen::MatrixXd a_w = w.asDiagonal() * a_mat;
  const Eigen::VectorXd b_w = w.asDiagonal() * b;

  // Scale columns to unit norm: the x^2 column is ~1e3 times the first at l = 5.
  Eigen::Vector3d scale = a_w.colwise().norm().transpose();
  for (int j = 0; j < 3; ++j)
    if (!(scale(j) > 0.0)) throw std::invalid_argument("fitYeoh: no point with stretch != 1; nothing to fit");
  const Eigen::MatrixXd a_scaled = a_w * scale.cwiseInverse().asDiagonal();
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a_scaled);
  if (qr.rank() < 3)
    throw std::invalid_argument(
        "fitYeoh: the data cannot determine three constants (need at "
        "least 3 distinct values of I1 = l^2 + 2/l other than 3)");
  const Eigen::Vector3d c = qr.solve(b_w).cwiseQuotient(scale);

  YeohFit fit;
  fit.material.c10_pa = c(0);
  fit.material.c20_pa = c(1);
  fit.material.c30_pa = c(2);
  fit.num_points = n;
  fit.weighting = options.weighting;
  residualStatistics(data, a_mat, b, w_rel, c, &fit);
  standardErrors(qr, scale, a_w, b_w, c, &fit);
  fit.validation = fit.material.validate().message();
  return fit;
}

void writeYeohFitCsv(const std::string& path, const TensileData& data, const YeohFit& fit) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << "stretch,stress_pa_measured,stress_pa_fitted\n" << std::setprecision(10);
  for (std::size_t i = 0; i < data.stretch.size() && i < data.stress_pa.size(); ++i)
    out << data.stretch[i] << ',' << data.stress_pa[i] << ',' << fit.material.uniaxialNominalStress(data.stretch[i])
        << '\n';
  out.flush();
  if (!out) throw std::runtime_error(path + ": write failed");
}

}  // namespace nursing_bed
