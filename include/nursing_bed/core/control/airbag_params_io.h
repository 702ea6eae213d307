// The parameter table of a whole airbag (cell physics, controller, safety, sensors), shared by
// the YAML loader and the airbag node's loadParams().
#pragma once

#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/control/gas_verifier.h"
#include "nursing_bed/core/io/param_table.h"

namespace nursing_bed {

/// Keys: "cell/<group>/<name>" (cellParamFields), "controller/...", "safety/...",
/// "sensors/...".
const ParamTable<AirbagCellParams>& airbagParamFields();

/// Applies flattened values (from YAML or the parameter server) on top of `base` and
/// validates; throws std::runtime_error naming `source` and the offending key. The structure
/// selection keys (cell/structure/type, cell/structure/table_file; cell_params_io.h) are read
/// too, a relative table path from the package's config/ folder.
AirbagCellParams airbagParamsFrom(const FlatParams& values, const std::string& source,
                                  const AirbagCellParams& base = AirbagCellParams{});

/// The gas check's keys (resume_vent_s, reanchor_below_m). They are set under "observer/"
/// with the observer's own keys (observerParamFields), as the re-anchor test they drive is.
const ParamTable<GasVerifierParams>& gasVerifierParamFields();

/// Applies the values under `prefix` (e.g. "observer/") to the observer's tuning, to the gas
/// check's (its keys routed to `gas_check`) and to the consistency monitor's (monitor_ keys,
/// to `monitor`); throws std::runtime_error naming `source` and the key for an unknown key or a
/// bad value.
void applyObserverParams(const FlatParams& values, const std::string& source, CellObserverParams* observer,
                         GasVerifierParams* gas_check, ConsistencyMonitorParams* monitor, const std::string& prefix);

}  // namespace nursing_bed
