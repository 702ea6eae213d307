// Runs recorded as ROS bags: every topic carrying nursing_bed/AirbagState becomes one run of the
// gap diagnosis, in the same structure as a run CSV (nursing_bed/core/gap/run_data.h).
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/gap/run_data.h"

namespace nursing_bed {

/**
 * Reads every nursing_bed/AirbagState topic of a bag as one run, sorted by topic:
 *  - t_s: header.stamp relative to the topic's first message (the bag's record time when the
 *    topic's first message is unstamped, i.e. stamp 0);
 *  - mdot_in_kg_s <- inflow_kg_s, p_gauge_pa <- gauge_pressure_pa, h_m <- height_m,
 *    t_gas_k <- gas_temperature_k, load_n_series <- external_load_n (load_n = its first value),
 *    valve_cmd <- -vent_valve_cmd while the vent was open, else inlet_valve_cmd (the inlet's gas
 *    is metered; a replay needs the unmetered vent's opening);
 *  - name = bag file stem + topic (e.g. "rig1/bed/cell_0/state"), source = the bag path,
 *    meta: nursing_bed_run, bag, topic.
 * Throws std::runtime_error naming the bag (and topic) when the bag cannot be opened, has no
 * AirbagState topic, a topic has fewer than 2 messages, or time does not strictly increase
 * (naming the message index).
 */
std::vector<RunData> readRunsFromBag(const std::string& path);

}  // namespace nursing_bed
