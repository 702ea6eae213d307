// The simulator's tissue-load metrics on the running bed: the topic appears at its rate with one
// entry per region in every array and values a supine patient on a flat bed can have; the
// margin rises off the bed base as the flat plan fills the cells.
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/RigTruth.h"
#include "nursing_bed/TissueLoad.h"

namespace nursing_bed {
namespace test {

TEST(TissueLoadTopic, AppearsWithSaneValuesForASupinePatient) {
  ros::NodeHandle nh;
  std::vector<TissueLoad> got;
  const boost::function<void(const TissueLoad::ConstPtr&)> on_load = [&got](const TissueLoad::ConstPtr& m) {
    got.push_back(*m);
  };
  ros::Subscriber sub = nh.subscribe<TissueLoad>("/simulator/tissue_load", 10, on_load);
  // The flat plan fills the cells from empty under the body: wait for the occiput, the sacrum
  // and the heels to lift off the bed base, then for two more snapshots.
  auto lowest_margin = [](const TissueLoad& m) {
    double lowest = 1.0;
    for (const char* name : {"occiput", "sacrum", "right_heel", "left_heel"}) {
      const auto it = std::find(m.region.begin(), m.region.end(), name);
      lowest = std::min(lowest, it == m.region.end() ? 0.0 : m.margin_m[it - m.region.begin()]);
    }
    return lowest;
  };
  std::size_t lifted = 0;
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(40.0);
  while (ros::ok() && ros::WallTime::now() < deadline && (lifted == 0 || got.size() < lifted + 2)) {
    ros::spinOnce();
    if (lifted == 0 && !got.empty() && lowest_margin(got.back()) > 0.05) lifted = got.size();
    ros::WallDuration(0.02).sleep();
  }
  ASSERT_GT(lifted, 0u) << "no tissue load with every bony prominence above the base (" << got.size() << " messages)";
  ASSERT_GE(got.size(), lifted + 2) << "the topic stopped";
  const TissueLoad& m = got.back();
  const std::size_t n = m.region.size();
  ASSERT_EQ(n, 9u);
  for (const std::vector<double>* a :
       {&m.peak_pressure_pa, &m.peak_pressure_mmhg, &m.mean_pressure_pa, &m.mean_pressure_mmhg, &m.contact_area_m2,
        &m.force_n, &m.margin_m, &m.min_margin_m, &m.max_peak_pressure_mmhg, &m.time_above_threshold_s,
        &m.share_above_threshold, &m.dose})
    EXPECT_EQ(a->size(), n);
  // Published at ~tissue_load_rate_hz (1 Hz), time accumulating.
  const double interval = (m.header.stamp - got[got.size() - 2].header.stamp).toSec();
  EXPECT_NEAR(interval, 1.0, 0.1);
  EXPECT_NEAR(m.observed_s - got[got.size() - 2].observed_s, interval, 1e-6);
  EXPECT_NEAR(m.threshold_pa, 32.0 * 133.322, 1.0);
  // The whole body's contact area: more than all the regions' together, less than the bed.
  double regions_m2 = 0.0;
  for (double a : m.contact_area_m2) regions_m2 += a;
  EXPECT_GT(m.body_contact_area_m2, regions_m2);
  EXPECT_LT(m.body_contact_area_m2, 2.0 * 0.9);
  auto at = [&m](const std::string& name) {
    const auto it = std::find(m.region.begin(), m.region.end(), name);
    return static_cast<std::size_t>(it - m.region.begin());
  };
  for (const char* name : {"occiput", "sacrum", "right_heel", "left_heel"}) {
    const std::size_t i = at(name);
    ASSERT_LT(i, n) << name << " missing";
    // Loaded, with peaks a flat bed gives (the references are 36-44, 46-59, 43-63 mmHg).
    EXPECT_GT(m.peak_pressure_mmhg[i], 15.0) << name;
    EXPECT_LT(m.peak_pressure_mmhg[i], 90.0) << name;
    EXPECT_GT(m.contact_area_m2[i], 0.0) << name;
    EXPECT_LE(m.mean_pressure_pa[i], m.peak_pressure_pa[i]) << name;
    EXPECT_NEAR(m.mean_pressure_pa[i] * m.contact_area_m2[i], m.force_n[i], 1e-6 * m.force_n[i] + 1e-9) << name;
    // Over the inflated cells: above the base, not above the highest cell.
    EXPECT_GT(m.margin_m[i], 0.03) << name;
    EXPECT_LT(m.margin_m[i], 0.16) << name;
    EXPECT_GE(m.share_above_threshold[i], 0.0) << name;
    EXPECT_LE(m.share_above_threshold[i], 1.0) << name;
    // Seconds on a flat bed use a tiny share of hours of tolerance.
    EXPECT_GE(m.dose[i], 0.0) << name;
    EXPECT_LT(m.dose[i], 0.01) << name;
  }
  std::printf("tissue load after %.1f s: sacrum %.1f mmHg over %.0f cm^2, margin %.1f mm; heels %.1f mmHg\n",
              m.observed_s, m.peak_pressure_mmhg[at("sacrum")], 1e4 * m.contact_area_m2[at("sacrum")],
              1e3 * m.margin_m[at("sacrum")], m.peak_pressure_mmhg[at("left_heel")]);
}

TEST(TissueLoadTopic, TheBodyLiesOnTheTruthWhenOneIsGiven) {
  ros::NodeHandle nh, pnh("~");
  int cells = 0;
  ASSERT_TRUE(pnh.getParam("cells", cells));
  TissueLoad last;
  AirbagState sacrum_cell;
  ros::Subscriber sub =
      nh.subscribe<TissueLoad>("/simulator/tissue_load", 10, [&last](const TissueLoad::ConstPtr& m) { last = *m; });
  ros::Subscriber state_sub = nh.subscribe<AirbagState>(
      "/airbag_8_1/state", 10, [&sacrum_cell](const AirbagState::ConstPtr& m) { sacrum_cell = *m; });
  ros::Publisher truth_pub = nh.advertise<RigTruth>("/test_truth", 10);
  auto sacrumMargin = [&last]() {
    const auto it = std::find(last.region.begin(), last.region.end(), "sacrum");
    return it == last.region.end() ? std::nan("") : last.margin_m[it - last.region.begin()];
  };
  // Until a truth arrives the body rests on the reported heights: the flat plan lifts it.
  ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(40.0);
  while (ros::ok() && ros::WallTime::now() < deadline && !(sacrumMargin() > 0.05)) {
    ros::spinOnce();
    ros::WallDuration(0.02).sleep();
  }
  ASSERT_GT(sacrumMargin(), 0.05) << "the flat plan never lifted the sacrum";
  // Now the truth puts every plate at the bed base; the cells go on reporting the flat bed.
  RigTruth truth;
  truth.height_m.assign(cells, 0.0);
  double margin = sacrumMargin();
  deadline = ros::WallTime::now() + ros::WallDuration(8.0);
  while (ros::ok() && ros::WallTime::now() < deadline && !(margin < 0.02)) {
    truth.header.stamp = ros::Time::now();
    truth_pub.publish(truth);
    ros::spinOnce();
    margin = sacrumMargin();
    ros::WallDuration(0.02).sleep();
  }
  EXPECT_LT(margin, 0.02) << "the body did not follow the true plate heights";
  EXPECT_GT(sacrum_cell.height_m, 0.05) << "the cell under the sacrum should still report the flat bed";
  std::printf("truth at the base: sacrum margin %.1f mm while its cell reports %.1f mm\n", 1e3 * margin,
              1e3 * sacrum_cell.height_m);
}

}  // namespace test
}  // namespace nursing_bed
