// Adaptive support (ROS-free): cell heights set from what the cells sense, each cell's gauge
// pressure and the observer's estimate of its load, without a pressure mat or the simulator's
// truth. After a survey on a level bed it reads where the body lies from the load map (head at
// the head end, trunk rows loaded in the midline, legs loaded on two columns, heels at the foot
// end), then floats the heels (the heel cells lowered, the calves' raised), raises the thighs to
// take load off the pelvis, keeps the cells under the trunk and pelvis above a bottoming-out
// height, levels the load between neighbouring cells under the body (filling its hollows), and
// relieves the head, the upper trunk and the pelvis in turn before a time budget or a dose on the
// tolerance curve runs out, the relieved load going to neighbour rows other than the pelvis.
// Its targets move at a bounded rate; the bed supervisor's rate limits (height and roll slope)
// apply on top. Reference: doc/bed_manager.md, "adaptive".
//
// Units: SI throughout (m, N, Pa, s); the dose is dimensionless (1: the curve's limit).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/core/bed/bed_grid.h"
#include "nursing_bed/core/bed/tissue_load.h"
#include "nursing_bed/core/io/param_table.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// What the cells sense, by cell id (NaN: unknown).
struct SensedCells {
  std::vector<double> gauge_pressure_pa;  ///< each cell's gauge pressure [Pa]
  std::vector<double> load_n;             ///< the observer's estimate of the load on each cell [N]
};

/// Parameters of the adaptive plan (config/bed_manager.yaml, `plans/adaptive/...`).
struct AdaptiveSupportParams {
  double survey_s = 20.0;        ///< the bed stays level this long before the load map is read [s]
  double contact_load_n = 1.0;   ///< a cell sensing more than this above an empty cell is under the body [N]
  double head_length_m = 0.25;   ///< loaded rows this close to the head end are the head [m]
  double heel_zone_m = 0.15;     ///< loaded leg rows this close to the foot end are the heels [m]
  double pelvis_length_m = 0.2;  ///< the last trunk rows over this length are the pelvis [m]
  double heel_height_m = 0.03;   ///< floated heel cells' height [m]
  double calf_length_m = 0.2;    ///< the leg rows over this length before the heels are the calves [m]
  /// The calves' cells go this much higher (at most to max_height_m), so the hanging feet
  /// clear the floated cells [m].
  double calf_lift_m = 0.05;
  /// The leg rows over this length after the pelvis, up to the calves, are the thighs (and
  /// knees) [m].
  double thigh_length_m = 0.8;
  /// The thighs' cells go this much higher (at most to max_height_m): they take part of the
  /// pelvis's load off the sacrum and the trochanters [m].
  double thigh_lift_m = 0.05;
  /// Lowest height of a cell under the trunk or pelvis: its bottoming-out margin [m].
  double margin_height_m = 0.07;
  double level_gain_m_n_s = 6e-5;  ///< levelling: height change per N of excess load per s [m/(N s)]
  double level_range_m = 0.03;     ///< levelling moves a cell at most this far from the nominal height [m]
  /// Levelling raises a cell that does not sense the body at most this far above the nominal
  /// height: it reaches for the body, but raising it further moves no load, and a lightly
  /// loaded bag near its top is where pressure tells its height worst [m].
  double reach_m = 0.015;
  double relief_budget_s = 1800.0;  ///< a region is relieved after this long under load ... [s]
  double dose_limit = 0.25;         ///< ... or sooner, when its sensed dose reaches this [-]
  double relief_s = 120.0;          ///< a relief lasts this long [s]
  double relief_drop_m = 0.02;      ///< relieved cells go this much lower, their neighbour rows higher [m]
  double max_rate_m_s = 0.002;      ///< fastest change of a target [m/s]
  ToleranceCurve tolerance;         ///< the sensed dose's tolerance curve (tissue_load.h defaults)

  /// Success when valid within the plan heights [min_height_m, nominal_height_m,
  /// max_height_m], else an error naming every bad field, `key_prefix` before each key.
  Status validate(double min_height_m, double nominal_height_m, double max_height_m,
                  const std::string& key_prefix = "") const;
};

/// Keys of AdaptiveSupportParams ("survey_s", ..., "tolerance/exponent").
const ParamTable<AdaptiveSupportParams>& adaptiveSupportFields();

/// Where the body lies, read off a load map. Rows are sorted; cells are ids.
struct BodyLayout {
  int first_row = 0, last_row = 0;  ///< loaded rows, head end to foot end
  int midline_col = 0;              ///< the load-weighted middle column
  double empty_load_n = 0.0;        ///< what an empty cell senses (plate, offset); loads are net of it [N]
  std::vector<int> head_rows, trunk_rows, pelvis_rows, heel_rows;
  /// Cells floated for the heels: from the first heel row to the bed's foot end, the heels'
  /// loaded columns and one either side.
  std::vector<std::uint32_t> heel_cells;
  std::vector<std::uint32_t> calf_cells;   ///< the calf rows before the heel rows, the heels' columns
  std::vector<std::uint32_t> thigh_cells;  ///< the thigh rows after the pelvis, loaded columns and one either side
  std::vector<std::uint32_t> trunk_cells;  ///< trunk rows, loaded columns and one either side
  /// Cells levelled against their neighbours: every cell of the loaded rows but the heels' and
  /// the calves'.
  std::vector<std::uint32_t> level_cells;
};

/// What an empty cell senses (the plate's weight, an estimate's offset): the 10th percentile of
/// `loads_n` [N], at least 0. The body covers well under 90 % of a bed's cells.
double emptyCellLoad(const std::vector<double>& loads_n);

/// The layout `loads` (by cell id [N]) show, or nullopt when no body or no trunk is sensed.
/// A cell is loaded when it senses more than contact_load_n above emptyCellLoad(). Trunk rows
/// carry their row's largest load in the midline column; leg rows carry it on two columns
/// either side of it.
std::optional<BodyLayout> inferBodyLayout(const BedGrid& grid, const std::vector<double>& loads_n,
                                          const AdaptiveSupportParams& params);

/// The load per cell the plan uses: the observer's estimate, else gauge pressure x face area,
/// else 0.
std::vector<double> sensedLoads(const BedGrid& grid, const SensedCells& sensed);

/// The adaptive plan's controller: called once per plan step, in time order.
class AdaptiveSupport {
 public:
  /// `params` valid for the plan heights (checked by the caller).
  AdaptiveSupport(const AdaptiveSupportParams& params, const BedGrid& grid, double min_height_m,
                  double nominal_height_m, double max_height_m);

  /// The targets `elapsed_s` after the start from what the cells sense now; *phase says what
  /// it does ("surveying", "adapting", "relieving pelvis").
  std::vector<double> update(double elapsed_s, const SensedCells& sensed, std::string* phase);

  /// The last targets (nominal before the first update) [m].
  const std::vector<double>& targets() const { return heights_m_; }
  const std::optional<BodyLayout>& layout() const { return layout_; }
  const AdaptiveSupportParams& params() const { return params_; }

 private:
  /// A region relieved in turn: its cells, the time it has been loaded, its sensed dose.
  struct Region {
    std::string name;
    std::vector<int> rows;
    double loaded_s = 0.0, dose = 0.0;
  };
  void buildRegions();
  void level(const std::vector<double>& loads, double dt_s);
  void account(const std::vector<double>& loads, double elapsed_s, double dt_s);
  /// The heights wanted now: nominal + levelling, heels floated, relief, floors.
  std::vector<double> wanted() const;
  double regionPressurePa(const Region& region, const std::vector<double>& loads) const;

  AdaptiveSupportParams params_;
  BedGrid grid_;
  double min_height_m_, nominal_height_m_, max_height_m_;
  std::optional<BodyLayout> layout_;
  std::vector<double> offset_m_;   ///< levelling offsets from nominal, by cell id
  std::vector<double> heights_m_;  ///< targets sent, by cell id
  std::vector<Region> regions_;
  int relieving_ = -1;  ///< index in regions_ (-1: none)
  double relief_end_s_ = 0.0, last_elapsed_s_ = 0.0;
};

}  // namespace nursing_bed
