// The register map: the shipped map, the compact block form, and bad maps refused with the
// entry named.
#include <gtest/gtest.h>

#include "../../test_helpers.h"
#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/hardware/register_map.h"

namespace nb = nursing_bed;
using nursing_bed::test::expectContains;

namespace {

// Two cells on one terminal, one proportional, one with a height input.
const char* kGoodMap = R"(
terminals:
  - name: t0
    host: 127.0.0.1
    port: 15600
    cells:
      - cell: 0
        inlet: {coil: 0}
        vent: {coil: 1}
        pressure: {input_register: 0, scale_pa: 2.0, offset_pa: -1000}
      - cell: 1
        inlet: {holding_register: 0, full_scale: 500}
        vent: {holding_register: 1}
        pressure: {input_register: 1, scale_pa: 2.0}
        height: {input_register: 2, scale_m: 1.0e-4}
)";

std::string parseError(const std::string& text, std::uint32_t cells = 2) {
  try {
    nb::parseRegisterMap(text, "map.yaml", cells);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

}  // namespace

TEST(RegisterMap, ParsesCellsWithTheirValvesAndInputs) {
  const nb::RegisterMap map = nb::parseRegisterMap(kGoodMap, "map.yaml", 2);
  ASSERT_EQ(map.terminals.size(), 1u);
  const nb::TerminalMap& t = map.terminals[0];
  EXPECT_EQ(t.cells[0].inlet.kind, nb::ValveOutput::kCoil);
  EXPECT_EQ(t.cells[1].inlet.kind, nb::ValveOutput::kHoldingRegister);
  EXPECT_EQ(t.cells[1].inlet.full_scale, 500.0);
  EXPECT_DOUBLE_EQ(t.cells[0].pressure_pa.toValue(1500), 2000.0);
  EXPECT_EQ(t.cells[0].pressure_pa.toCount(2000.0), 1500);
  EXPECT_TRUE(t.cells[1].height_m.present());
  EXPECT_FALSE(t.cells[0].height_m.present());
  std::size_t terminal = 9, slot = 9;
  ASSERT_TRUE(map.find(1, &terminal, &slot));
  EXPECT_EQ(slot, 1u);
  EXPECT_FALSE(map.find(7, &terminal, &slot));
}

TEST(RegisterMap, TheShippedMapServesTheWholeBedOnThreeTerminals) {
  const nb::RegisterMap map =
      nb::loadRegisterMap(std::string(NURSING_BED_SOURCE_DIR) + "/config/real_bed_register_map.yaml", 180);
  ASSERT_EQ(map.terminals.size(), 3u);
  for (const auto& t : map.terminals) EXPECT_EQ(t.cells.size(), 60u) << t.name;
  EXPECT_EQ(map.terminals[2].cells[59].cell_id, 179u);
  EXPECT_EQ(map.terminals[1].cells[3].vent.address, 103);
  for (const auto& t : map.terminals) EXPECT_EQ(t.realtime_priority, 20) << t.name << ": its bus thread real-time";
}

TEST(RegisterMap, RefusesOverlappingAddressesNamingBothEntries) {
  expectContains(parseError(replaced(kGoodMap, "vent: {coil: 1}", "vent: {coil: 0}")),
                 {"map.yaml", "cell 0 vent", "address 0", "cell 0 inlet"});
  expectContains(parseError(replaced(kGoodMap, "pressure: {input_register: 1,", "pressure: {input_register: 0,")),
                 {"cell 1 pressure", "address 0", "cell 0 pressure"});
}

TEST(RegisterMap, RefusesAMissingCellAZeroScaleAndUnknownKeys) {
  expectContains(parseError(kGoodMap, 3), {"cell 2 is missing"});
  expectContains(parseError(replaced(kGoodMap, "scale_pa: 2.0}", "scale_pa: 0.0}")), {"cell 1 pressure", "scale 0"});
  expectContains(parseError(replaced(kGoodMap, "port: 15600", "port: 15600\n    speed: 3")),
                 {"terminals[0]", "unknown key 'speed'"});
  expectContains(parseError(replaced(kGoodMap, "        vent: {coil: 1}\n", "")), {"cell 0", "'vent'"});
  expectContains(parseError(replaced(kGoodMap, "port: 15600", "port: 70000")), {"terminal 't0'", "port 70000"});
  expectContains(parseError("terminals: 3"), {"'terminals' must be a list"});
}

TEST(RegisterMap, TakesLinkLossAfterSWithinItsBoundsAndRefusesItOutside) {
  auto with = [](const std::string& keys) { return replaced(kGoodMap, "port: 15600", "port: 15600\n" + keys); };
  EXPECT_DOUBLE_EQ(nb::parseRegisterMap(kGoodMap, "map.yaml", 2).terminals[0].link_loss_after_s, 0.2) << "default";
  EXPECT_DOUBLE_EQ(
      nb::parseRegisterMap(with("    link_loss_after_s: 0.3"), "map.yaml", 2).terminals[0].link_loss_after_s, 0.3);
  const std::pair<const char*, const char*> out_of_range[] = {
      {"0", "0"}, {"-0.1", "-0.1"}, {"1.0", "1"}, {"0.41", "0.41"}};
  for (const auto& [yaml, shown] : out_of_range)
    expectContains(
        parseError(with(std::string("    link_loss_after_s: ") + yaml)),
        {"map.yaml", "terminal 't0'", std::string("link_loss_after_s ") + shown + " must lie in (0, 0.4] s"});
  // Not above one request (response timeout 0.05 s + cycle 0.005 s): a single timeout would drop the link.
  expectContains(parseError(with("    link_loss_after_s: 0.05")),
                 {"terminal 't0'", "link_loss_after_s 0.05", "must exceed response_timeout_s + cycle_s"});
  // A silent terminal must be reported within 0.5 s: 0.35 + 0.2 + 0.005 is too late.
  expectContains(parseError(with("    response_timeout_s: 0.2\n    link_loss_after_s: 0.35")),
                 {"terminal 't0'", "link_loss_after_s + response_timeout_s + cycle_s", "0.5 s"});
  expectContains(parseError(with("    link_loss_after_s: soon")),
                 {"terminals[0]", "link_loss_after_s", "not a valid value"});
}

TEST(RegisterMap, TakesTheTerminalsWatchdogAndRefusesOneShorterThanACycle) {
  auto with = [](const std::string& keys) { return replaced(kGoodMap, "port: 15600", "port: 15600\n" + keys); };
  EXPECT_DOUBLE_EQ(nb::parseRegisterMap(kGoodMap, "map.yaml", 2).terminals[0].watchdog_s, 0.1) << "default";
  EXPECT_DOUBLE_EQ(nb::parseRegisterMap(with("    watchdog_s: 1.5"), "map.yaml", 2).terminals[0].watchdog_s, 1.5);
  for (const char* bad : {"0", "0.004", "-1", "61"})
    expectContains(
        parseError(with(std::string("    watchdog_s: ") + bad)),
        {"map.yaml", "terminal 't0'", std::string("watchdog_s ") + bad, "must exceed cycle_s and be at most 60 s"});
}

TEST(RegisterMap, TakesTheBusThreadsRealtimePriorityAndRefusesOneOutOfRange) {
  auto with = [](const std::string& keys) { return replaced(kGoodMap, "port: 15600", "port: 15600\n" + keys); };
  EXPECT_EQ(nb::parseRegisterMap(kGoodMap, "map.yaml", 2).terminals[0].realtime_priority, 0) << "default: normal";
  EXPECT_EQ(nb::parseRegisterMap(with("    realtime_priority: 20"), "map.yaml", 2).terminals[0].realtime_priority, 20);
  for (const char* bad : {"-1", "100"})
    expectContains(parseError(with(std::string("    realtime_priority: ") + bad)),
                   {"map.yaml", "terminal 't0'", std::string("realtime_priority ") + bad, "not in 0..99"});
  expectContains(parseError(with("    realtime_priority: high")),
                 {"terminals[0]", "realtime_priority", "not a valid value"});
}

TEST(RegisterMap, RefusesACellMappedTwiceAndTwoTerminalsOnOneEndpoint) {
  const std::string twice = std::string(kGoodMap) + R"(
  - name: t1
    host: 127.0.0.1
    port: 15600
    cells:
      - cell: 1
        inlet: {coil: 0}
        vent: {coil: 1}
        pressure: {input_register: 0, scale_pa: 2.0}
)";
  expectContains(parseError(twice), {"cell 1 is mapped twice", "'t0'", "'t1'", "used by another terminal"});
}

TEST(AddressRuns, GroupConsecutiveAddressesUpToTheRequestLimit) {
  const auto runs = nb::addressRuns({5, 3, 4, 10, 11, 12, 13}, 3);
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[0].first, 3);
  EXPECT_EQ(runs[0].count, 3);
  EXPECT_EQ(runs[1].first, 10);
  EXPECT_EQ(runs[1].count, 3);
  EXPECT_EQ(runs[2].first, 13);
  EXPECT_EQ(runs[2].count, 1);
}

TEST(PwmChannel, MeanOpeningEqualsTheDutyOverFramesOneFrameLate) {
  for (double duty : {0.0, 0.1, 0.37, 0.5, 0.93, 1.0}) {
    nb::PwmChannel pwm;
    int on = 0;
    const int steps = 4, frames = 250;
    for (int i = 0; i < steps * frames; ++i) on += pwm.next(duty, i % steps, steps) ? 1 : 0;
    if (duty > 0.0) {
      EXPECT_GT(on, 0) << duty;
    }
    // The last frame's demand is still to come: at most one frame short.
    EXPECT_NEAR(static_cast<double>(on) / (steps * frames), duty, 1.0 / frames + 1e-12) << duty;
    EXPECT_LE(static_cast<double>(on) / (steps * frames), duty + 1.0 / (steps * frames)) << duty;
  }
}
