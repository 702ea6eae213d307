// Reading and writing CellParams: one table of every parameter (key, unit, meaning), used by the
// YAML loader here and by the ROS wrappers' loadParams(), so both accept exactly the same keys.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/io/param_table.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

using CellParamField = ParamField<CellParams>;

/// Every scalar parameter of a cell, in documentation order.
const ParamTable<CellParams>& cellParamFields();

/// The package's default cell: config/airbag_tpu_double_100.yaml in the package folder
/// (findPackageFile). The one place that names it; the tools, benches and the gap default to it.
std::string defaultCellParamsFile();

/**
 * Reads a YAML file of cell parameters (layout: config/airbag_tpu_double_100.yaml) on top of
 * `defaults`. Keys that are absent keep their default. Throws std::runtime_error naming the
 * file and the key for: unreadable file or YAML syntax error, an unknown key (a typo would
 * otherwise be silently ignored), a non-numeric or non-integer value, or a parameter set that
 * fails CellParams::validate().
 */
CellParams loadCellParamsYaml(const std::string& path, const CellParams& defaults = CellParams{});

/// Same, from YAML text (`source` names it in errors).
CellParams parseCellParamsYaml(const std::string& yaml_text, const std::string& source,
                               const CellParams& defaults = CellParams{});

/**
 * The two text keys that select the structure (CellParams::structure_type, structure_table_file),
 * taken out of `flat` before the numeric table is applied:
 *   structure/type: pillow | table | fold_table | bellows   which CellStructure the cell runs on
 *                                     (default pillow; bellows: the numbers under bellows/)
 *   structure/table_file: <path>      FE structure table (fe_airbag --mode table) or fold table
 *                                     (scripts/fold_table.py); a relative
 *                                     path is taken from `base_dir` (the YAML's folder)
 * The YAML loaders here call it; `prefix` serves nested tables (e.g. "cell/").
 */
void applyStructureSelection(FlatParams* flat, const std::string& base_dir, CellParams* params,
                             const std::string& prefix = "");

/// The parameters as YAML (every key, one comment each).
std::string cellParamsToYaml(const CellParams& params);

}  // namespace nursing_bed
