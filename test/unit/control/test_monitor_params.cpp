// The consistency monitor's keys among the observer's (observer/monitor_*): the shipped
// config/observer.yaml loads them, and a bad value is refused naming its key.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/observer/observer_params_io.h"

namespace nb = nursing_bed;

namespace {

/// The shipped observer YAML's values under "observer/", as the launch file sets them.
nb::FlatParams shippedObserverValues() {
  nb::FlatParams values;
  for (const auto& [key, value] : nb::flattenYamlFile(std::string(NURSING_BED_SOURCE_DIR) + "/config/observer.yaml"))
    values["observer/" + key] = value;
  return values;
}

}  // namespace

TEST(MonitorParams, TheShippedObserverYamlSetsEveryMonitorKeyToItsDefault) {
  nb::CellObserverParams observer;
  nb::GasVerifierParams gas;
  nb::ConsistencyMonitorParams monitor;
  monitor.max_load_n = 1.0;  // overwritten by the file
  nb::applyObserverParams(shippedObserverValues(), "observer.yaml", &observer, &gas, &monitor, "observer/");
  const nb::ConsistencyMonitorParams defaults;
  for (const auto& field : nb::consistencyMonitorParamFields())
    EXPECT_DOUBLE_EQ(field.get(monitor), field.get(defaults)) << field.key;
  EXPECT_TRUE(monitor.validate().ok());
}

TEST(MonitorParams, AnUnknownOrBadMonitorKeyIsRefusedByName) {
  nb::CellObserverParams observer;
  nb::GasVerifierParams gas;
  nb::ConsistencyMonitorParams monitor;
  nb::FlatParams values = shippedObserverValues();
  values["observer/monitor_resonse_sds"] = values["observer/monitor_response_sds"];
  try {
    nb::applyObserverParams(values, "test", &observer, &gas, &monitor, "observer/");
    FAIL() << "an unknown key was taken";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("monitor_resonse_sds"), std::string::npos) << e.what();
  }
  nb::ConsistencyMonitorParams bad;
  bad.response_sds = -1.0;
  EXPECT_NE(bad.validate().message().find("response_sds"), std::string::npos);
}
