// The small synthetic protocol's runs, shared by the gap diagnosis tests.
#pragma once

#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/synth.h"

namespace nursing_bed {
namespace test {

/// What a rig differs in from the model, and how its runs are recorded.
struct SmallRig {
  std::map<std::string, double> airbag;  ///< rigAirbag() differences (calibration or cell keys)
  bool valve_driven = false;             ///< valve commands instead of a metered inflow
  double noise_scale = 1.0;              ///< multiplies the default sensor noise
  bool with_roles = true;                ///< keep the protocol's fit/withheld roles
};

/// The small protocol's runs, noisy (seeded), with `effects` hidden in the rig's cell.
inline std::vector<RunData> smallProtocolRuns(const std::vector<CellEffectPtr>& effects, std::uint32_t seed,
                                              const SmallRig& rig = {}) {
  const CellParams params = rigAirbag(CellParams{}, rig.airbag);
  SynthProtocol protocol = synthProtocol("small", params);
  protocol.valve_driven = rig.valve_driven;
  std::mt19937 rng(seed);
  std::vector<RunData> runs;
  for (const auto& spec : protocol.runs) {
    runs.push_back(simulateSynthRun(params, effects, protocol, spec, SensorNoise{}.scaled(rig.noise_scale), &rng));
    if (rig.with_roles) runs.back().role = spec.role;
  }
  return runs;
}

}  // namespace test
}  // namespace nursing_bed
