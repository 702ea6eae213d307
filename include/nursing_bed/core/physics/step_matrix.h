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

/// LU factorisation with row pivoting of a small fixed-size matrix, written out so that the
/// compiler unrolls it (Eigen's runs its generic blocked loops at every size).
template <int N>
class SmallLu {
 public:
  using Matrix = Eigen::Matrix<double, N, N>;
  using Vector = Eigen::Matrix<double, N, 1>;

  /// Factorises `a`; a singular matrix leaves infinities, which the solves pass on.
  void compute(const Matrix& a) {
    lu_ = a;
    for (int k = 0; k < N; ++k) {
      int pivot = k;
      for (int i = k + 1; i < N; ++i)
        if (std::fabs(lu_(i, k)) > std::fabs(lu_(pivot, k))) pivot = i;
      pivots_[k] = pivot;
      if (pivot != k) lu_.row(k).swap(lu_.row(pivot));
      inverse_diagonal_[k] = 1.0 / lu_(k, k);
      for (int i = k + 1; i < N; ++i) {
        const double f = lu_(i, k) * inverse_diagonal_[k];
        lu_(i, k) = f;
        for (int j = k + 1; j < N; ++j) lu_(i, j) -= f * lu_(k, j);
      }
    }
  }

  Vector solve(Vector b) const {
    for (int k = 0; k < N; ++k) std::swap(b[k], b[pivots_[k]]);
    for (int i = 1; i < N; ++i)
      for (int j = 0; j < i; ++j) b[i] -= lu_(i, j) * b[j];
    for (int i = N - 1; i >= 0; --i) {
      for (int j = i + 1; j < N; ++j) b[i] -= lu_(i, j) * b[j];
      b[i] *= inverse_diagonal_[i];
    }
    return b;
  }

 private:
  Matrix lu_ = Matrix::Identity();
  Vector inverse_diagonal_ = Vector::Ones();
  int pivots_[N] = {};
};

/**
 * The factorisation of W = I - gamma h J and its solves. A cell without effect states and with
 * one film shape coordinate has six states: that size takes fixed-size matrices (unrolled, no
 * run-time size checks); any other size takes run-time-size ones.
 *
 * At the nominal size, the plate's height row (dh/dt = v) and the regulator's row (its own lag)
 * are eliminated first, leaving a 4 x 4 system in mass, energy, velocity and shape; a Jacobian
 * without that pattern is factorised whole.
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
      const NominalMatrix w =
          NominalMatrix::Identity() - gamma_h * jacobian.topLeftCorner<kNominalStates, kNominalStates>();
      reduced_ = hasPlateAndRegulatorPattern(w);
      if (!reduced_) {
        nominal_lu_.compute(w);
        return;
      }
      height_velocity_ = w(kHeight, kVelocity);
      regulator_diagonal_ = w(kRegulator, kRegulator);
      ReducedMatrix a;
      for (int i = 0; i < kReduced; ++i) {
        const int row = kKept[i];
        height_column_[i] = w(row, kHeight);
        regulator_column_[i] = w(row, kRegulator);
        for (int j = 0; j < kReduced; ++j) a(i, j) = w(row, kKept[j]);
        a(i, kReducedVelocity) -= height_column_[i] * height_velocity_;
      }
      reduced_lu_.compute(a);
    } else {
      lu_.compute(CellStateMatrix::Identity(size_, size_) - gamma_h * jacobian);
    }
  }

  /// Size of the last factorisation.
  int size() const { return size_; }
  /// W^-1 b for the last factorisation, which was of the nominal size.
  NominalVector solveNominal(const NominalVector& b) const {
    if (!reduced_) return nominal_lu_.solve(b);
    const double regulator = b[kRegulator] / regulator_diagonal_;
    ReducedVector rhs;
    for (int i = 0; i < kReduced; ++i)
      rhs[i] = b[kKept[i]] - height_column_[i] * b[kHeight] - regulator_column_[i] * regulator;
    const ReducedVector y = reduced_lu_.solve(rhs);
    NominalVector x;
    for (int i = 0; i < kReduced; ++i) x[kKept[i]] = y[i];
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
    return lu_.solve(b);
  }

 private:
  // The nominal states' order (CellModel::StateIndex) and the four kept after the elimination.
  static constexpr int kHeight = 2, kVelocity = 3, kRegulator = 4;
  static constexpr int kReduced = 4;
  static constexpr int kKept[kReduced] = {0, 1, kVelocity, 5};
  static constexpr int kReducedVelocity = 2;
  using ReducedMatrix = Eigen::Matrix<double, kReduced, kReduced>;
  using ReducedVector = Eigen::Matrix<double, kReduced, 1>;

  /// W's height row is (0 0 1 w 0 0) and its regulator row (0 0 0 0 d 0), d != 0.
  static bool hasPlateAndRegulatorPattern(const NominalMatrix& w) {
    for (int j = 0; j < kNominalStates; ++j) {
      if (j != kHeight && j != kVelocity && w(kHeight, j) != 0.0) return false;
      if (j != kRegulator && w(kRegulator, j) != 0.0) return false;
    }
    return w(kHeight, kHeight) == 1.0 && w(kRegulator, kRegulator) != 0.0 && std::isfinite(w(kHeight, kVelocity));
  }

  int size_ = 0;
  bool reduced_ = false;
  SmallLu<kNominalStates> nominal_lu_;
  SmallLu<kReduced> reduced_lu_;
  ReducedVector height_column_ = ReducedVector::Zero();
  ReducedVector regulator_column_ = ReducedVector::Zero();
  double height_velocity_ = 0.0;
  double regulator_diagonal_ = 1.0;
  Eigen::PartialPivLU<CellStateMatrix> lu_;
};

}  // namespace nursing_bed
