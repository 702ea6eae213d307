// The linear algebra of one linearly implicit (Rosenbrock-W) step of the cell model.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <utility>

namespace nursing_bed {

/// Upper bound on the cell model's states (nominal states, film shape and effect states).
constexpr int kMaxCellStates = 24;
using CellStateVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxCellStates, 1>;
using CellStateMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxCellStates, kMaxCellStates>;

namespace detail {

/// Row-pivoted LU of the leading n x n block of `lu`, in place (unit lower part below the
/// diagonal, the upper's inverse diagonal apart). A singular matrix leaves infinities, which the
/// solves pass on. With n a constant the compiler unrolls it.
template <class Matrix>
inline void luInPlace(Matrix& lu, int n, int* pivots, double* inverse_diagonal) {
  for (int k = 0; k < n; ++k) {
    int pivot = k;
    for (int i = k + 1; i < n; ++i)
      if (std::fabs(lu(i, k)) > std::fabs(lu(pivot, k))) pivot = i;
    pivots[k] = pivot;
    if (pivot != k) lu.row(k).swap(lu.row(pivot));
    inverse_diagonal[k] = 1.0 / lu(k, k);
    for (int i = k + 1; i < n; ++i) {
      const double f = lu(i, k) * inverse_diagonal[k];
      lu(i, k) = f;
      for (int j = k + 1; j < n; ++j) lu(i, j) -= f * lu(k, j);
    }
  }
}

/// Solves with luInPlace's factors, in place on the first n entries of `b`.
template <class Matrix>
inline void luSolveInPlace(const Matrix& lu, int n, const int* pivots, const double* inverse_diagonal, double* b) {
  for (int k = 0; k < n; ++k) std::swap(b[k], b[pivots[k]]);
  for (int i = 1; i < n; ++i)
    for (int j = 0; j < i; ++j) b[i] -= lu(i, j) * b[j];
  for (int i = n - 1; i >= 0; --i) {
    for (int j = i + 1; j < n; ++j) b[i] -= lu(i, j) * b[j];
    b[i] *= inverse_diagonal[i];
  }
}

}  // namespace detail

/// LU factorisation with row pivoting of a small fixed-size matrix, written out so that the
/// compiler unrolls it (Eigen's runs its generic blocked loops at every size).
template <int N>
class SmallLu {
 public:
  using Matrix = Eigen::Matrix<double, N, N>;
  using Vector = Eigen::Matrix<double, N, 1>;

  void compute(const Matrix& a) {
    lu_ = a;
    detail::luInPlace(lu_, N, pivots_, inverse_diagonal_);
  }

  Vector solve(Vector b) const {
    detail::luSolveInPlace(lu_, N, pivots_, inverse_diagonal_, b.data());
    return b;
  }

 private:
  Matrix lu_ = Matrix::Identity();
  double inverse_diagonal_[N] = {};
  int pivots_[N] = {};
};

/// The inverse of a matrix whose size is known at run time (at most kMaxCellStates), from the
/// same factorisation: plain loops on fixed storage, without the blocking and size dispatch of
/// Eigen's, which cost more than the arithmetic at these sizes. It keeps only the inverse: a
/// factorisation serves three solves per step and usually several steps, and a product has no
/// pivoting and no chain of divisions.
class RuntimeInverse {
 public:
  /// Inverts the leading n x n block of `a` through its row-pivoted LU.
  void compute(const CellStateMatrix& a, int n) {
    n_ = n;
    CellStateMatrix lu = a.topLeftCorner(n, n);
    double inverse_diagonal[kMaxCellStates];
    int pivots[kMaxCellStates];
    detail::luInPlace(lu, n, pivots, inverse_diagonal);
    inverse_ = CellStateMatrix::Identity(n, n);
    for (int j = 0; j < n; ++j) detail::luSolveInPlace(lu, n, pivots, inverse_diagonal, inverse_.col(j).data());
  }

  /// Solves in place for the first n entries of `b` (a product with the inverse).
  void solveInPlace(double* b) const {
    double x[kMaxCellStates];
    for (int i = 0; i < n_; ++i) x[i] = 0.0;
    for (int j = 0; j < n_; ++j)
      for (int i = 0; i < n_; ++i) x[i] += inverse_(i, j) * b[j];
    for (int i = 0; i < n_; ++i) b[i] = x[i];
  }

 private:
  int n_ = 0;
  CellStateMatrix inverse_;
};

/**
 * The factorisation of W = I - gamma h J and its solves.
 *
 * The plate's height row (dh/dt = v) and the regulator's row (its own lag) are eliminated
 * first, leaving a system in the other states (mass, energy, velocity, shape and any effect
 * states); a Jacobian without that pattern is factorised whole. A cell without effect states
 * and with one film shape coordinate has six states: its 4 x 4 remainder takes fixed-size code
 * (a cofactor inverse). Each solve is then a matrix-vector product.
 */
class StepMatrix {
 public:
  static constexpr int kNominalStates = 6;
  using NominalMatrix = Eigen::Matrix<double, kNominalStates, kNominalStates>;
  using NominalVector = Eigen::Matrix<double, kNominalStates, 1>;

  /// Factorises I - gamma_h * jacobian (square).
  void factor(const CellStateMatrix& jacobian, double gamma_h) {
    size_ = static_cast<int>(jacobian.rows());
    if (size_ == kNominalStates) {
      factorNominal(NominalMatrix::Identity() - gamma_h * jacobian.topLeftCorner<kNominalStates, kNominalStates>());
      return;
    }
    const CellStateMatrix w = CellStateMatrix::Identity(size_, size_) - gamma_h * jacobian;
    reduced_ = size_ > kRegulator && hasPlateAndRegulatorPattern(w, size_);
    if (!reduced_) {
      runtime_.compute(w, size_);
      return;
    }
    const int m = size_ - 2;
    CellStateMatrix a(m, m);
    eliminatePlateAndRegulator(w, m, &a);
    runtime_.compute(a, m);
  }

  /// Size of the last factorisation.
  int size() const { return size_; }

  /// W^-1 b for the last factorisation, which was of the nominal size.
  NominalVector solveNominal(const NominalVector& b) const {
    if (!reduced_) return nominal_lu_.solve(b);
    const double regulator = b[kRegulator] / regulator_diagonal_;
    NominalReducedVector rhs;
    for (int i = 0; i < kNominalReduced; ++i)
      rhs[i] = b[kept(i)] - height_column_[i] * b[kHeight] - regulator_column_[i] * regulator;
    const NominalReducedVector y = nominal_reduced_inverse_ * rhs;
    NominalVector x;
    for (int i = 0; i < kNominalReduced; ++i) x[kept(i)] = y[i];
    x[kHeight] = b[kHeight] - height_velocity_ * y[kReducedVelocity];
    x[kRegulator] = regulator;
    return x;
  }

  /// W^-1 b for the last factorisation (b of the factorised size).
  CellStateVector solve(const CellStateVector& b) const {
    if (size_ == kNominalStates) {
      const NominalVector x = solveNominal(b.head<kNominalStates>());
      return x;
    }
    CellStateVector x = b;
    solveInPlace(x.data());
    return x;
  }

 private:
  // The nominal states' order (CellModel::StateIndex); the reduced system keeps every state but
  // the height and the regulator, in order (velocity becomes its third).
  static constexpr int kHeight = 2, kVelocity = 3, kRegulator = 4;
  static constexpr int kReducedVelocity = 2;
  static constexpr int kNominalReduced = kNominalStates - 2;
  static int kept(int i) { return i < kHeight ? i : (i == kReducedVelocity ? kVelocity : i + 2); }

  using NominalReducedMatrix = Eigen::Matrix<double, kNominalReduced, kNominalReduced>;
  using NominalReducedVector = Eigen::Matrix<double, kNominalReduced, 1>;

  /// factor() at the nominal size, on fixed-size matrices.
  void factorNominal(const NominalMatrix& w) {
    reduced_ = hasPlateAndRegulatorPattern(w, kNominalStates);
    if (!reduced_) {
      nominal_lu_.compute(w);
      return;
    }
    NominalReducedMatrix a;
    eliminatePlateAndRegulator(w, kNominalReduced, &a);
    // Each factorisation serves three solves per step and usually several steps: a 4 x 4
    // product has no pivoting and no dependent chain of divisions (Eigen's cofactor inverse).
    nominal_reduced_inverse_ = a.inverse();
  }

  /// W's height row is (0 0 1 w 0 ... 0) and its regulator row (0 0 0 0 d 0 ... 0), d != 0.
  template <class Matrix>
  static bool hasPlateAndRegulatorPattern(const Matrix& w, int n) {
    for (int j = 0; j < n; ++j) {
      if (j != kHeight && j != kVelocity && w(kHeight, j) != 0.0) return false;
      if (j != kRegulator && w(kRegulator, j) != 0.0) return false;
    }
    return w(kHeight, kHeight) == 1.0 && w(kRegulator, kRegulator) != 0.0 && std::isfinite(w(kHeight, kVelocity));
  }

  /// Keeps the height and regulator rows' terms and writes the remaining m x m system into `a`.
  template <class Matrix, class Reduced>
  void eliminatePlateAndRegulator(const Matrix& w, int m, Reduced* a) {
    height_velocity_ = w(kHeight, kVelocity);
    regulator_diagonal_ = w(kRegulator, kRegulator);
    for (int i = 0; i < m; ++i) {
      const int row = kept(i);
      height_column_[i] = w(row, kHeight);
      regulator_column_[i] = w(row, kRegulator);
      for (int j = 0; j < m; ++j) (*a)(i, j) = w(row, kept(j));
      (*a)(i, kReducedVelocity) -= height_column_[i] * height_velocity_;
    }
  }

  /// solve() at any size but the nominal one.
  void solveInPlace(double* x) const {
    if (!reduced_) {
      runtime_.solveInPlace(x);
      return;
    }
    const int m = size_ - 2;
    const double height_rhs = x[kHeight];
    const double regulator = x[kRegulator] / regulator_diagonal_;
    double y[kMaxCellStates];
    for (int i = 0; i < m; ++i) y[i] = x[kept(i)] - height_column_[i] * height_rhs - regulator_column_[i] * regulator;
    runtime_.solveInPlace(y);
    for (int i = 0; i < m; ++i) x[kept(i)] = y[i];
    x[kHeight] = height_rhs - height_velocity_ * y[kReducedVelocity];
    x[kRegulator] = regulator;
  }

  int size_ = 0;
  bool reduced_ = false;
  SmallLu<kNominalStates> nominal_lu_;
  NominalReducedMatrix nominal_reduced_inverse_ = NominalReducedMatrix::Identity();
  RuntimeInverse runtime_;
  double height_column_[kMaxCellStates] = {};
  double regulator_column_[kMaxCellStates] = {};
  double height_velocity_ = 0.0;
  double regulator_diagonal_ = 1.0;
};

}  // namespace nursing_bed
