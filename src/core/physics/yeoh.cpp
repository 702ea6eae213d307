#include "nursing_bed/core/physics/yeoh.h"

#include <cmath>
#include <sstream>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

double YeohMaterial::energy(double i1) const {
  const double x = i1 - 3.0;
  return x * (c10_pa + x * (c20_pa + x * c30_pa));
}

double YeohMaterial::energyDerivative(double i1) const {
  const double x = i1 - 3.0;
  return c10_pa + x * (2.0 * c20_pa + 3.0 * x * c30_pa);
}

double YeohMaterial::energySecondDerivative(double i1) const { return 2.0 * c20_pa + 6.0 * (i1 - 3.0) * c30_pa; }

double YeohMaterial::uniaxialNominalStress(double stretch) const {
  const double l = stretch;
  const double i1 = l * l + 2.0 / l;
  return 2.0 * (l - 1.0 / (l * l)) * energyDerivative(i1);
}

double YeohMaterial::equibiaxialEnergy(double stretch) const {
  const double l2 = stretch * stretch;
  return energy(2.0 * l2 + 1.0 / (l2 * l2));
}

double YeohMaterial::equibiaxialEnergyDerivative(double stretch) const {
  const double l = stretch;
  const double l2 = l * l;
  const double i1 = 2.0 * l2 + 1.0 / (l2 * l2);
  const double di1 = 4.0 * l - 4.0 / (l2 * l2 * l);
  return energyDerivative(i1) * di1;
}

double YeohMaterial::equibiaxialEnergySecondDerivative(double stretch) const {
  const double l = stretch;
  const double l2 = l * l;
  const double l6 = l2 * l2 * l2;
  const double i1 = 2.0 * l2 + 1.0 / (l2 * l2);
  const double di1 = 4.0 * l - 4.0 / (l2 * l2 * l);
  const double d2i1 = 4.0 + 20.0 / l6;
  return energySecondDerivative(i1) * di1 * di1 + energyDerivative(i1) * d2i1;
}

Status YeohMaterial::validate() const {
  ErrorList errors;
  if (!std::isfinite(c10_pa) || !std::isfinite(c20_pa) || !std::isfinite(c30_pa)) {
    errors.add("Yeoh constants must be finite");
  } else if (!(c10_pa > 0.0)) {
    errors.add("c10_pa must be positive (initial shear modulus 2*C10), got ", c10_pa);
  } else if (c30_pa < 0.0) {
    errors.add("c30_pa must be >= 0 (else the film softens without bound at large stretch), got ", c30_pa);
  } else if (c30_pa > 0.0) {
    // dW/dI1 = C10 + 2 C20 x + 3 C30 x^2 has its minimum at x = -C20/(3 C30).
    const double x_min = -c20_pa / (3.0 * c30_pa);
    if (x_min > 0.0 && energyDerivative(3.0 + x_min) <= 0.0)
      errors.add("Yeoh constants give dW/dI1 <= 0 at I1 = ", 3.0 + x_min, " (material instability); check c20_pa");
  } else if (c20_pa < 0.0) {
    errors.add("with c30_pa = 0 a negative c20_pa makes dW/dI1 negative at large stretch");
  }
  return errors.status();
}

}  // namespace nursing_bed
