#include "nursing_bed/core/gap/validation.h"

#include <cmath>
#include <map>
#include <sstream>
#include <tuple>

namespace nursing_bed {
namespace gap {
namespace {

/// Running sums of one row.
struct Sums {
  int n = 0;
  double e = 0.0, e2 = 0.0, data = 0.0, num = 0.0, input = 0.0;
};

/// Adds the used samples of `run` (replayed as `replay`) to `rows`.
void addRun(const FitData::Run& run, const Replay& replay, std::map<std::tuple<int, RunPhase, double>, Sums>* rows) {
  const RunData& data = *run.data;
  for (std::size_t j = 0; j < run.index.size(); ++j) {
    const std::size_t i = run.index[j];
    const RunPhase phase = replay.phases[i];
    const double load = std::round(data.loadAt(i) * 10.0) / 10.0;
    for (int signal = 0; signal < 2; ++signal) {
      if (signal == 1 && !run.has_height) continue;
      const double e = signal == 0 ? replay.p_gauge_pa[i] - data.p_gauge_pa[i] : replay.h_m[i] - data.h_m[i];
      if (!std::isfinite(e)) continue;
      Sums& s = (*rows)[{signal, phase, load}];
      ++s.n;
      s.e += e;
      s.e2 += e * e;
      s.data += signal == 0 ? run.var_data_p[j] : run.var_data_h[j];
      s.num += signal == 0 ? run.var_num_p[j] : run.var_num_h[j];
      s.input += signal == 0 ? run.var_input_p[j] : run.var_input_h[j];
    }
  }
}

}  // namespace

std::vector<ValidationRow> validationTable(const PreparedRuns& prepared, const NoiseModel& noise,
                                           const std::vector<Replay>& replays) {
  std::map<std::tuple<int, RunPhase, double>, Sums> rows;
  for (std::size_t j = 0; j < prepared.fit.size() && j < noise.fit.runs.size(); ++j)
    if (prepared.fit[j] < replays.size() && replays[prepared.fit[j]].ok)
      addRun(noise.fit.runs[j], replays[prepared.fit[j]], &rows);
  for (std::size_t j = 0; j < prepared.withheld.size() && j < noise.held.runs.size(); ++j)
    if (prepared.withheld[j] < replays.size() && replays[prepared.withheld[j]].ok)
      addRun(noise.held.runs[j], replays[prepared.withheld[j]], &rows);
  std::vector<ValidationRow> out;
  for (const auto& [key, s] : rows) {
    if (s.n == 0) continue;
    ValidationRow r;
    r.signal = std::get<0>(key) == 0 ? "pressure" : "height";
    r.phase = phaseName(std::get<1>(key));
    r.load_n = std::get<2>(key);
    r.samples = s.n;
    r.e_mean = s.e / s.n;
    r.e_rms = std::sqrt(s.e2 / s.n);
    r.u_data = std::sqrt(s.data / s.n);
    r.u_num = std::sqrt(s.num / s.n);
    r.u_input = std::sqrt(s.input / s.n);
    r.u_val = std::sqrt(r.u_data * r.u_data + r.u_num * r.u_num + r.u_input * r.u_input);
    out.push_back(r);
  }
  return out;
}

std::string validationWords(const ValidationRow& row) {
  if (!(row.u_val > 0.0)) return "–";
  const double ratio = row.e_rms / row.u_val;
  if (ratio <= 1.0) return "within u_val";
  std::ostringstream s;
  s.precision(ratio < 10.0 ? 2 : 3);
  s << ratio << " u_val";
  return s.str();
}

}  // namespace gap
}  // namespace nursing_bed
