// Channel distortions: candidates of the gap diagnosis that change what a channel reports (or
// what the model is driven with), not the physics. One family per channel: gain, offset, linear
// drift, time shift and first-order lag. Output channels (pressure, height) are distorted readings
// of the model's true ones; measured inputs (inflow, supply pressure, the recorded load) are
// distorted readings the replay corrects before it drives the model; the valve command is
// distorted on its way to the valve. Two catalogue effects are members too: pressure_sensor_lag
// (the pressure's lag) and inflow_bias (the inflow's gain and offset). doc/gap_effects.md.
#pragma once

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/run_data.h"

namespace nursing_bed {

/// The distortion candidates (EffectSpec::channel and ::kind set), one parameter each, off at 0.
/// Their names are "<channel>_<kind>" (pressure_gain, height_shift, ...).
const std::vector<EffectSpec>& distortionCatalog();

/// Every channel distortion of the catalogues (the two physical-catalogue members included), by
/// channel and kind: the effect name and the parameter that carries it. Channels: pressure,
/// height, inflow, valve_cmd, supply, load. Kinds: gain, offset, drift, shift, lag.
struct DistortionMember {
  std::string channel, kind;
  std::string effect;  ///< catalogue effect
  std::string param;   ///< its parameter for this kind
};
const std::vector<DistortionMember>& distortionMembers();

/// The distortion candidates that these runs can show: pressure and load always; height when a
/// run has height readings; inflow when a run has a metered flow; valve_cmd and supply when a run
/// is driven through the model's valves (runIsValveDriven()). Members of the physical catalogue
/// (pressure_sensor_lag, inflow_bias) are not listed: they are candidates already.
std::vector<std::string> distortionCandidatesFor(const std::vector<const RunData*>& runs);

/// Parses "channel:kind=value[,kind=value...]" (e.g. "height:gain=-0.04", "inflow:shift=0.08")
/// into effects with their parameters (inflow gain and offset merge into one inflow_bias).
/// Throws std::invalid_argument naming an unknown channel or kind (with the known ones), a missing
/// "=value", a value that is not a finite number, a kind given twice, or a value outside the
/// admissible range.
std::map<std::string, std::map<std::string, double>> parseDistortion(const std::string& text);

/// Whether `effect_name` is a channel distortion (of either catalogue).
bool isDistortionEffect(const std::string& effect_name);

/// "height: gain -4.1 % ± 0.3 %" for a distortion effect and its fitted parameters (standard
/// errors by parameter name, NaN or absent: none). Empty for an effect that is not a distortion.
std::string describeDistortion(const std::string& effect_name, const std::map<std::string, double>& params,
                               const std::map<std::string, double>& std_errors = {});

// ---- the transforms on a sampled series (NaN samples stay NaN and are skipped) -----------------

/// What a channel with this distortion reports for the true series x(t):
///   gain: (1 + g) x;  offset: x + b;  drift: x + r (t - t0);  shift: x(t - d) (d > 0: late,
///   linear interpolation, the end values held beyond the ends);  lag: tau dy/dt = x - y, y(t0) =
///   x(t0), exact for x linear between samples.
/// `at_rest` (finite): the series' value before its record, for a shift: what a run that starts
/// at rest had (an inflow, a valve command: 0), the value |d| before the first sample; the
/// unrecorded stretch between them linear.
void distortSeries(const std::string& kind, double value, const std::vector<double>& t, std::vector<double>* x,
                   double at_rest = NAN);
/// The true series from a distorted one: the inverse of distortSeries() for gain, offset, drift
/// and shift (a lag's inverse would differentiate the noise: throws std::invalid_argument).
/// Exact zeros are kept for gain and drift (a closed inlet's zeroed flow passes no gas).
void undistortSeries(const std::string& kind, double value, const std::vector<double>& t, std::vector<double>* x,
                     double at_rest = NAN);

/// A channel distortion as a CellEffect: it adds nothing to the model and has no state; the
/// replay applies it to the run's inputs before (applyInputDistortions) or to the simulated
/// readings after (applyOutputDistortions).
class ChannelDistortionEffect : public CellEffect {
 public:
  ChannelDistortionEffect(std::string effect, std::string channel, std::string kind, std::string param, double value);
  std::string name() const override { return effect_; }
  std::map<std::string, double> parameters() const override { return {{param_, value_}}; }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams&, const CellVariables&, const double*, EffectTerms*, double*) const override {}
  const std::string& channel() const { return channel_; }
  const std::string& kind() const { return kind_; }
  double value() const { return value_; }
  /// Acts on the simulated readings (pressure, height), not on the model's inputs.
  bool outputSide() const { return channel_ == "pressure" || channel_ == "height"; }

 private:
  std::string effect_, channel_, kind_, param_;
  double value_;
};

/// True when `effects` is not empty and every one is an output-side channel distortion (a replay
/// with them is the replay without them, its readings transformed).
bool onlyOutputDistortions(const std::vector<CellEffectPtr>& effects);
/// Whether `effects` read the height early (a height shift below 0): its first readings then
/// show the plate after the run's start.
bool readsHeightEarly(const std::vector<CellEffectPtr>& effects);
/// The run's inputs as the model should see them under `effects`' input-side distortions
/// (inflow, supply and load corrected, the valve command distorted); false when there are none
/// (the run is left as it is).
bool applyInputDistortions(const std::vector<CellEffectPtr>& effects, RunData* run);
/// The height readings `h` (at times `t`) as a true height sensor would give them under
/// `effects`' height gain, offset and drift (a shift or lag leaves a run's start at rest as it
/// is), into `out`; false where there are none (`out` untouched).
bool undoHeightReadingDistortions(const std::vector<CellEffectPtr>& effects, const std::vector<double>& t,
                                  const std::vector<double>& h, std::vector<double>* out);
/// The simulated readings `p`, `h` (at times `t`) as the distorted sensors report them.
void applyOutputDistortions(const std::vector<CellEffectPtr>& effects, const std::vector<double>& t,
                            std::vector<double>* p, std::vector<double>* h);

}  // namespace nursing_bed
