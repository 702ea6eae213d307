// Recorded runs (one experiment on one airbag) and datasets (a directory of runs), as the gap
// diagnosis reads them. Format: doc/formats/run_data.md.
// ROS bags are read by the ROS wrappers (nursing_bed/ros/bag_runs.h) into the same structure.
#pragma once

#include <limits>
#include <map>
#include <string>
#include <vector>

namespace nursing_bed {

/// One run. Signals in SI units, one entry per sample; NaN where a sample was not measured.
// size: a plain record of one run: one field per CSV column and known metadata key
struct RunData {
  std::string name;                         ///< file name ("a.csv"), or bag stem + topic
  std::string source;                       ///< file it was read from (empty when built in memory)
  std::map<std::string, std::string> meta;  ///< every metadata key as written (known or not)
  std::string airbag;                       ///< parameter set name or file; empty: package default
  /// Constant external load on the plate, plate weight included [N]; NaN when the run only has
  /// a load_n column.
  double load_n = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> t_s;           ///< time [s], strictly increasing
  std::vector<double> mdot_in_kg_s;  ///< measured inlet mass flow, + into the bag [kg/s]
  std::vector<double> p_gauge_pa;    ///< measured gauge pressure [Pa]
  std::vector<double> h_m;           ///< measured plate height [m]
  // Optional columns: empty when absent.
  std::vector<double> load_n_series;      ///< time-varying load [N]
  std::vector<double> valve_cmd;          ///< -1 vent ... +1 inflate
  std::vector<double> p_supply_gauge_pa;  ///< supply pressure, gauge [Pa]
  std::vector<double> t_gas_k;            ///< gas temperature [K]
  /// The meter's raw flow beside a corrected mdot_in_kg_s (a recorder's offset correction
  /// undone) [kg/s]
  std::vector<double> mdot_uncorrected_kg_s;
  std::vector<double> p_setpoint_gauge_pa;  ///< the pressure controller's target, gauge [Pa]
  std::string role;                         ///< "fit", "withheld" or "" (not assigned)
  /// true: mdot_in_kg_s[i] is the mean flow over the interval that ends at sample i, as a
  /// bed's AirbagState reports it (metadata "mdot_sampling: interval_mean"); a valve that
  /// opens for a few ms between samples then still moves the right gas in the right interval.
  /// false (default, "mdot_sampling: instant"): the meter's reading at t_s[i], linear between.
  bool flow_interval_means = false;
  /// Samples whose flow the diagnosis set to 0 because the inlet was closed there
  /// (zeroClosedInletFlow); empty: none. Not read or written with the CSV.
  std::vector<bool> inlet_closed;

  std::size_t size() const { return t_s.size(); }
  /// Load at sample i: the column where present and finite, else load_n.
  double loadAt(std::size_t i) const;
};

/// Format version this code reads and writes.
constexpr int kRunCsvVersion = 1;
/// Metadata key saying how mdot_in_kg_s was sampled: "instant" or "interval_mean".
constexpr const char* kFlowSamplingKey = "mdot_sampling";

/**
 * Reads a run CSV (version 1). Metadata lines "# key: value" before the header; the version
 * key nursing_bed_run must be 1; load_n is required unless a load_n column exists. Required
 * columns t_s, mdot_in_kg_s, p_gauge_pa, h_m, in any order; optional load_n, valve_cmd,
 * p_supply_gauge_pa, t_gas_k, mdot_uncorrected_kg_s, p_setpoint_gauge_pa; other columns are
 * ignored. An empty field (or "nan") is NaN;
 * t_s must be present on every row. Throws std::runtime_error naming the file, line and
 * column for: unreadable file, missing or unsupported version, missing or non-numeric load_n,
 * missing header or required column, duplicate column, a row with the wrong number of fields,
 * a non-numeric or infinite field, time not strictly increasing, fewer than 2 rows. Nothing is
 * returned half-read. `name` is the file name, `source` the path.
 */
RunData readRunCsv(const std::string& path);

/// Writes a run in the same format (version 1; metadata: version, load_n if finite, airbag if
/// set, then the other meta keys; required columns, then the optional ones that are present).
/// Numbers are written in their shortest exact form (read back bit for bit); NaN as an empty
/// field. Throws std::runtime_error when the file cannot be written or the columns' sizes
/// disagree.
void writeRunCsv(const std::string& path, const RunData& run);

/**
 * Reads a dataset directory: every *.csv (sorted by name) plus `extra_runs` (e.g. runs the
 * caller read from bags in the directory), and the optional dataset.yaml:
 *   airbag: airbag_tpu_double_100.yaml   # parameter file in config/, or a path
 *   runs: {a.csv: fit, b.csv: withheld}  # role per run (a run name, or a bag's file name
 *                                        # for all of its topics)
 * dataset.yaml's airbag is given to runs that name none. Throws std::runtime_error for: a
 * directory that cannot be read, no runs found, duplicate run names, a dataset.yaml that
 * cannot be parsed or has an unknown key, a role for a run that does not exist, a role other
 * than fit/withheld. Runs come back sorted by name.
 */
std::vector<RunData> readDataset(const std::string& dir, std::vector<RunData> extra_runs = {});

/**
 * The parameter file an airbag name refers to: empty -> config/airbag_tpu_double_100.yaml;
 * an existing file (as given, or relative to `dataset_dir`) -> that file; else
 * config/<name>, config/<name>.yaml, config/airbag_<name>.yaml in the package folder
 * (findPackageDir, io/package_path.h).
 * Throws std::runtime_error listing the places tried.
 */
std::string resolveAirbagParamsFile(const std::string& airbag, const std::string& dataset_dir = "");

}  // namespace nursing_bed
