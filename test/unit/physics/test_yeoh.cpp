// Yeoh film law (paper eq. 7-10): stresses are derivatives of the strain energy.
#include <gtest/gtest.h>

#include "nursing_bed/core/physics/yeoh.h"

namespace nb = nursing_bed;

namespace {

const nb::YeohMaterial kTpu;  // defaults: fitted to data/tpu_uniaxial.csv

double uniaxialEnergy(const nb::YeohMaterial& m, double l) { return m.energy(l * l + 2.0 / l); }

TEST(Yeoh, UniaxialStressIsTheDerivativeOfTheEnergy) {
  for (double l : {1.01, 1.1, 1.5, 2.0, 3.0}) {
    const double h = 1e-6;
    const double fd = (uniaxialEnergy(kTpu, l + h) - uniaxialEnergy(kTpu, l - h)) / (2 * h);
    EXPECT_NEAR(kTpu.uniaxialNominalStress(l), fd, 1e-6 * std::abs(fd)) << "stretch " << l;
  }
}

TEST(Yeoh, EquibiaxialDerivativesMatchFiniteDifferences) {
  for (double l : {0.95, 1.0, 1.05, 1.2, 1.6}) {
    const double h = 1e-6;
    const double d1 = (kTpu.equibiaxialEnergy(l + h) - kTpu.equibiaxialEnergy(l - h)) / (2 * h);
    const double d2 = (kTpu.equibiaxialEnergyDerivative(l + h) - kTpu.equibiaxialEnergyDerivative(l - h)) / (2 * h);
    EXPECT_NEAR(kTpu.equibiaxialEnergyDerivative(l), d1, 1e-5 * std::max(1.0, std::abs(d1))) << l;
    EXPECT_NEAR(kTpu.equibiaxialEnergySecondDerivative(l), d2, 1e-5 * std::abs(d2)) << l;
  }
}

TEST(Yeoh, SmallStrainModulusIsSixC10) {
  // Uniaxial: sigma ~ E (l - 1) with E = 6 C10 near l = 1.
  const double l = 1.0 + 1e-6;
  EXPECT_NEAR(kTpu.uniaxialNominalStress(l) / (l - 1.0), 6.0 * kTpu.c10_pa, 1e-4 * 6.0 * kTpu.c10_pa);
  EXPECT_NEAR(kTpu.youngsModulus(), 6.0 * kTpu.c10_pa, 1e-9);
  EXPECT_EQ(kTpu.uniaxialNominalStress(1.0), 0.0);
}

TEST(Yeoh, ValidationNamesTheProblem) {
  EXPECT_TRUE(kTpu.validate().ok());
  nb::YeohMaterial m;
  m.c10_pa = -1.0;
  EXPECT_NE(m.validate().message().find("c10_pa"), std::string::npos);
  m = nb::YeohMaterial{};
  m.c20_pa = -3.0e6;  // dW/dI1 turns negative: unstable film
  EXPECT_NE(m.validate().message().find("instability"), std::string::npos);
  m = nb::YeohMaterial{};
  m.c30_pa = -1.0;
  EXPECT_NE(m.validate().message().find("c30_pa"), std::string::npos);
}

}  // namespace
