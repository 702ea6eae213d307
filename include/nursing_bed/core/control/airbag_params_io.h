// The parameter table of a whole airbag (cell physics, controller, safety, sensors), shared by
// the YAML loader and the airbag node's loadParams().
#pragma once

#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
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

}  // namespace nursing_bed
