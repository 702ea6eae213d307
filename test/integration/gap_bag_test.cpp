// rostest node (gap_bag.test): the gap diagnosis on bags recorded from the simulated bed.
//
// The launch starts a 1 x 2 bed with sensor noise on; cell (0,0) is simulated with a hidden
// effect (its private ~effects parameter; by default a leak, the launch's `effect` arg), cell
// (0,1) is nominal. This test drives both cells with the same protocol at the same time and
// records their AirbagState topics with rosbag (each message written at its receipt time), one
// bag per run:
//   run A: load 10.6 N, flat -> 0.12 m, 25 s                                 role "fit"
//   (unrecorded: load 15.6 N, down to 0.05 m, settle)
//   run B: load 15.6 N, 0.05 m -> 0.13 m, 25 s                               role "withheld"
// Each run is a leak test: the move and the controller's hold (heartbeats keep the command
// watchdog, safety/command_timeout_s, alive), then from kSealAtS on the heartbeats stop, the
// watchdog shuts both valves and the cell holds its gas to the end of the run.
// It then reads the bags back (readRunsFromBag), makes one dataset per cell and diagnoses each
// against the nominal model of the default cell file with the default options: the affected
// cell must come out "explained" by exactly its effect (each fitted parameter within a factor
// 2 of the simulated one), the nominal one "none". Each report is printed in full
// (reportMarkdown); when the test fails (or NURSING_BED_KEEP_BAGS is set), the bags and the
// reports (report_airbag_R_C/) stay in the temp dir it names.
#include <rosbag/bag.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>
#include <unistd.h>

#include <cstdlib>

#include <filesystem>
#include <iostream>
#include <memory>

#include "bed_fixture.h"
#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/ros/bag_runs.h"

namespace nursing_bed {
namespace test {
namespace fs = std::filesystem;

class GapBagFixture : public BedFixture {
 protected:
  void SetUp() override {
    BedFixture::SetUp();
    if (HasFatalFailure()) return;
    dir_ = fs::temp_directory_path() / ("nursing_bed_gap_bag_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    for (const std::string cell : {"/airbag_0_0", "/airbag_0_1"}) {
      const std::string topic = cell + "/state";
      const boost::function<void(const AirbagState::ConstPtr&)> record = [this, topic](const AirbagState::ConstPtr& m) {
        if (bag_) bag_->write(topic, ros::Time::now(), m);  // receipt time
      };
      record_subs_.push_back(nh_.subscribe<AirbagState>(topic, 100, record));
      load_pubs_.push_back(nh_.advertise<std_msgs::Float64>(cell + "/load", 1, true));
      heartbeat_pubs_.push_back(nh_.advertise<std_msgs::Empty>(cell + "/heartbeat", 1));
    }
    heartbeat_timer_ = nh_.createWallTimer(ros::WallDuration(0.1), [this](const ros::WallTimerEvent&) {
      if (heartbeats_)
        for (auto& p : heartbeat_pubs_) p.publish(std_msgs::Empty());
    });
    ASSERT_TRUE(waitFor(
        [this] {
          for (const auto& p : load_pubs_)
            if (p.getNumSubscribers() == 0) return false;
          for (const auto& p : heartbeat_pubs_)
            if (p.getNumSubscribers() == 0) return false;
          for (const auto& s : record_subs_)
            if (s.getNumPublishers() == 0) return false;
          return true;
        },
        10.0))
        << "the cells' load and state topics are not connected";
  }

  void TearDown() override {
    bag_.reset();
    if (!HasFailure() && !std::getenv("NURSING_BED_KEEP_BAGS")) {
      std::error_code ec;
      fs::remove_all(dir_, ec);
    } else {
      std::cout << "bags kept in " << dir_ << std::endl;
    }
  }

  void setLoads(double load_n) {
    std_msgs::Float64 m;
    m.data = load_n;
    for (auto& p : load_pubs_) p.publish(m);
  }

  void setHeights(double height_m) {
    for (uint32_t id = 0; id < 2; ++id) {
      const SetHeight::Response res = callCell("/airbag_0_" + std::to_string(id), id, height_m);
      EXPECT_TRUE(res.success) << res.message;
    }
  }

  /// Waits until `s` seconds after `start`, spinning.
  void waitUntil(const ros::WallTime& start, double s) {
    waitFor([] { return false; }, s - (ros::WallTime::now() - start).toSec());
  }

  void report(const std::string& what, double target_m) {
    for (uint32_t id = 0; id < 2; ++id)
      std::cout << what << ": cell " << id << " at " << states_[id].height_m << " m, " << states_[id].gauge_pressure_pa
                << " Pa, mode " << int(states_[id].mode) << ", faults " << states_[id].faults << " (target " << target_m
                << " m)" << std::endl;
  }

  /// Records both cells into NAME.bag for kRunS: the move to `height_m` at 0.5 s, the
  /// controller's hold, the sealed hold from kSealAtS.
  fs::path recordRun(const std::string& name, double height_m) {
    const fs::path path = dir_ / (name + ".bag");
    heartbeats_ = true;
    bag_ = std::make_unique<rosbag::Bag>(path.string(), rosbag::bagmode::Write);
    const ros::WallTime start = ros::WallTime::now();
    waitUntil(start, 0.5);
    setHeights(height_m);
    waitUntil(start, kSealAtS);
    report(name + " before sealing", height_m);
    heartbeats_ = false;
    waitUntil(start, kRunS);
    bag_->close();
    bag_.reset();
    heartbeats_ = true;
    report(name + " end", height_m);
    for (uint32_t id = 0; id < 2; ++id)
      EXPECT_TRUE(states_[id].faults & AirbagState::FAULT_COMMAND_TIMEOUT)
          << name << ": cell " << id << " was not sealed";
    return path;
  }

  static constexpr double kRunS = 25.0;    ///< length of a recorded run
  static constexpr double kSealAtS = 8.0;  ///< heartbeats stop here (the watchdog trips ~0.5 s later)

  fs::path dir_;
  std::unique_ptr<rosbag::Bag> bag_;
  std::vector<ros::Subscriber> record_subs_;
  std::vector<ros::Publisher> load_pubs_, heartbeat_pubs_;
  ros::WallTimer heartbeat_timer_;
  bool heartbeats_ = true;
};

TEST_F(GapBagFixture, LeakyCellIsExplainedByALeakAndTheNominalCellByNothing) {
  const ros::WallTime t0 = ros::WallTime::now();
  // The hidden effect of cell (0,0), as its ~effects parameter has it: one candidate with every
  // parameter given.
  std::string effect_text;
  ros::NodeHandle("~").param("effect", effect_text, effect_text);
  SynthEffectRequest truth;
  try {
    truth = parseEffectRequest(effect_text);
  } catch (const std::invalid_argument& e) {
    FAIL() << "~effect '" << effect_text << "': " << e.what();
  }
  ASSERT_FALSE(truth.params.empty()) << "~effect '" << effect_text << "' gives no parameter values";

  // Run A: 10.6 N, flat -> 12 cm.
  setLoads(10.6);
  waitFor([] { return false; }, 1.0);
  const fs::path bag_a = recordRun("run_a", 0.12);
  // Unrecorded: the heavier load, down to 5 cm, settle.
  setLoads(15.6);
  setHeights(0.05);
  EXPECT_TRUE(settle({{0, 0.05}, {1, 0.05}}, 1.5e-3, 1.5, 20.0))
      << "cells at " << states_[0].height_m << ", " << states_[1].height_m << " m";
  // Run B: 15.6 N, 5 cm -> 13 cm.
  const fs::path bag_b = recordRun("run_b", 0.13);
  std::cout << "recorded in " << (ros::WallTime::now() - t0).toSec() << " s" << std::endl;

  // One dataset per cell: run A fits, run B is withheld.
  std::map<std::string, std::vector<RunData>> datasets;
  for (const auto& [bag, role] : {std::make_pair(bag_a, "fit"), std::make_pair(bag_b, "withheld")}) {
    std::vector<RunData> runs = readRunsFromBag(bag.string());
    ASSERT_EQ(runs.size(), 2u) << bag;
    for (RunData& run : runs) {
      run.role = role;
      std::cout << run.name << ": " << run.size() << " samples, " << run.t_s.back() << " s, load " << run.load_n << " N"
                << std::endl;
      datasets[run.meta.at("topic")].push_back(std::move(run));
    }
  }
  ASSERT_EQ(datasets.size(), 2u);

  const CellParams params = loadCellParamsYaml(resolveAirbagParamsFile(""));
  DiagnosisOptions options;
  options.progress = [](const std::string& line) { std::cout << "  " << line << std::endl; };
  std::map<std::string, DiagnosisReport> reports;
  for (const auto& [topic, runs] : datasets) {
    const ros::WallTime d0 = ros::WallTime::now();
    std::cout << "diagnosing " << topic << std::endl;
    DiagnosisReport report = diagnoseRuns(runs, params, options, topic);
    std::cout << "---- " << topic << " (" << (ros::WallTime::now() - d0).toSec() << " s): " << report.status;
    for (const auto& e : report.verdict_effects) std::cout << " " << e;
    std::cout << "\n";
    for (const auto& r : report.reasons) std::cout << "  " << r << "\n";
    std::cout << reportMarkdown(report) << std::endl;
    // Kept with the bags when the test fails.
    writeReportFiles((dir_ / ("report_" + topic.substr(1, topic.rfind('/') - 1))).string(), report);
    reports[topic] = std::move(report);
  }

  const DiagnosisReport& affected = reports.at("/airbag_0_0/state");
  const DiagnosisReport& nominal = reports.at("/airbag_0_1/state");
  EXPECT_EQ(affected.status, "explained");
  EXPECT_EQ(affected.verdict_effects, std::vector<std::string>{truth.name});
  for (const auto& [key, simulated] : truth.params) {
    if (!affected.verdict_params.count(key)) continue;
    const double fitted = affected.verdict_params.at(key);
    std::cout << "fitted " << key << " " << fitted << ", simulated " << simulated << std::endl;
    EXPECT_GT(fitted, 0.5 * simulated) << key;
    EXPECT_LT(fitted, 2.0 * simulated) << key;
  }
  EXPECT_EQ(nominal.status, "none");
  EXPECT_TRUE(nominal.verdict_effects.empty());
  std::cout << "total " << (ros::WallTime::now() - t0).toSec() << " s" << std::endl;
}

}  // namespace test
}  // namespace nursing_bed
