// Pillow structure: volume, effective area and film forces are consistent derivatives of one
// geometry (so the model conserves energy), and the h(p, load) characteristic behaves.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/physics/pillow_structure.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

const nb::PillowParams kParams;

// Film energy of the whole cell, written from the model's definition: n A0 t W(2 l^2 + l^-4).
double filmEnergy(const nb::PillowParams& p, double stretch) {
  const double loop = 2.0 * (p.face_side_m + p.gusset_height_m);
  return p.chambers * 0.5 * loop * loop * p.film_thickness_m * p.material.equibiaxialEnergy(stretch);
}

TEST(PillowStructure, DerivativesAreConsistentWithTheVolume) {
  const nb::PillowStructure s(kParams);
  for (double h : {0.02, 0.08, 0.14}) {
    for (double l : {1.0, 1.05, 1.12}) {
      double q[1] = {l};
      const nb::StructureEval e = s.evaluate(h, q);
      const double dh = 1e-7, dl = 1e-7;
      const double v_hp = s.evaluate(h + dh, q).volume_m3, v_hm = s.evaluate(h - dh, q).volume_m3;
      EXPECT_NEAR(e.effective_area_m2, (v_hp - v_hm) / (2 * dh), 1e-6 * std::abs(e.effective_area_m2) + 1e-10)
          << "h " << h << " l " << l;
      double qp[1] = {l + dl}, qm[1] = {l - dl};
      const double dv_dl = (s.evaluate(h, qp).volume_m3 - s.evaluate(h, qm).volume_m3) / (2 * dl);
      EXPECT_NEAR(e.dvolume_dshape[0], dv_dl, 1e-6 * std::abs(dv_dl) + 1e-12);
      const double dw_dl = (filmEnergy(kParams, l + dl) - filmEnergy(kParams, l - dl)) / (2 * dl);
      EXPECT_NEAR(e.elastic_force[0], dw_dl, 1e-5 * std::abs(dw_dl) + 1e-6);
    }
  }
}

TEST(PillowStructure, FlatCellHoldsOnlyItsDeadVolume) {
  const nb::PillowStructure s(kParams);
  const auto rest = s.restShape();
  const nb::StructureEval e = s.evaluate(0.0, rest.data());
  EXPECT_DOUBLE_EQ(e.volume_m3, kParams.dead_volume_m3);
  const double half_loop = kParams.face_side_m + kParams.gusset_height_m;
  EXPECT_NEAR(e.contact_area_m2, half_loop * half_loop, 1e-15);
  EXPECT_NEAR(e.effective_area_m2, half_loop * half_loop, 1e-15);
  EXPECT_EQ(e.elastic_force[0], 0.0);
  // Pressed into the bed, the plate squeezes the folds' gas out and no more: the volume ends at
  // the dead volume less the folds', and no volume is left for the gas to push the plate with.
  const nb::StructureEval deep = s.evaluate(-0.01, rest.data());
  EXPECT_NEAR(deep.volume_m3, (1.0 - kParams.fold_fraction) * kParams.dead_volume_m3, 1e-15);
  EXPECT_LT(deep.effective_area_m2, 1e-12);
}

TEST(PillowStructure, BelowFlatThePlateForceAreaIsTheVolumesSlope) {
  // Work follows the volume: A_eff = dV/dh on both sides of flat and across it, so the gas does
  // p dV on the plate and nothing more, however hard the plate presses the flat cell.
  const nb::PillowStructure s(kParams);
  const auto rest = s.restShape();
  const double dh = 1e-10;  // far below the folds' depth, whose curvature a longer step would see
  for (double h : {-1e-3, -2e-4, -5e-5, -1e-5, 0.0, 1e-5, 1e-4}) {
    const double slope =
        (s.evaluate(h + dh, rest.data()).volume_m3 - s.evaluate(h - dh, rest.data()).volume_m3) / (2 * dh);
    const double area = s.evaluate(h, rest.data()).effective_area_m2;
    EXPECT_NEAR(area, slope, 1e-5 * s.evaluate(0.0, rest.data()).effective_area_m2) << "h " << h;
  }
  // Continuous at flat: the folds hand the plate over to the bed without a jump in force.
  EXPECT_NEAR(s.evaluate(-1e-12, rest.data()).effective_area_m2, s.evaluate(0.0, rest.data()).effective_area_m2, 1e-9);
}

TEST(PillowStructure, ElasticForceWithoutTheStructureIsTheEvaluatedOne) {
  // The film's force depends on the stretch alone: above and below flat, the static form gives
  // evaluate()'s value to the bit.
  nb::PillowParams params;
  params.film_thickness_m *= 1.3;
  const nb::PillowStructure structure(params);
  for (double stretch : {0.95, 1.0, 1.04, 1.2})
    for (double height : {-1e-4, 0.0, 0.06, 0.14}) {
      EXPECT_EQ(nb::PillowStructure::elasticForce(params, stretch),
                structure.evaluate(height, &stretch).elastic_force[0])
          << "stretch " << stretch << ", height " << height;
    }
}

TEST(PillowStructure, RefusesAFoldFractionOutsideZeroToOne) {
  for (double f : {0.0, 1.0, -0.1, std::nan("")}) {
    nb::PillowParams p = kParams;
    p.fold_fraction = f;
    const nb::Status st = p.validate();
    EXPECT_FALSE(st.ok()) << f;
    EXPECT_NE(st.message().find("fold_fraction"), std::string::npos) << st.message();
  }
}

TEST(PillowStructure, EffectiveAreaShrinksAsTheCellRises) {
  // The load-bearing area must fall with height for h(p) to be single-valued.
  const nb::PillowStructure s(kParams);
  double q[1] = {1.05};
  double previous = 1e9;
  for (double h = 0.0; h < 0.9 * s.heightLimit(q); h += 0.005) {
    const double a = s.evaluate(h, q).effective_area_m2;
    EXPECT_LT(a, previous) << "h " << h;
    previous = a;
  }
  EXPECT_NEAR(s.evaluate(s.heightLimit(q), q).effective_area_m2, 0.0, 1e-12);
}

TEST(PillowStructure, EquilibriumHeightRisesWithPressureAndFallsWithLoad) {
  const nb::PillowStructure s(kParams);
  for (double load : {0.6, 10.6, 20.6}) {
    double previous = -1.0;
    for (double p = 2000.0; p <= 30000.0; p += 2000.0) {
      const nb::StructureEquilibrium e = s.equilibriumAtPressure(p, load);
      ASSERT_TRUE(e.converged);
      EXPECT_GT(e.height_m, previous) << "load " << load << " p " << p;
      previous = e.height_m;
      // Forces balance at the returned state.
      EXPECT_NEAR(p * e.eval.effective_area_m2, load, 1e-6 * load + 1e-9);
    }
  }
  for (double p : {3000.0, 10000.0, 25000.0}) {
    double previous = 1e9;
    for (double load : {0.6, 5.0, 10.6, 15.6, 20.6, 30.0}) {
      const double h = s.equilibriumAtPressure(p, load).height_m;
      EXPECT_LT(h, previous) << "p " << p << " load " << load;
      previous = h;
    }
  }
}

TEST(PillowStructure, UnloadedCellReachesThePapersHeightAtTheValvePressure) {
  // Calibration target (paper section 2.1): 150 mm at the 20 kPa valve setting, plate only.
  const nb::PillowStructure s(kParams);
  EXPECT_NEAR(s.equilibriumAtPressure(20e3, 0.6).height_m, 0.150, 0.002);
}

TEST(PillowStructure, PressureCannotLiftALoadBelowTheFlatCellsArea) {
  const nb::PillowStructure s(kParams);
  const double half_loop = kParams.face_side_m + kParams.gusset_height_m;
  const double lift_off_pa = 20.6 / (half_loop * half_loop);
  EXPECT_EQ(s.equilibriumAtPressure(0.95 * lift_off_pa, 20.6).height_m, 0.0);
  EXPECT_GT(s.equilibriumAtPressure(1.05 * lift_off_pa, 20.6).height_m, 0.0);
}

TEST(PillowStructure, HeightAndPressureEquilibriaAreInverse) {
  const nb::PillowStructure s(kParams);
  for (double h : {0.03, 0.10, 0.14}) {
    const nb::StructureEquilibrium at_h = s.equilibriumAtHeight(h, 15.6);
    ASSERT_TRUE(at_h.converged);
    const nb::StructureEquilibrium at_p = s.equilibriumAtPressure(at_h.gauge_pressure_pa, 15.6);
    EXPECT_NEAR(at_p.height_m, h, 1e-6);
  }
  EXPECT_FALSE(s.equilibriumAtHeight(0.5, 15.6).converged);  // beyond any height the film allows
}

TEST(PillowStructure, ParamsValidationNamesTheField) {
  nb::PillowParams p;
  EXPECT_TRUE(p.validate().ok());
  p.film_thickness_m = 0.0;
  p.chambers = 0;
  const std::string err = p.validate().message();
  EXPECT_NE(err.find("film_thickness_m"), std::string::npos);
  EXPECT_NE(err.find("chambers"), std::string::npos);
}

}  // namespace
