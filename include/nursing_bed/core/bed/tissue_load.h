// Tissue-load metrics (ROS-free): what the bed does to the skin over each bony prominence.
// TissueRegion names a part of the body's contact map (BodyModel::contactMap);
// measureRegions() takes one snapshot per region (peak and mean interface pressure, contact
// area, force, bottoming-out margin); TissueLoadMeter accumulates snapshots over time (time
// above a threshold, a pressure-time dose against a tolerance curve). Reference: doc/tissue_load.md.
//
// Units: SI throughout (Pa, m, m^2, N, s); the dose is dimensionless (1 = the tolerance curve's
// limit reached).
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/io/param_table.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// Tolerance of tissue to sustained interface pressure: the time a pressure may be borne,
///   t_allow(p) = reference_time_s * (reference_pressure_pa / p)^exponent  for p > floor_pressure_pa,
/// unlimited at or below the floor. Defaults: an inverse power law through ~500 mmHg for 1 h
/// and ~70 mmHg for 12 h read off Reswick & Rogers' curve (Bedsore Biomechanics, 1976, pp. 301-310).
struct ToleranceCurve {
  double reference_pressure_pa = 66661.0;  ///< a point of the curve: this pressure [Pa] (500 mmHg) ...
  double reference_time_s = 3600.0;        ///< ... is borne this long [s]
  double exponent = 1.263;                 ///< how fast the allowed time falls with pressure [-]
  double floor_pressure_pa = 4266.3;       ///< at or below this no dose accrues [Pa] (32 mmHg)

  /// The allowed time at `pressure_pa` [s]; +infinity at or below the floor.
  double allowedTimeS(double pressure_pa) const;
};

/// What the metrics count as too much.
struct TissueLoadParams {
  /// A region is "above the threshold" while its peak exceeds this [Pa] (32 mmHg, the
  /// capillary closing pressure convention).
  double threshold_pa = 4266.3;
  ToleranceCurve tolerance;

  /// Success when valid, else an error naming every bad field.
  Status validate() const;
};

/// The keys of TissueLoadParams for YAML and the parameter server: threshold_pa,
/// tolerance/reference_pressure_pa, tolerance/reference_time_s, tolerance/exponent,
/// tolerance/floor_pressure_pa.
const ParamTable<TissueLoadParams>& tissueLoadParamFields();

/// A body region: the contact points of some segments, within a window along the body and
/// across each segment (fractions of the segment footprint's half width, signed + to the left).
struct TissueRegion {
  std::string name;                ///< e.g. "sacrum", "right_heel"
  std::vector<int> segments;       ///< indices in segmentTable()
  double from_vertex_min_h = 0.0;  ///< window along the body, from the vertex, of stature H
  double from_vertex_max_h = 1.0;  ///< ... to this, of H
  double lateral_min = -1.0;       ///< window across the segment, of its half width [-1, 1]
  double lateral_max = 1.0;        ///< ... to this
};

/// The default regions, over the bony prominences of a supine or turned patient: occiput,
/// scapulae, sacrum, right/left trochanter, right/left elbow, right/left heel.
const std::vector<TissueRegion>& defaultTissueRegions();

/// One region at one instant.
struct RegionLoad {
  double peak_pressure_pa = 0.0;  ///< highest point pressure [Pa]
  double mean_pressure_pa = 0.0;  ///< force / contact area (0 without contact) [Pa]
  double contact_area_m2 = 0.0;   ///< area of the points bearing pressure [m^2]
  double force_n = 0.0;           ///< the region's load [N]
  /// Lowest skin height above the bed base over the region [m]; 0: bottomed out; NaN when the
  /// region has no point on the bed.
  double margin_m = 0.0;
};

/// The snapshot of every region (same order as `regions`) from a contact map; `height_m` is
/// the patient's stature, which scales the regions' windows along the body.
std::vector<RegionLoad> measureRegions(const std::vector<ContactPoint>& points,
                                       const std::vector<TissueRegion>& regions, double height_m);

/// One region's metrics over time.
struct RegionDose {
  RegionLoad now;                     ///< the last snapshot
  double time_above_s = 0.0;          ///< time with the peak above the threshold [s]
  double dose = 0.0;                  ///< sum of dt / t_allow(peak) (1: the tolerance curve's limit)
  double max_peak_pressure_pa = 0.0;  ///< highest peak seen [Pa]
  /// Sum of peak x dt [Pa s]; over the meter's observedS(), the time-mean peak: unlike
  /// time_above_s and dose it does not jump where the peak crosses the threshold.
  double peak_integral_pa_s = 0.0;
  double min_margin_m = 0.0;  ///< lowest margin seen [m] (NaN until a finite margin is seen)
};

/// Accumulates region snapshots: sample(loads, dt) counts `loads` for the dt seconds before it
/// (a rectangle rule), so sampling at a modest rate (1-2 Hz) integrates loads that change over
/// minutes well.
class TissueLoadMeter {
 public:
  /// Throws std::invalid_argument naming the problem when `params` are invalid or `regions` is
  /// empty.
  TissueLoadMeter(const TissueLoadParams& params, std::vector<TissueRegion> regions);

  /// Adds `dt_s` seconds of `loads` (one per region, in the regions' order); throws
  /// std::invalid_argument (state untouched) when the size does not match or dt_s is negative
  /// or not finite.
  void sample(const std::vector<RegionLoad>& loads, double dt_s);
  /// Clears the accumulated time, dose and extremes.
  void reset();

  const std::vector<TissueRegion>& regions() const { return regions_; }
  const std::vector<RegionDose>& doses() const { return doses_; }
  const TissueLoadParams& params() const { return params_; }
  /// Time sampled since the start or reset() [s].
  double observedS() const { return observed_s_; }

 private:
  TissueLoadParams params_;
  std::vector<TissueRegion> regions_;
  std::vector<RegionDose> doses_;
  double observed_s_ = 0.0;
};

}  // namespace nursing_bed
