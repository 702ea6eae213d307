// rostest node for the bed's edges (doc/safety.md): fuzzed arguments to every service and topic,
// stray publishers on the per-cell command topics, the start-up judging no cell dead, and a lost
// fieldbus terminal as a bed alarm. Each .test file runs one case (--gtest_filter); the figures
// are printed and recorded.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/master.h>
#include <ros/network.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>
#include <std_msgs/Float64MultiArray.h>

#include <cstdlib>
#include <limits>
#include <random>
#include <set>

#include "bed_fixture.h"
#include "nursing_bed/SetPressure.h"

namespace nursing_bed {
namespace test {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::string cellName(int row, int col) { return "/airbag_" + std::to_string(row) + "_" + std::to_string(col); }

/// Text no request may accept: huge and malformed numbers, unicode, empty, deeply nested.
std::vector<std::string> hostileTexts() {
  std::vector<std::string> t{"",
                             std::string(40000, '9'),
                             "-" + std::string(40000, '1'),
                             "0." + std::string(40000, '0') + "1",
                             "1e" + std::string(40000, '9'),
                             std::string(40000, '(') + "0.1" + std::string(40000, ')'),
                             std::string(10000, '[') + "0.1" + std::string(10000, ']'),
                             std::string(10000, '{'),
                             "\xef\xbc\x90.\xef\xbc\x91",  // fullwidth "0.1"
                             "\xd9\xa0.\xd9\xa1",          // Arabic-Indic "0.1"
                             "0.1\xc2\xa0",                // a no-break space after
                             "\xf0\x9f\x9b\x8f",           // a bed emoji
                             "\xff\xfe\xfd",               // not UTF-8
                             std::string("0.1\0junk", 8),
                             "nan",
                             "-inf",
                             "1e999",
                             "0x1p-3",
                             " ",
                             "\n",
                             std::string(100000, 'x')};
  return t;
}

/// Random text from `rng`: hostile pieces, random bytes, or a random-length digit run.
std::string randomText(std::mt19937& rng) {
  static const std::vector<std::string> texts = hostileTexts();
  switch (rng() % 3) {
    case 0: return texts[rng() % texts.size()];
    case 1: {
      std::string s(1 + rng() % 64, ' ');
      for (char& c : s) c = static_cast<char>(rng() % 256);
      return s;
    }
    default: return std::string(1 + rng() % 50000, static_cast<char>('0' + rng() % 10));
  }
}

/// A double no cell or plan accepts as a height, pressure or load.
double randomBadNumber(std::mt19937& rng) {
  static const std::vector<double> bad{kNaN, kInf, -kInf, 1e308, -1e308, 1e9, -1e-9, -0.5, 4.9e-324, 1e5};
  return bad[rng() % bad.size()];
}

/// A load no cell accepts (outside 0..safety/max_load_n or not finite).
double randomBadLoad(std::mt19937& rng) {
  static const std::vector<double> bad{kNaN, kInf, -kInf, 1e308, -1e308, 1e9, -1e-9, -0.5, -4.9e-324, 1e5};
  return bad[rng() % bad.size()];
}

}  // namespace

class EdgesFixture : public PlanFixture {
 protected:
  std::set<std::string> nodes() {
    std::vector<std::string> list;
    ros::master::getNodes(list);
    return {list.begin(), list.end()};
  }

  /// The bed's own state: plan, parameters, each cell's setpoint and load.
  std::string stateText() {
    std::string s = bed_.plan + " " + bed_.parameters;
    for (int id = 0; id < cells(); ++id)
      s += " | " + std::to_string(std::round(states_[id].height_setpoint_m * 1e4) / 1e4) + " " +
           std::to_string(states_[id].external_load_n) + " " + std::to_string(states_[id].mode);
    return s;
  }

  /// One bad call; counts it and whether it was refused with a reason.
  template <typename Srv>
  void callBad(const std::string& service, Srv& srv) {
    ++calls_;
    if (!callService(service, srv)) {  // retried once on a dropped connection
      ADD_FAILURE() << service << ": the call failed twice (is the server alive?)";
      return;
    }
    if (!srv.response.success && !srv.response.message.empty()) ++refused_;
    else ADD_FAILURE() << service << " accepted a bad request: " << srv.response.message;
  }

  void fuzzPosture(std::mt19937& rng) {
    static const std::vector<std::string> plans{"flat", "cpr", "max_inflate", "alternating", "lateral_turn", "custom"};
    static const std::vector<std::string> keys{"height_m", "timeout_s", "pattern", "side", "angle_deg", "period_s"};
    SetPosture srv;
    const int kind = static_cast<int>(rng() % 4);
    if (kind == 0) {  // a hostile plan name
      srv.request.plan = randomText(rng);
    } else if (kind == 1) {  // a real plan, a real key, a hostile value
      srv.request.plan = plans[rng() % 5];
      srv.request.keys = {keys[rng() % keys.size()]};
      srv.request.values = {randomText(rng)};
    } else if (kind == 2) {  // long lists: many keys, values, heights
      srv.request.plan = plans[rng() % plans.size()];
      const std::size_t n = 1 + rng() % 20000;
      srv.request.keys.assign(n, randomText(rng).substr(0, 100));
      srv.request.values.assign(n + rng() % 2, "0.1");
      srv.request.heights_m.assign(rng() % 100000, randomBadNumber(rng));
    } else {  // custom with bad heights
      srv.request.plan = "custom";
      srv.request.heights_m.assign(cells(), 0.1);
      srv.request.heights_m[rng() % cells()] = randomBadNumber(rng);
    }
    callBad("/bed_manager/set_posture", srv);
  }

  void fuzzHeights(std::mt19937& rng) {
    SetHeights many;
    const std::size_t n = 1 + rng() % 50000;
    for (std::size_t i = 0; i < n; ++i) many.request.cell_ids.push_back(static_cast<uint32_t>(rng()));
    many.request.heights_m.assign(n + rng() % 2, randomBadNumber(rng));
    callBad("/bed_manager/set_airbag_heights", many);
    SetHeight one;
    one.request.cell_id = rng() % 2 ? static_cast<uint32_t>(rng()) : static_cast<uint32_t>(rng() % cells());
    one.request.height_m = randomBadNumber(rng);
    callBad("/bed_manager/set_airbag_height", one);
  }

  void fuzzCells(std::mt19937& rng) {
    const int id = static_cast<int>(rng() % cells());
    const std::string ns = cellName(id / cols_, id % cols_);
    SetHeight h;
    h.request.cell_id = rng() % 2 ? id : static_cast<uint32_t>(rng());
    h.request.height_m = rng() % 2 ? randomBadNumber(rng) : 0.05;  // owned by the manager: refused anyway
    callBad(ns + "/set_height", h);
    SetPressure p;
    p.request.cell_id = rng() % 2 ? id : static_cast<uint32_t>(rng());
    p.request.pressure_pa = rng() % 2 ? randomBadNumber(rng) : 3000.0;
    callBad(ns + "/set_pressure", p);
  }

  int calls_ = 0, refused_ = 0;
};

TEST_F(EdgesFixture, FuzzedArgumentsToEveryServiceAndTopicAreRefusedAndChangeNothing) {
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.08"}).success);
  ASSERT_TRUE(settle(uniform(0.08), 2e-3, 0.3, 25.0));
  for (const char* s : {"/bed_manager/set_posture", "/bed_manager/set_airbag_heights"})
    ASSERT_TRUE(ros::service::waitForService(s, ros::Duration(5.0)));
  const std::set<std::string> nodes_before = nodes();
  // The reference is a steady state: the setpoint ramp and mode may still end after the heights settle.
  std::string before = stateText();
  ros::WallTime steady_since = ros::WallTime::now();
  ASSERT_TRUE(waitFor(
      [&] {
        const std::string now = stateText();
        if (now != before) {
          before = now;
          steady_since = ros::WallTime::now();
        }
        return (ros::WallTime::now() - steady_since).toSec() >= 1.0;
      },
      10.0))
      << "the bed did not hold a steady state before the fuzzing: " << before;
  const auto counts_before = counts_;
  // Topics: every per-cell topic and the bed-wide ones, from this (stray) node.
  std::vector<ros::Publisher> loads, setpoints, vents, heartbeats;
  for (int id = 0; id < cells(); ++id) {
    const std::string ns = cellName(id / cols_, id % cols_);
    loads.push_back(nh_.advertise<std_msgs::Float64>(ns + "/load", 100));
    setpoints.push_back(nh_.advertise<std_msgs::Float64>(ns + "/height_setpoint", 100));
    vents.push_back(nh_.advertise<std_msgs::Empty>(ns + "/vent", 100));
    heartbeats.push_back(nh_.advertise<std_msgs::Empty>(ns + "/heartbeat", 100));
  }
  ros::Publisher array = nh_.advertise<std_msgs::Float64MultiArray>("/airbag_loads", 100);
  ros::Publisher bed_heartbeat = nh_.advertise<std_msgs::Empty>("/bed_manager/heartbeat", 100);
  waitFor([&] { return array.getNumSubscribers() > 0 && vents.back().getNumSubscribers() > 0; }, 5.0);
  std::mt19937 rng(42);
  int messages = 0;
  const ros::WallTime start = ros::WallTime::now();
  for (int round = 0; round < 250; ++round) {
    fuzzPosture(rng);
    fuzzHeights(rng);
    fuzzCells(rng);
    const int id = static_cast<int>(rng() % cells());
    std_msgs::Float64 value;
    value.data = randomBadLoad(rng);
    loads[id].publish(value);
    value.data = rng() % 2 ? randomBadNumber(rng) : 0.15;  // a valid height from a stray node
    setpoints[id].publish(value);
    vents[id].publish(std_msgs::Empty());
    heartbeats[id].publish(std_msgs::Empty());
    bed_heartbeat.publish(std_msgs::Empty());
    std_msgs::Float64MultiArray m;
    if (rng() % 2) m.data.assign(rng() % 200000, 10.0);  // wrong lengths (a right one is never drawn)
    else m.data.assign(cells(), randomBadLoad(rng));
    if (m.data.size() == static_cast<std::size_t>(cells()) && std::isfinite(m.data[0])) m.data.push_back(10.0);
    m.layout.dim.resize(rng() % 1000);  // nested dimensions nobody reads
    array.publish(m);
    messages += 6;
    ros::spinOnce();
  }
  const double fuzz_s = (ros::WallTime::now() - start).toSec();
  waitFor([] { return false; }, 2.0);
  EXPECT_GE(calls_, 1000);
  EXPECT_EQ(refused_, calls_);
  EXPECT_EQ(nodes(), nodes_before) << "a process died";
  for (int id = 0; id < cells(); ++id) EXPECT_GT(counts_[id], counts_before.at(id) + 20) << "cell " << id << " silent";
  EXPECT_EQ(stateText(), before);
  EXPECT_TRUE(bed_.dead_cells.empty() && bed_.faulty_cells.empty());
  EXPECT_TRUE(settle(uniform(0.08), 2e-3, 0.3, 5.0)) << "a refused request moved a cell";
  std::printf(
      "fuzz: %d service calls (%d refused with a reason), %d topic messages in %.1f s; %zu nodes alive, "
      "state unchanged\n",
      calls_, refused_, messages, fuzz_s, nodes().size());
  RecordProperty("fuzz_calls", calls_);
  RecordProperty("fuzz_refused", refused_);
  RecordProperty("fuzz_messages", messages);
}

TEST_F(EdgesFixture, StrayPerCellPublishersNeitherMoveAnOwnedCellNorKeepCellsOutOfSafe) {
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.08"}).success);
  ASSERT_TRUE(settle(uniform(0.08), 2e-3, 0.3, 25.0));
  ros::Publisher setpoint = nh_.advertise<std_msgs::Float64>("/airbag_0_0/height_setpoint", 10);
  ros::Publisher vent = nh_.advertise<std_msgs::Empty>("/airbag_0_1/vent", 10);
  std::vector<ros::Publisher> heartbeats;
  for (int id = 0; id < cells(); ++id)
    heartbeats.push_back(nh_.advertise<std_msgs::Empty>(cellName(id / cols_, id % cols_) + "/heartbeat", 10));
  ros::Publisher bed_heartbeat = nh_.advertise<std_msgs::Empty>("/bed_manager/heartbeat", 10);
  ASSERT_TRUE(waitFor([&] { return setpoint.getNumSubscribers() > 0 && vent.getNumSubscribers() > 0; }, 5.0));
  // 3 s of a stray 0.15 m setpoint at 50 Hz and a vent at 10 Hz.
  double lowest = 1.0, highest = 0.0;
  max_setpoint_rate_m_s_ = 0.0;
  for (int i = 0; i < 150; ++i) {
    std_msgs::Float64 m;
    m.data = 0.15;
    setpoint.publish(m);
    if (i % 5 == 0) vent.publish(std_msgs::Empty());
    waitFor([] { return false; }, 0.02);
    highest = std::max(highest, states_[0].height_m);
    lowest = std::min(lowest, states_[1].height_m);
  }
  EXPECT_LT(highest, 0.08 + 3e-3) << "a stray setpoint moved cell 0";
  EXPECT_GT(lowest, 0.08 - 3e-3) << "a stray vent dropped cell 1";
  EXPECT_NEAR(states_[0].height_setpoint_m, 0.08, 1e-9);
  EXPECT_EQ(states_[1].mode, AirbagState::MODE_HEIGHT);
  EXPECT_LE(max_setpoint_rate_m_s_, 0.02 * 1.1);
  std::printf("stray setpoint 0.15 m and vents for 3 s: cell 0 at most %.1f mm, cell 1 at least %.1f mm (target 80)\n",
              1e3 * highest, 1e3 * lowest);
  // The bed manager dies while a stray node sends heartbeats: every cell still goes SAFE.
  ros::WallTimer beat = nh_.createWallTimer(ros::WallDuration(0.1), [&](const ros::WallTimerEvent&) {
    bed_heartbeat.publish(std_msgs::Empty());
    for (auto& p : heartbeats) p.publish(std_msgs::Empty());
  });
  ASSERT_EQ(std::system("rosnode kill /bed_manager > /dev/null 2>&1"), 0);
  const ros::WallTime killed = ros::WallTime::now();
  const bool safe = everyCellSafeWithin(5.0);
  const double safe_s = (ros::WallTime::now() - killed).toSec();
  beat.stop();
  EXPECT_TRUE(safe) << "a stray heartbeat kept cells out of SAFE";
  std::printf("bed manager killed under stray heartbeats: every cell SAFE after %.2f s\n", safe_s);
  RecordProperty("stray_highest_mm", std::to_string(1e3 * highest));
  RecordProperty("stray_lowest_mm", std::to_string(1e3 * lowest));
  RecordProperty("safe_after_kill_s", std::to_string(safe_s));
}

TEST_F(EdgesFixture, TheStartUpDeclaresNoCellDeadAndStartsTheInitialPlan) {
  // The fixture waited for every cell; the bed manager's state since its start is watched here.
  ros::NodeHandle pnh("~");
  double watch_s = 15.0;
  pnh.param("watch_s", watch_s, watch_s);
  std::set<std::string> plans;
  std::size_t most_dead = 0;
  ros::Subscriber sub = nh_.subscribe<BedState>("/bed_manager/state", 50, [&](const BedState::ConstPtr& m) {
    plans.insert(m->plan);
    most_dead = std::max(most_dead, m->dead_cells.size());
  });
  waitFor([] { return false; }, watch_s);
  EXPECT_EQ(most_dead, 0u);
  EXPECT_EQ(plans, std::set<std::string>{"flat"});
  EXPECT_TRUE(settle(uniform(0.10), 5e-3, 0.3, 40.0)) << "the bed never got flat";
  std::printf("start-up of %d cells: plans seen {%s}, at most %zu cells dead\n", cells(),
              plans.empty() ? "" : plans.begin()->c_str(), most_dead);
  RecordProperty("most_dead", static_cast<int>(most_dead));
}

TEST_F(EdgesFixture, ALostTerminalIsABedAlarmWithItsCellsSafeOnDiagnosticsWithinHalfASecond) {
  std::vector<uint32_t> ids;
  for (int id = 0; id < cells(); ++id) ids.push_back(id);
  ASSERT_TRUE(callBed(ids, std::vector<double>(ids.size(), 0.06)).success);
  ASSERT_TRUE(settle(uniform(0.06), 0.01, 0.5, 40.0));
  diagnostic_msgs::DiagnosticStatus bed_diag;
  ros::Subscriber diag_sub = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& m) {
        for (const auto& s : m->status)
          if (s.name == "bed") bed_diag = s;
      });
  ASSERT_NO_FATAL_FAILURE(shutdownNode("/rig_emulator", "test: terminal lost"));
  const ros::WallTime lost = ros::WallTime::now();
  double safe_s = kNaN, alarm_s = kNaN, diag_s = kNaN;
  auto contains = [](const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; };
  waitFor(
      [&] {
        const double t = (ros::WallTime::now() - lost).toSec();
        bool all_safe = true;
        for (int id = 0; id < cells(); ++id)
          all_safe = all_safe && states_[id].mode == AirbagState::MODE_SAFE &&
                     (states_[id].faults & AirbagState::FAULT_COMMUNICATION);
        if (all_safe && std::isnan(safe_s)) safe_s = t;
        if (std::isnan(alarm_s) && !bed_.alarms.empty() && contains(bed_.alarms.front(), "hardware link lost"))
          alarm_s = t;
        if (std::isnan(diag_s) && bed_diag.level == diagnostic_msgs::DiagnosticStatus::ERROR &&
            contains(bed_diag.message, "hardware link lost") && contains(bed_diag.message, "airbag_0_0"))
          diag_s = t;
        return !std::isnan(safe_s) && !std::isnan(alarm_s) && !std::isnan(diag_s);
      },
      5.0);
  std::printf("terminal lost: every cell SAFE after %.3f s, bed alarm after %.3f s, /diagnostics ERROR after %.3f s\n",
              safe_s, alarm_s, diag_s);
  // Within 0.5 s, give or take this process's view of the 50 Hz states.
  EXPECT_LE(safe_s, 0.5 + 0.04);
  EXPECT_LE(alarm_s, 0.5 + 0.04);
  EXPECT_LE(diag_s, 0.5 + 0.04);
  EXPECT_TRUE(bed_.dead_cells.empty());
  for (int id = 0; id < cells(); ++id) EXPECT_NEAR(states_[id].height_setpoint_m, 0.06, 1e-5) << "cell " << id;
  RecordProperty("safe_s", std::to_string(safe_s));
  RecordProperty("alarm_s", std::to_string(alarm_s));
  RecordProperty("diagnostics_s", std::to_string(diag_s));
}

}  // namespace test
}  // namespace nursing_bed
