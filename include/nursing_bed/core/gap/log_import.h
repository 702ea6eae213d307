// Importing recorded logs of other formats (a ventilator's, a bench logger's) as a dataset of
// run CSVs: a column-mapping file says which column is what, in which unit, how derived channels
// follow from the columns, how a long log is cut into runs at cycle starts and which runs are fit
// or withheld. Mapping format: doc/formats/import_mapping.md; tool: `gap import`
// (doc/gap_import.md); run format: doc/formats/run_data.md.
#pragma once

#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/run_data.h"

namespace nursing_bed {

/// What a signal measures; a unit belongs to one quantity.
enum class Quantity { kTime, kPressure, kVolumeFlow, kMassFlow, kVolume, kLength, kForce, kTemperature, kRatio };

/// A unit a log may use: SI value = field * to_si + si_offset.
struct LogUnit {
  std::string name;  ///< as written in a mapping ("cmH2O", "kPa", "mL/s", "L/min", ...)
  Quantity quantity;
  double to_si;
  double si_offset = 0.0;  ///< only temperatures (degC)
};

/// The unit called `name`, or nullopt (names are case-sensitive: "mL" is not "ML").
std::optional<LogUnit> findLogUnit(const std::string& name);
/// Every known unit name, comma-separated (for error messages and docs).
std::string logUnitNames();

/// Choosing a signal's unit among candidates: the candidate whose value, at the samples just
/// before each cycle start (the end of expiration on a ventilator), has a median ratio to the
/// reference signal's median within [ratio_min, ratio_max]. Exactly one candidate must fit.
struct UnitDetection {
  std::string reference;         ///< a signal with one unit, of the same quantity
  std::string at = "cycle_end";  ///< "cycle_end" (needs cycles) or "all" (whole log)
  double window_s = 0.3;         ///< cycle_end: samples this long before each cycle start
  double ratio_min = 0.7;
  double ratio_max = 1.4;
};

/// A venturi (or orifice pair) turning differential pressures into a mass flow:
/// mdot = cd * sign(dp) * sqrt(2 |dp| rho) * A1 A2 / sqrt(A1^2 - A2^2), rho the gas density of
/// the mapping; with a reverse venturi the net flow is mdot(forward) - mdot(reverse).
struct VenturiSpec {
  std::string forward_dp;  ///< pressure signal of the venturi whose flow counts positive
  std::string reverse_dp;  ///< optional: pressure signal of the one whose flow counts negative
  double discharge_coefficient = 1.0;
  double inlet_diameter_m = 0.0;   ///< D1
  double throat_diameter_m = 0.0;  ///< D2 < D1
};

/// One signal: a log column with its unit, or a derived channel (venturi).
/// Column value in SI: sign * (scale * field + offset) in the unit, then the unit's conversion.
struct SignalSpec {
  std::string name;
  std::string column;              ///< source column (empty: derived)
  std::vector<std::string> units;  ///< one unit, or the candidates `detect` chooses from
  std::optional<UnitDetection> detect;
  double scale = 1.0;
  double offset = 0.0;  ///< in the signal's unit, added after the scale
  double sign = 1.0;
  /// A volumetric flow a differential-pressure meter computed assuming this gas density
  /// [kg/m^3]: its mass flow is Q * sqrt(meter_density * density) instead of Q * density.
  double meter_density_kg_m3 = std::numeric_limits<double>::quiet_NaN();
  std::optional<VenturiSpec> venturi;
  int line = 0;  ///< line in the mapping file (1-based), for errors
};

/// Leaving out the cycles unlike the others (an obstruction, a disconnection): each cycle's
/// metered volume in and out (the flow's integral while the cycle signal is above, and while it
/// is below, the middle of its range) must lie within `factor` of that phase's median over the
/// log's whole cycles.
struct TypicalCycles {
  std::string flow;     ///< a flow signal (volume or mass flow)
  double factor = 0.0;  ///< > 1: kept when median / factor <= volume <= median * factor
};

/// Cutting a log into runs of whole cycles at the rising edges of a signal (a setpoint).
struct CycleSpec {
  std::string signal;
  int cycles_per_run = 1;                     ///< 0: one run of all whole cycles (of each stretch of kept cycles)
  std::optional<TypicalCycles> keep_typical;  ///< absent: every whole cycle is kept
};

/// Which imported runs the diagnosis fits and which it withholds.
struct RoleSpec {
  std::vector<std::string> pattern;           ///< cycled over each log's runs ("fit", "withheld")
  std::map<std::string, std::string> by_run;  ///< run name -> role (runs not named: no role)
};

/// A parsed mapping file (doc/formats/import_mapping.md).
struct ImportMapping {
  std::string source;         ///< the mapping file
  std::string comment = "#";  ///< a line starting with it (after blanks) is a comment
  char delimiter = 0;         ///< 0: runs of blanks; else ',', ';' or '\t'
  std::string time_column;
  double time_to_s = 1.0;  ///< the time column's unit (s or ms)
  std::vector<SignalSpec> signals;
  std::map<std::string, std::string> outputs;  ///< run column -> signal
  double density_kg_m3 = 1.204;                ///< gas density turning volumetric flows into mass flows
  std::optional<CycleSpec> cycles;
  RoleSpec roles;
  std::string run_prefix;                                                   ///< prepended to every run name
  std::map<std::string, std::string> metadata;                              ///< written into every run
  std::map<std::string, std::map<std::string, std::string>> file_metadata;  ///< per log file name
};

/// The run columns a mapping may fill (run CSV columns, doc/formats/run_data.md), with the
/// quantity each takes.
const std::map<std::string, Quantity>& importRunColumns();

/// Reads a mapping file. Throws std::runtime_error naming the file, the line and the key for:
/// unreadable file or YAML syntax, a missing or unknown key, a wrong type, an unknown unit, a
/// unit of the wrong quantity, a signal referring to one that does not exist, a run column not
/// in importRunColumns(), an output of the wrong quantity, a missing p_gauge_pa output.
ImportMapping loadImportMapping(const std::string& path);
/// Same from YAML text; `source` names it in errors.
ImportMapping parseImportMapping(const std::string& yaml_text, const std::string& source);

/// What the import made of one log: its runs and what it decided (units chosen, cycles found).
struct ImportedLog {
  std::string path;
  std::vector<RunData> runs;          ///< with names, roles and metadata set
  std::vector<std::string> notes;     ///< one line per decision ("pressure: unit kPa (...)")
  std::size_t cycles = 0;             ///< whole cycles found (0: not cut)
  std::vector<std::size_t> left_out;  ///< cycles left out as unlike the others (0-based)
};

/**
 * Imports one log with a mapping, in memory. Throws std::runtime_error naming the file, the line
 * and the column for: unreadable file, no header, a mapped column missing from the header, a row
 * of the wrong width, a non-numeric or infinite field, a missing time, time not strictly
 * increasing, a unit no candidate (or more than one) fits, fewer than two cycle starts, a
 * `keep_typical` phase whose median volume is not positive, no cycle kept.
 */
ImportedLog importLog(const ImportMapping& mapping, const std::string& log_path);

/**
 * Imports every log, then writes the dataset directory `out_dir`: one run CSV per run and a
 * dataset.yaml with the roles. Everything is read and checked before anything is written; the
 * files go to a temporary directory beside `out_dir`, renamed at the end, so an error leaves no
 * output. `out_dir` must not exist or be empty. Throws std::runtime_error (see importLog; also
 * two runs of one name, an output directory that exists and is not empty, a write failure).
 */
std::vector<ImportedLog> importLogsToDataset(const ImportMapping& mapping, const std::vector<std::string>& log_paths,
                                             const std::string& out_dir);

}  // namespace nursing_bed
