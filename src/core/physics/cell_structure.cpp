#include "nursing_bed/core/physics/cell_structure.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace nursing_bed {
namespace {

using ShapeVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxShapeDofs, 1>;
using ShapeMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxShapeDofs, kMaxShapeDofs>;

// Film balance dW/dq_i - p dV/dq_i.
ShapeVector shapeResidual(const CellStructure& s, double h, double p, const double* q) {
  const StructureEval e = s.evaluate(h, q);
  ShapeVector r(s.shapeDofs());
  for (int i = 0; i < s.shapeDofs(); ++i) r[i] = e.elastic_force[i] - p * e.dvolume_dshape[i];
  return r;
}

}  // namespace

FlatFold::FlatFold(double fold_volume_m3, double flat_area_m2)
    : volume_m3_(fold_volume_m3), area_m2_(flat_area_m2), depth_m_(fold_volume_m3 / flat_area_m2) {
  if (!(volume_m3_ > 0.0 && std::isfinite(volume_m3_)))
    throw std::invalid_argument("FlatFold: fold_volume_m3 must be a positive finite volume");
  if (!(area_m2_ > 0.0 && std::isfinite(area_m2_)))
    throw std::invalid_argument("FlatFold: the flat cell's effective area must be positive and finite");
}

StructureEval FlatFold::below(double height_m, StructureEval at_flat) const {
  if (!(height_m < 0.0)) return at_flat;
  const double squeezed = std::exp(height_m / depth_m_);  // 1 at flat, 0 deep in the stack
  at_flat.volume_m3 -= volume_m3_ * (1.0 - squeezed);
  at_flat.effective_area_m2 = area_m2_ * squeezed;
  return at_flat;
}

std::array<double, kMaxShapeDofs> CellStructure::relaxedShape(double height_m, double gauge_pressure_pa,
                                                              const double* initial_shape) const {
  const int n = shapeDofs();
  std::array<double, kMaxShapeDofs> q = initial_shape ? std::array<double, kMaxShapeDofs>{} : restShape();
  if (initial_shape) std::copy(initial_shape, initial_shape + n, q.begin());
  // Damped Newton with a finite-difference Jacobian; the film balance is smooth and, from the
  // rest shape, reaches the first (stable) root.
  for (int iter = 0; iter < 200; ++iter) {
    const ShapeVector r = shapeResidual(*this, height_m, gauge_pressure_pa, q.data());
    ShapeMatrix jac(n, n);
    for (int j = 0; j < n; ++j) {
      auto qp = q;
      const double dq = 1e-7 * std::max(1.0, std::fabs(q[j]));
      qp[j] += dq;
      jac.col(j) = (shapeResidual(*this, height_m, gauge_pressure_pa, qp.data()) - r) / dq;
    }
    ShapeVector step = -jac.fullPivLu().solve(r);
    const double max_step = step.cwiseAbs().maxCoeff();
    if (max_step > 0.05) step *= 0.05 / max_step;
    for (int j = 0; j < n; ++j) q[j] += step[j];
    if (max_step < 1e-12) break;
  }
  return q;
}

StructureEquilibrium CellStructure::equilibriumAtPressure(double gauge_pressure_pa, double load_n) const {
  StructureEquilibrium out;
  out.gauge_pressure_pa = gauge_pressure_pa;
  auto excess_force = [&](double h, std::array<double, kMaxShapeDofs>* q) {
    *q = relaxedShape(h, gauge_pressure_pa, q->data());
    const StructureEval e = evaluate(h, q->data());
    return gauge_pressure_pa * e.effective_area_m2 + e.plate_force_n - load_n;
  };
  std::array<double, kMaxShapeDofs> q_lo = restShape();
  if (!(gauge_pressure_pa > 0.0) || excess_force(0.0, &q_lo) <= 0.0) {
    // The pressure cannot lift the load: the plate rests on the flat cell.
    out.converged = true;
    out.height_m = 0.0;
    out.shape = q_lo;
    out.eval = evaluate(0.0, q_lo.data());
    return out;
  }
  // Upper bracket: just below the height where the effective area vanishes.
  std::array<double, kMaxShapeDofs> q_hi = q_lo;
  double h_hi = heightLimit(q_hi.data());
  for (int i = 0; i < 20; ++i) {
    if (excess_force(h_hi, &q_hi) < 0.0) break;
    h_hi = heightLimit(q_hi.data()) * 1.0001 + 1e-4;
  }
  double h_lo = 0.0;
  std::array<double, kMaxShapeDofs> q = q_lo;
  for (int iter = 0; iter < 80 && h_hi - h_lo > 1e-10; ++iter) {
    const double h_mid = 0.5 * (h_lo + h_hi);
    q = q_lo;
    if (excess_force(h_mid, &q) > 0.0) {
      h_lo = h_mid;
      q_lo = q;
    } else {
      h_hi = h_mid;
    }
  }
  out.height_m = 0.5 * (h_lo + h_hi);
  out.shape = relaxedShape(out.height_m, gauge_pressure_pa, q_lo.data());
  out.eval = evaluate(out.height_m, out.shape.data());
  out.converged = withinLimits(out.height_m, out.shape.data()) &&
                  std::fabs(gauge_pressure_pa * out.eval.effective_area_m2 + out.eval.plate_force_n - load_n) <=
                      1e-6 * (1.0 + load_n);
  return out;
}

StructureEquilibrium CellStructure::equilibriumAtHeight(double height_m, double load_n, int branch) const {
  StructureEquilibrium out;
  out.height_m = height_m;
  std::array<double, kMaxShapeDofs> q = restShape();
  // Each trial pressure starts on the branch, so the force is one function of the pressure
  // whatever the trials before it (the film's coordinates still carry over as a warm start).
  auto excess_force = [&](double p) {
    enterBranch(branch, q.data());
    q = relaxedShape(height_m, p, q.data());
    const StructureEval e = evaluate(height_m, q.data());
    return p * e.effective_area_m2 + e.plate_force_n - load_n;
  };
  double p_lo = 0.0;
  double p_hi = 100.0;
  while (excess_force(p_hi) < 0.0) {
    p_lo = p_hi;
    p_hi *= 2.0;
    // Height out of reach: no pressure holds the plate there within the film's limits.
    if (p_hi > 1e7 || !withinLimits(height_m, q.data())) return out;
  }
  // Illinois regula falsi on the bracket: superlinear, and never leaves the bracket.
  double f_lo = excess_force(p_lo), f_hi = excess_force(p_hi);
  int side = 0;
  double p_new = p_hi;
  for (int iter = 0; iter < 100 && p_hi - p_lo > 1e-10 * p_hi; ++iter) {
    p_new = (p_lo * f_hi - p_hi * f_lo) / (f_hi - f_lo);
    const double f_new = excess_force(p_new);
    if (std::fabs(f_new) < 1e-10 * (1.0 + load_n)) break;
    if (f_new > 0.0) {
      p_hi = p_new;
      f_hi = f_new;
      if (side == 1) f_lo *= 0.5;
      side = 1;
    } else {
      p_lo = p_new;
      f_lo = f_new;
      if (side == -1) f_hi *= 0.5;
      side = -1;
    }
  }
  out.gauge_pressure_pa = p_new;
  enterBranch(branch, q.data());
  out.shape = relaxedShape(height_m, out.gauge_pressure_pa, q.data());
  out.eval = evaluate(height_m, out.shape.data());
  out.converged = withinLimits(height_m, out.shape.data());
  return out;
}

}  // namespace nursing_bed
