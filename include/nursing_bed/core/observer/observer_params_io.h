// The observer's parameter table (keys under "observer/" on the parameter server and in YAML).
#pragma once

#include "nursing_bed/core/io/param_table.h"
#include "nursing_bed/core/observer/cell_observer.h"
#include "nursing_bed/core/observer/consistency_monitor.h"

namespace nursing_bed {

/// Keys: pressure_noise_pa, height_noise_m, ..., as in CellObserverParams (period_s excluded:
/// it is the control period).
const ParamTable<CellObserverParams>& observerParamFields();

/// The consistency monitor's keys: monitor_frozen_s, monitor_settle_s, ..., as in
/// ConsistencyMonitorParams with a "monitor_" prefix (set beside the observer's own keys).
const ParamTable<ConsistencyMonitorParams>& consistencyMonitorParamFields();

}  // namespace nursing_bed
