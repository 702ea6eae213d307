// Yeoh hyperelastic film (paper eq. 6-10), incompressible.
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/**
 * Yeoh strain energy W = C10 (I1-3) + C20 (I1-3)^2 + C30 (I1-3)^3 [J/m^3] (paper eq. 7).
 *
 * Defaults are the constants fitted by `fit_material` to data/tpu_uniaxial.csv (a soft TPU,
 * within the published range C10 1.4-3.8 MPa, C20 -0.15..-0.73 MPa, C30 0.013-0.10 MPa);
 * see doc/material.md.
 */
struct YeohMaterial {
  double c10_pa = 1.912139e6;
  double c20_pa = -0.352553e6;
  double c30_pa = 0.050329e6;

  /// W(I1) [J/m^3].
  double energy(double i1) const;
  /// dW/dI1 [Pa].
  double energyDerivative(double i1) const;
  /// d2W/dI1^2 [Pa].
  double energySecondDerivative(double i1) const;

  /// Uniaxial engineering (nominal) stress at stretch lambda (eq. 8-10):
  /// I1 = l^2 + 2/l, sigma = dW/dl = 2 (l - l^-2) dW/dI1 [Pa].
  double uniaxialNominalStress(double stretch) const;

  /// Equibiaxial film (l1 = l2 = l, l3 = l^-2): I1 = 2 l^2 + l^-4.
  double equibiaxialEnergy(double stretch) const;
  /// d/dl of equibiaxialEnergy [J/m^3]; equals twice the nominal stress in each direction.
  double equibiaxialEnergyDerivative(double stretch) const;
  /// d2/dl2 of equibiaxialEnergy [J/m^3].
  double equibiaxialEnergySecondDerivative(double stretch) const;

  /// Small-strain Young's modulus E = 6 C10 [Pa].
  double youngsModulus() const { return 6.0 * c10_pa; }

  /// Success when the constants give a positive initial modulus and dW/dI1 > 0 for all
  /// I1 >= 3 (no material instability in tension); else an error naming what is wrong.
  Status validate() const;
};

}  // namespace nursing_bed
