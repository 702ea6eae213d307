// Elapsed time and the time left of a diagnosis (doc/gap_diagnosis.md, "Progress"): the pipeline
// declares each stage with the steps it expects and what a step costs relative to one single
// candidate's fit; every progress line of the stage is one step done. The time left is the work
// still planned at the mean cost of the work done so far.
#pragma once

#include <mutex>
#include <string>

namespace nursing_bed {
namespace gap {

class ProgressEstimate {
 public:
  /// Plans `steps` more steps of `units` each (a single candidate's fit is 1).
  void plan(int steps, double units);
  /// Drops up to `steps` planned steps of `units` each that will not run after all.
  void unplan(int steps, double units);
  /// A step of `units` done, `elapsed_s` after the start.
  void done(double units, double elapsed_s);
  /// The time left at `elapsed_s`: the planned units left at the mean cost of a unit done since
  /// the first step began (NaN before any step is done).
  double secondsLeft(double elapsed_s) const;
  /// "41 s elapsed, about 2 min left" (or "... time left not yet known").
  std::string line(double elapsed_s) const;
  /// Marks where the fitting work begins (what comes before is not a unit of it).
  void start(double elapsed_s);

 private:
  mutable std::mutex mutex_;
  double planned_ = 0.0, done_ = 0.0;
  double started_s_ = 0.0, last_done_s_ = 0.0;
};

/// A duration in words for a progress line: "45 s", "3 min", "1.5 min".
std::string roughDuration(double seconds);

}  // namespace gap
}  // namespace nursing_bed
