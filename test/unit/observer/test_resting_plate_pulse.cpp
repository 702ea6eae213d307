// RestingPlatePulse: which periods it corrects (core/observer/resting_plate_pulse.h).
#include <gtest/gtest.h>

#include "nursing_bed/core/observer/resting_plate_pulse.h"

namespace nb = nursing_bed;

namespace {

struct Cell {
  Cell() : model(params) {
    model.resetToEquilibrium(0.045, 2.0);
    state = model.state();
    rest = model.variables();
  }
  /// One period of `pulse` from the cell at rest, the vent at `vent`.
  double period(nb::RestingPlatePulse& pulse, double vent) {
    nb::CellInputs in;
    in.vent_opening = vent;
    in.load_n = 2.0;
    in.flow_gauge_pressure_pa = rest.gauge_pressure_pa;
    const double f = pulse.factor(model, 0.0, state, rest.pressure_pa, in, rest.gauge_pressure_pa, 0.005);
    model.setState(0.0, state);
    return f;
  }
  nb::CellParams params;
  nb::CellModel model;
  nb::CellModel::StateVector state;
  nb::CellVariables rest;
};

}  // namespace

TEST(RestingPlatePulse, CorrectsOnlyAnOpeningOnAPlateThatHasRestedAtALowPressure) {
  Cell cell;
  ASSERT_NEAR(cell.rest.gauge_pressure_pa, 100.0, 30.0);
  nb::RestingPlatePulse pulse(300.0);
  EXPECT_EQ(cell.period(pulse, 0.0), 1.0) << "valves shut";
  const double first = cell.period(pulse, 1.0);
  EXPECT_LT(first, 0.95) << "a vent opening on the resting plate passes less than at the readings' pressure";
  EXPECT_GT(first, 0.5);
  EXPECT_EQ(cell.period(pulse, 1.0), 1.0) << "a train's second period: the plate is moving";
  for (int k = 0; k < 4; ++k) EXPECT_EQ(cell.period(pulse, 0.0), 1.0);
  EXPECT_EQ(cell.period(pulse, 1.0), 1.0) << "20 ms shut: the plate still rings";
  for (int k = 0; k < 8; ++k) cell.period(pulse, 0.0);
  EXPECT_NEAR(cell.period(pulse, 1.0), first, 1e-3) << "40 ms shut: at rest again";

  pulse.interrupt();
  EXPECT_EQ(cell.period(pulse, 1.0), 1.0) << "after lost readings the plate's motion is unknown";
  nb::RestingPlatePulse high(50.0);
  EXPECT_EQ(cell.period(high, 1.0), 1.0) << "above the swing pressure the readings count it";
  nb::RestingPlatePulse fresh(300.0);
  EXPECT_EQ(cell.period(fresh, 1e-9), 1.0) << "a sliver of an opening (the delay line's rounding)";
  EXPECT_NEAR(cell.period(fresh, 1.0), first, 1e-3) << "and the plate still rests";
}
