// Gas and orifice flow (paper eq. 16-23 with the choked branch).
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/physics/orifice.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

const nb::GasProperties kAir;

TEST(Gas, AirPropertiesAndCriticalRatio) {
  EXPECT_NEAR(kAir.cv(), 717.6, 0.1);
  EXPECT_NEAR(kAir.cp(), 1004.7, 0.1);
  EXPECT_NEAR(kAir.criticalPressureRatio(), 0.5283, 1e-4);
  EXPECT_TRUE(kAir.validate().ok());
  nb::GasProperties bad;
  bad.heat_capacity_ratio = 0.9;
  EXPECT_NE(bad.validate().message().find("heat_capacity_ratio"), std::string::npos);
}

TEST(Gas, EnergyPressureTemperatureRoundTrip) {
  const double v = 1.5e-3, t = 300.0, p = 120e3;
  const double m = nb::massFromState(kAir, p, t, v);
  const double u = m * kAir.cv() * t;
  EXPECT_NEAR(nb::pressureFromEnergy(kAir, u, v), p, 1e-9 * p);
  EXPECT_NEAR(nb::temperatureFromEnergy(kAir, u, m), t, 1e-12 * t);
}

// Closed forms written out independently of the implementation.
double chokedClosedForm(double area, double p_up, double t_up) {
  const double g = 1.4, r = 287.05;
  return area * p_up * std::sqrt(g / (r * t_up)) * std::pow(2.0 / (g + 1.0), (g + 1.0) / (2.0 * (g - 1.0)));
}
double subsonicClosedForm(double area, double p_up, double t_up, double p_down) {
  const double g = 1.4, r = 287.05, pr = p_down / p_up;
  // rho_out u A with u from eq. 21 and rho_out = rho (p_out/p)^(1/gamma) from eq. 18.
  const double rho = p_up / (r * t_up);
  const double u = std::sqrt(2.0 * g / (g - 1.0) * p_up / rho * (1.0 - std::pow(pr, (g - 1.0) / g)));
  return rho * std::pow(pr, 1.0 / g) * u * area;
}

TEST(Orifice, ChokedFlowMatchesClosedForm) {
  const double area = 2e-6;
  for (double p_up : {250e3, 400e3, 1e6}) {
    const nb::OrificeFlow f = nb::orificeFlow(kAir, area, p_up, 293.15, 101325.0, 293.15, 100.0);
    EXPECT_TRUE(f.choked);
    EXPECT_NEAR(f.mass_flow_kg_s, chokedClosedForm(area, p_up, 293.15), 1e-12);
  }
}

TEST(Orifice, SubsonicFlowMatchesClosedForm) {
  const double area = 2e-6;
  for (double p_up : {102e3, 110e3, 150e3, 190e3}) {
    const nb::OrificeFlow f = nb::orificeFlow(kAir, area, p_up, 310.0, 101325.0, 293.15, 100.0);
    EXPECT_FALSE(f.choked);
    const double expected = subsonicClosedForm(area, p_up, 310.0, 101325.0);
    EXPECT_NEAR(f.mass_flow_kg_s, expected, 1e-9 * expected) << "p_up " << p_up;
    EXPECT_DOUBLE_EQ(f.upstream_temperature_k, 310.0);
  }
}

TEST(Orifice, ContinuousAtTheChokingRatio) {
  const double p_up = 200e3, rc = kAir.criticalPressureRatio();
  const double below = nb::isentropicMassFlow(kAir, 1e-6, p_up, 293.15, p_up * rc * (1 - 1e-9));
  const double above = nb::isentropicMassFlow(kAir, 1e-6, p_up, 293.15, p_up * rc * (1 + 1e-9));
  EXPECT_NEAR(below, above, 1e-9 * below);
}

TEST(Orifice, ReversesWithThePressureDifferenceAndCarriesUpstreamTemperature) {
  const nb::OrificeFlow f = nb::orificeFlow(kAir, 1e-6, 101325.0, 293.15, 130e3, 320.0, 100.0);
  EXPECT_LT(f.mass_flow_kg_s, 0.0);
  EXPECT_DOUBLE_EQ(f.upstream_temperature_k, 320.0);
  EXPECT_NEAR(-f.mass_flow_kg_s, subsonicClosedForm(1e-6, 130e3, 320.0, 101325.0), 1e-12);
}

TEST(Orifice, SmoothAndMonotoneThroughZeroDifference) {
  // Inside the band the flow is a monotone odd cubic; at the band edge value and slope match.
  const double band = 100.0, p_down = 101325.0;
  double previous = -1.0;
  for (double dp = -300.0; dp <= 300.0; dp += 0.5) {
    const double flow = nb::orificeFlow(kAir, 1e-6, p_down + dp, 293.15, p_down, 293.15, band).mass_flow_kg_s;
    EXPECT_GT(flow, previous) << "dp " << dp;
    previous = flow;
  }
  EXPECT_EQ(nb::orificeFlow(kAir, 1e-6, p_down, 293.15, p_down, 293.15, band).mass_flow_kg_s, 0.0);
  auto flow_at = [&](double dp) {
    return nb::orificeFlow(kAir, 1e-6, p_down + dp, 293.15, p_down, 293.15, band).mass_flow_kg_s;
  };
  const double eps = 1e-4;
  EXPECT_NEAR(flow_at(band - eps), flow_at(band + eps), 1e-6 * flow_at(band));
  const double slope_in = (flow_at(band - eps) - flow_at(band - 3 * eps)) / (2 * eps);
  const double slope_out = (flow_at(band + 3 * eps) - flow_at(band + eps)) / (2 * eps);
  EXPECT_NEAR(slope_in, slope_out, 1e-3 * slope_out);
}

TEST(Orifice, PressureSlopesMatchCentralDifferences) {
  // Choked, subsonic and inside the band, in both directions: the returned slopes against
  // central differences of the flow in each side's pressure.
  const double band = 100.0, p_b = 101325.0;
  for (double dp : {150e3, 30e3, 2000.0, 120.0, 60.0, 5.0, -5.0, -60.0, -2000.0, -30e3}) {
    auto flow = [&](double pa, double pb) {
      return nb::orificeFlow(kAir, 1e-6, pa, 310.0, pb, 293.15, band).mass_flow_kg_s;
    };
    const nb::OrificeFlow f = nb::orificeFlow(kAir, 1e-6, p_b + dp, 310.0, p_b, 293.15, band);
    const double h = 1e-3;
    const double d_pa = (flow(p_b + dp + h, p_b) - flow(p_b + dp - h, p_b)) / (2.0 * h);
    const double d_pb = (flow(p_b + dp, p_b + h) - flow(p_b + dp, p_b - h)) / (2.0 * h);
    const double scale = std::max(std::fabs(d_pa), std::fabs(d_pb));
    EXPECT_NEAR(f.d_flow_d_pa, d_pa, 1e-5 * scale) << "dp " << dp;
    EXPECT_NEAR(f.d_flow_d_pb, d_pb, 1e-5 * scale) << "dp " << dp;
  }
  const nb::OrificeFlow closed = nb::orificeFlow(kAir, 0.0, 300e3, 293.15, 101325.0, 293.15, band);
  EXPECT_EQ(closed.d_flow_d_pa, 0.0);
  EXPECT_EQ(closed.d_flow_d_pb, 0.0);
}

TEST(Orifice, ClosedValvePassesNothing) {
  EXPECT_EQ(nb::orificeFlow(kAir, 0.0, 300e3, 293.15, 101325.0, 293.15, 100.0).mass_flow_kg_s, 0.0);
}

}  // namespace

namespace {

// ISO 6358: choked below b, the elliptic law above it, continuous at b, nothing without a
// pressure drop or a conductance.
TEST(Iso6358, ChokedAndSubsonicFlowMeetAtTheCriticalRatio) {
  const double c = 1.5e-7, b = 0.3, p_up = 136325.0, t = 293.15;
  const double choked = nb::iso6358MassFlow(c, b, p_up, t, 0.2 * p_up);
  EXPECT_NEAR(choked, c * nb::kIso6358ReferenceDensityKgM3 * p_up, 1e-12);
  EXPECT_NEAR(nb::iso6358MassFlow(c, b, p_up, t, b * p_up), choked, 1e-12);
  EXPECT_NEAR(nb::iso6358MassFlow(c, b, p_up, t, (b + 1e-9) * p_up), choked, 1e-9 * choked);
  const double r = 0.65, x = (r - b) / (1.0 - b);
  EXPECT_NEAR(nb::iso6358MassFlow(c, b, p_up, t, r * p_up), choked * std::sqrt(1.0 - x * x), 1e-12);
  EXPECT_NEAR(nb::iso6358MassFlow(c, b, p_up, 4.0 * t, 0.0), 0.5 * choked, 1e-12);  // sqrt(T0/T)
  EXPECT_EQ(nb::iso6358MassFlow(c, b, p_up, t, p_up), 0.0);
  EXPECT_EQ(nb::iso6358MassFlow(c, b, p_up, t, 2.0 * p_up), 0.0);
  EXPECT_EQ(nb::iso6358MassFlow(0.0, b, p_up, t, 0.0), 0.0);
}

}  // namespace
