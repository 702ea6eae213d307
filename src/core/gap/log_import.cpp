// `gap import`: a log of another format read with a column mapping (log_import_mapping.cpp),
// its signals converted to SI, units detected where the mapping gives candidates, derived
// channels computed, the log cut into runs of whole cycles, and the dataset written only once
// everything has been read and checked (doc/formats/import_mapping.md).
#include "nursing_bed/core/gap/log_import.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// A rise of the cycle signal counts from the sample where it starts climbing; climbing means
/// more than this share of the signal's range per sample (its float noise is far below).
constexpr double kRiseTolerance = 1e-3;

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> splitFields(const std::string& line, char delimiter) {
  std::vector<std::string> out;
  if (delimiter == 0) {
    std::istringstream in(line);
    for (std::string f; in >> f;) out.push_back(f);
    return out;
  }
  std::size_t start = 0;
  while (true) {
    const std::size_t d = line.find(delimiter, start);
    out.push_back(trim(line.substr(start, d == std::string::npos ? std::string::npos : d - start)));
    if (d == std::string::npos) break;
    start = d + 1;
  }
  return out;
}

/// Locale-independent number; empty or "nan" -> NaN. False when the text is not a number.
bool parseNumber(const std::string& text, double* value) {
  if (text.empty() || text == "nan" || text == "NaN") {
    *value = kNaN;
    return true;
  }
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  if (*begin == '+' && end - begin > 1 && begin[1] != '-') ++begin;
  const auto r = std::from_chars(begin, end, *value);
  return r.ec == std::errc() && r.ptr == end;
}

std::string fmt(double v, int digits = 4) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*g", digits, v);
  return buf;
}

std::string fileName(const std::string& path) { return fs::path(path).filename().string(); }

/// The columns of a log the mapping uses, as read (the mapping's unit, before any conversion).
struct LogTable {
  std::vector<std::string> header;
  std::size_t header_line = 0;
  std::vector<double> t_s;
  std::map<std::string, std::vector<double>> columns;
};

/// Reads a log line by line; every error names the file, the line and the column.
class LogReader {
 public:
  LogReader(const ImportMapping& mapping, const std::string& path) : mapping_(mapping), path_(path) {
    used_.insert(mapping.time_column);
    for (const auto& s : mapping.signals)
      if (!s.column.empty()) used_.insert(s.column);
  }

  LogTable read() {
    std::ifstream in(path_);
    if (!in) throw std::runtime_error(path_ + ": cannot open log file");
    std::string line;
    while (std::getline(in, line)) {
      ++line_no_;
      const std::string text = trim(line);
      if (text.empty() || text.rfind(mapping_.comment, 0) == 0) continue;
      if (table_.header.empty()) headerLine(text);
      else dataRow(text);
    }
    if (in.bad()) throw std::runtime_error(path_ + ": read error");
    if (table_.header.empty()) throw fail(line_no_, "no header line (only comments or blank lines)");
    if (table_.t_s.size() < 2)
      throw fail(line_no_, std::to_string(table_.t_s.size()) + " data row(s), a log needs at least 2");
    return std::move(table_);
  }

 private:
  std::runtime_error fail(std::size_t line, const std::string& what) const {
    return std::runtime_error(path_ + ":" + std::to_string(line) + ": " + what);
  }

  void headerLine(const std::string& text) {
    table_.header = splitFields(text, mapping_.delimiter);
    table_.header_line = line_no_;
    for (const auto& name : used_) {
      const auto n = std::count(table_.header.begin(), table_.header.end(), name);
      std::string list;
      for (const auto& h : table_.header) list += (list.empty() ? "" : ", ") + h;
      if (n == 0)
        throw fail(line_no_,
                   "column '" + name + "' (named by " + mapping_.source + ") not in the header (" + list + ")");
      if (n > 1) throw fail(line_no_, "column '" + name + "' appears " + std::to_string(n) + " times in the header");
    }
    for (std::size_t c = 0; c < table_.header.size(); ++c) {
      if (!used_.count(table_.header[c])) continue;
      index_.push_back(c);
      table_.columns[table_.header[c]];
    }
  }

  void dataRow(const std::string& text) {
    const std::vector<std::string> fields = splitFields(text, mapping_.delimiter);
    if (fields.size() != table_.header.size())
      throw fail(line_no_, "expected " + std::to_string(table_.header.size()) + " fields (header at line " +
                               std::to_string(table_.header_line) + "), got " + std::to_string(fields.size()));
    for (const std::size_t c : index_) {
      const std::string& name = table_.header[c];
      const std::string where = "column '" + name + "' (" + std::to_string(c + 1) + "): ";
      double v = 0.0;
      if (!parseNumber(fields[c], &v)) throw fail(line_no_, where + "non-numeric field '" + fields[c] + "'");
      if (std::isinf(v)) throw fail(line_no_, where + "field '" + fields[c] + "' is not finite");
      if (name == mapping_.time_column) checkTime(v * mapping_.time_to_s, where);
      table_.columns[name].push_back(v);
    }
  }

  void checkTime(double t, const std::string& where) {
    if (std::isnan(t)) throw fail(line_no_, where + "time missing (every row needs one)");
    if (!table_.t_s.empty() && !(t > table_.t_s.back()))
      throw fail(line_no_, where + "time not strictly increasing (" + fmt(t, 10) + " s after " +
                               fmt(table_.t_s.back(), 10) + " s on line " + std::to_string(last_time_line_) + ")");
    table_.t_s.push_back(t);
    last_time_line_ = line_no_;
  }

  const ImportMapping& mapping_;
  const std::string path_;
  std::set<std::string> used_;
  std::vector<std::size_t> index_;  ///< header positions of the used columns
  LogTable table_;
  std::size_t line_no_ = 0, last_time_line_ = 0;
};

/// A signal in SI with what it is.
struct Signal {
  std::vector<double> si;
  Quantity quantity = Quantity::kRatio;
  std::string unit;  ///< the unit used ("kPa"), or "derived"
  double meter_density_kg_m3 = kNaN;
};

std::vector<double> toSi(const SignalSpec& spec, const LogUnit& unit, const std::vector<double>& raw) {
  std::vector<double> out(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i)
    out[i] = spec.sign * (spec.scale * raw[i] + spec.offset) * unit.to_si + unit.si_offset;
  return out;
}

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

double percentile(std::vector<double> v, double q) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

/// Sample indices where a cycle starts: the signal crosses the middle of its range (5th to 95th
/// percentile) upwards; the start is the first sample of that climb.
std::vector<std::size_t> cycleStarts(const std::vector<double>& v) {
  const double lo = percentile(v, 0.05), hi = percentile(v, 0.95);
  std::vector<std::size_t> starts;
  if (!(hi > lo)) return starts;
  const double mid = 0.5 * (lo + hi), tol = kRiseTolerance * (hi - lo);
  for (std::size_t i = 1; i < v.size(); ++i) {
    if (!(v[i - 1] < mid && v[i] >= mid)) continue;
    std::size_t j = i;
    while (j > 0 && v[j - 1] < v[j] - tol) --j;
    if (starts.empty() || j > starts.back()) starts.push_back(j);
  }
  return starts;
}

/// Turns one log into runs; every decision is noted.
class LogImporter {
 public:
  LogImporter(const ImportMapping& mapping, const std::string& path) : m_(mapping), path_(path) {}

  ImportedLog run() {
    table_ = LogReader(m_, path_).read();
    out_.path = path_;
    for (const auto& s : m_.signals)
      if (!s.column.empty() && s.units.size() == 1) columnSignal(s, *findLogUnit(s.units[0]));
    if (m_.cycles) findCycles();
    for (const auto& s : m_.signals)
      if (s.units.size() > 1) detectUnit(s);
    for (const auto& s : m_.signals)
      if (s.venturi) venturiSignal(s);
    if (m_.cycles) judgeCycles();
    cutRuns();
    return std::move(out_);
  }

 private:
  std::runtime_error fail(const std::string& what) const { return std::runtime_error(path_ + ": " + what); }

  void columnSignal(const SignalSpec& s, const LogUnit& unit) {
    Signal& sig = signals_[s.name];
    sig.si = toSi(s, unit, table_.columns.at(s.column));
    sig.quantity = unit.quantity;
    sig.unit = unit.name;
    sig.meter_density_kg_m3 = s.meter_density_kg_m3;
  }

  void findCycles() {
    const SignalSpec& spec = *std::find_if(m_.signals.begin(), m_.signals.end(),
                                           [&](const SignalSpec& s) { return s.name == m_.cycles->signal; });
    // Edges do not depend on a positive unit factor: the first candidate serves before detection.
    const std::vector<double> v = toSi(spec, *findLogUnit(spec.units[0]), table_.columns.at(spec.column));
    starts_ = cycleStarts(v);
    cycle_signal_ = v;
    cycle_mid_ = 0.5 * (percentile(v, 0.05) + percentile(v, 0.95));
    if (starts_.size() < 2)
      throw fail("column '" + spec.column + "': " + std::to_string(starts_.size()) +
                 " cycle start(s) (rising edges of signal '" + spec.name +
                 "'), at least 2 are needed for a whole cycle");
    out_.cycles = starts_.size() - 1;
    out_.notes.push_back(fileName(path_) + ": " + std::to_string(out_.cycles) + " whole cycles between " +
                         fmt(table_.t_s[starts_.front()]) + " s and " + fmt(table_.t_s[starts_.back()]) +
                         " s (rising edges of " + spec.name + ")");
  }

  /// Samples the detection compares: just before each cycle start, or all.
  std::vector<std::size_t> detectionSamples(const UnitDetection& d) const {
    std::vector<std::size_t> idx;
    if (d.at == "all") {
      for (std::size_t i = 0; i < table_.t_s.size(); ++i) idx.push_back(i);
      return idx;
    }
    for (const std::size_t s : starts_)
      for (std::size_t i = s; i-- > 0 && table_.t_s[i] >= table_.t_s[s] - d.window_s;) idx.push_back(i);
    return idx;
  }

  void detectUnit(const SignalSpec& s) {
    const UnitDetection& d = *s.detect;
    const std::vector<std::size_t> idx = detectionSamples(d);
    std::vector<double> ref;
    for (const std::size_t i : idx) ref.push_back(signals_.at(d.reference).si[i]);
    const double ref_median = median(ref);
    const std::string where = "column '" + s.column + "' (signal '" + s.name + "'): ";
    if (!std::isfinite(ref_median) || std::abs(ref_median) < 1e-12)
      throw fail(where + "cannot tell its unit: the reference '" + d.reference + "' is zero or missing at " + d.at);
    std::vector<std::string> fits;
    std::string tried;
    for (const auto& name : s.units) {
      const LogUnit unit = *findLogUnit(name);
      const std::vector<double> si = toSi(s, unit, table_.columns.at(s.column));
      std::vector<double> sel;
      for (const std::size_t i : idx) sel.push_back(si[i]);
      const double ratio = median(sel) / ref_median;
      tried += (tried.empty() ? "" : ", ") + fmt(ratio, 3) + " as " + name;
      if (ratio >= d.ratio_min && ratio <= d.ratio_max) fits.push_back(name);
    }
    const std::string rule = "median " + (d.at == "all" ? std::string("over the log") : "before the cycle starts") +
                             " / " + d.reference + ": " + tried + "; plausible " + fmt(d.ratio_min) + "-" +
                             fmt(d.ratio_max);
    if (fits.size() != 1)
      throw fail(where + "cannot tell its unit (" + rule + (fits.empty() ? "; none fits)" : "; several fit)"));
    columnSignal(s, *findLogUnit(fits[0]));
    out_.notes.push_back(fileName(path_) + ": " + s.name + " in " + fits[0] + " (detected: " + rule + ")");
  }

  void venturiSignal(const SignalSpec& s) {
    const VenturiSpec& v = *s.venturi;
    const double a1 = 0.25 * kPi * v.inlet_diameter_m * v.inlet_diameter_m;
    const double a2 = 0.25 * kPi * v.throat_diameter_m * v.throat_diameter_m;
    const double k = v.discharge_coefficient * a1 * a2 / std::sqrt(a1 * a1 - a2 * a2);
    const double rho = m_.density_kg_m3;
    auto mdot = [&](double dp_pa) { return (dp_pa < 0 ? -1.0 : 1.0) * k * std::sqrt(2.0 * std::abs(dp_pa) * rho); };
    const std::vector<double>& fwd = signals_.at(v.forward_dp).si;
    Signal& sig = signals_[s.name];
    sig.quantity = Quantity::kMassFlow;
    sig.unit = "derived";
    sig.si.resize(fwd.size());
    for (std::size_t i = 0; i < fwd.size(); ++i) sig.si[i] = mdot(fwd[i]);
    if (!v.reverse_dp.empty()) {
      const std::vector<double>& rev = signals_.at(v.reverse_dp).si;
      for (std::size_t i = 0; i < rev.size(); ++i) sig.si[i] -= mdot(rev[i]);
    }
  }

  /// A run column's values over the whole log (mass flows from volume flows with the density).
  std::vector<double> output(const std::string& signal_name) const {
    const Signal& sig = signals_.at(signal_name);
    if (sig.quantity != Quantity::kVolumeFlow) return sig.si;
    const double rho = std::isfinite(sig.meter_density_kg_m3) ? std::sqrt(sig.meter_density_kg_m3 * m_.density_kg_m3)
                                                              : m_.density_kg_m3;
    std::vector<double> out(sig.si);
    for (double& x : out) x *= rho;
    return out;
  }

  std::map<std::string, std::string> runMetadata() const {
    std::map<std::string, std::string> meta = m_.metadata;
    const auto f = m_.file_metadata.find(fileName(path_));
    if (f != m_.file_metadata.end())
      for (const auto& [k, v] : f->second) meta[k] = v;
    meta["import_source"] = fileName(path_);
    meta["import_mapping"] = fileName(m_.source);
    std::string units;
    for (const auto& s : m_.signals) {
      if (s.venturi) continue;
      units +=
          (units.empty() ? "" : ", ") + s.column + "=" + signals_.at(s.name).unit + (s.detect ? " (detected)" : "");
    }
    meta["import_units"] = units;
    return meta;
  }

  /// Applies the metadata keys with a meaning in RunData.
  void applyMetadata(const std::map<std::string, std::string>& meta, RunData* run) const {
    run->meta = meta;
    const auto load = meta.find("load_n");
    if (load != meta.end()) {
      if (!parseNumber(load->second, &run->load_n) || !std::isfinite(run->load_n))
        throw fail("metadata load_n (from " + m_.source + "): expected a number of newtons, got '" + load->second +
                   "'");
    } else if (!m_.outputs.count("load_n")) {
      throw fail("no load: give 'load_n' under metadata (or files) in " + m_.source + ", or map a load_n column");
    }
    const auto airbag = meta.find("airbag");
    if (airbag != meta.end()) run->airbag = airbag->second;
    const auto sampling = meta.find(kFlowSamplingKey);
    if (sampling != meta.end()) {
      if (sampling->second != "instant" && sampling->second != "interval_mean")
        throw fail(std::string("metadata ") + kFlowSamplingKey + " (from " + m_.source +
                   "): expected instant or interval_mean, got '" + sampling->second + "'");
      run->flow_interval_means = sampling->second == "interval_mean";
    }
  }

  /// Each whole cycle's metered volume in (while the cycle signal is at or above the middle of
  /// its range) and out (below it) [m^3], from the flow signal `name`.
  std::pair<std::vector<double>, std::vector<double>> phaseVolumes(const std::string& name) const {
    const Signal& sig = signals_.at(name);
    const double to_volume = sig.quantity == Quantity::kVolumeFlow ? 1.0 : 1.0 / m_.density_kg_m3;
    const std::size_t k = starts_.size() - 1;
    std::vector<double> in(k, 0.0), out(k, 0.0);
    for (std::size_t c = 0; c < k; ++c)
      for (std::size_t i = starts_[c]; i < starts_[c + 1]; ++i) {
        const double dv = 0.5 * (sig.si[i] + sig.si[i + 1]) * (table_.t_s[i + 1] - table_.t_s[i]) * to_volume;
        if (cycle_signal_[i] >= cycle_mid_) in[c] += dv;
        else out[c] -= dv;
      }
    return {in, out};
  }

  /// Marks the cycles unlike the others (cycles/keep_typical) and notes each one left out.
  void judgeCycles() {
    kept_.assign(starts_.size() - 1, true);
    if (!m_.cycles->keep_typical) return;
    const TypicalCycles& rule = *m_.cycles->keep_typical;
    const auto [in, out] = phaseVolumes(rule.flow);
    const double med_in = median(in), med_out = median(out);
    if (!(med_in > 0.0) || !(med_out > 0.0))
      throw fail("cycles/keep_typical: the median volume in (" + fmt(med_in * 1e6) + " mL) or out (" +
                 fmt(med_out * 1e6) + " mL) of a cycle is not positive: '" + rule.flow +
                 "' does not fill and empty with the cycles of '" + m_.cycles->signal + "'");
    auto typical = [&](double v, double med) { return v >= med / rule.factor && v <= med * rule.factor; };
    for (std::size_t c = 0; c < kept_.size(); ++c) {
      if (typical(in[c], med_in) && typical(out[c], med_out)) continue;
      kept_[c] = false;
      out_.left_out.push_back(c);
      out_.notes.push_back(fileName(path_) + ": cycle " + std::to_string(c + 1) + " (" + fmt(table_.t_s[starts_[c]]) +
                           "-" + fmt(table_.t_s[starts_[c + 1]]) +
                           " s) left out, unlike the others: " + fmt(in[c] * 1e6) + " mL in, " + fmt(out[c] * 1e6) +
                           " mL out against medians of " + fmt(med_in * 1e6) + " and " + fmt(med_out * 1e6) +
                           " mL (factor " + fmt(rule.factor) + ", " + rule.flow + ")");
    }
    if (out_.left_out.size() == kept_.size())
      throw fail("cycles/keep_typical: every cycle left out (factor " + fmt(rule.factor) + ")");
  }

  /// A run: samples [first, last] and, when cut into cycles, its cycles [cycle, cycle_end).
  struct RunRange {
    std::size_t first = 0, last = 0, cycle = 0, cycle_end = 0;
  };

  /// The runs: groups of whole kept cycles (a group never spans a cycle left out), or the
  /// whole log.
  std::vector<RunRange> runRanges() const {
    if (!m_.cycles) return {{0, table_.t_s.size() - 1, 0, 0}};
    std::vector<RunRange> ranges;
    const std::size_t k = kept_.size();
    for (std::size_t c = 0; c < k;) {
      if (!kept_[c]) {
        ++c;
        continue;
      }
      std::size_t end = c;
      while (end < k && kept_[end]) ++end;
      const std::size_t per =
          m_.cycles->cycles_per_run == 0 ? end - c : static_cast<std::size_t>(m_.cycles->cycles_per_run);
      for (std::size_t g = c; g < end; g += per) {
        const std::size_t e = std::min(g + per, end);
        ranges.push_back({starts_[g], starts_[e], g, e});
      }
      c = end;
    }
    return ranges;
  }

  void cutRuns() {
    const auto meta = runMetadata();
    std::map<std::string, std::vector<double>> columns;
    for (const auto& [column, signal] : m_.outputs) columns[column] = output(signal);
    const auto ranges = runRanges();
    const std::string stem = m_.run_prefix + fs::path(path_).stem().string();
    for (std::size_t r = 0; r < ranges.size(); ++r) {
      const std::size_t a = ranges[r].first, b = ranges[r].last;
      auto slice = [&](const std::vector<double>& v) { return std::vector<double>(v.begin() + a, v.begin() + b + 1); };
      RunData run;
      char index[32];
      std::snprintf(index, sizeof(index), "_%02zu", r + 1);
      run.name = stem + (ranges.size() > 1 || m_.cycles ? std::string(index) : "") + ".csv";
      run.source = path_;
      applyMetadata(meta, &run);
      if (m_.cycles)
        run.meta["import_cycles"] = std::to_string(ranges[r].cycle + 1) + "-" + std::to_string(ranges[r].cycle_end) +
                                    " of " + std::to_string(out_.cycles);
      run.t_s = slice(table_.t_s);
      run.h_m.assign(run.t_s.size(), kNaN);
      run.mdot_in_kg_s.assign(run.t_s.size(), kNaN);
      for (const auto& [column, values] : columns) *runColumn(&run, column) = slice(values);
      if (!m_.roles.pattern.empty()) run.role = m_.roles.pattern[r % m_.roles.pattern.size()];
      const auto role = m_.roles.by_run.find(run.name);
      if (role != m_.roles.by_run.end()) run.role = role->second;
      out_.runs.push_back(std::move(run));
    }
  }

  static std::vector<double>* runColumn(RunData* run, const std::string& column) {
    const std::map<std::string, std::vector<double>*> known = {{"p_gauge_pa", &run->p_gauge_pa},
                                                               {"mdot_in_kg_s", &run->mdot_in_kg_s},
                                                               {"h_m", &run->h_m},
                                                               {"load_n", &run->load_n_series},
                                                               {"valve_cmd", &run->valve_cmd},
                                                               {"p_supply_gauge_pa", &run->p_supply_gauge_pa},
                                                               {"t_gas_k", &run->t_gas_k},
                                                               {"mdot_uncorrected_kg_s", &run->mdot_uncorrected_kg_s},
                                                               {"p_setpoint_gauge_pa", &run->p_setpoint_gauge_pa}};
    return known.at(column);  // the mapping reader admits only importRunColumns()
  }

  const ImportMapping& m_;
  const std::string path_;
  LogTable table_;
  std::map<std::string, Signal> signals_;
  std::vector<std::size_t> starts_;
  std::vector<double> cycle_signal_;  ///< the cycle signal in SI (its first candidate unit)
  double cycle_mid_ = kNaN;           ///< the middle of its range: above it, a cycle's first phase
  std::vector<bool> kept_;            ///< per whole cycle: not left out as unlike the others
  ImportedLog out_;
};

void writeDatasetYaml(const std::string& path, const std::vector<ImportedLog>& logs, const ImportMapping& mapping) {
  YAML::Emitter e;
  e << YAML::Comment("Imported by gap import with " + fileName(mapping.source));
  e << YAML::BeginMap << YAML::Key << "runs" << YAML::Value << YAML::BeginMap;
  std::size_t n = 0;
  for (const auto& log : logs)
    for (const auto& r : log.runs)
      if (!r.role.empty()) {
        e << YAML::Key << r.name << YAML::Value << r.role;
        ++n;
      }
  e << YAML::EndMap << YAML::EndMap;
  std::ofstream f(path);
  f << (n ? e.c_str() : "# Imported by gap import: no roles, the diagnosis chooses the withheld runs") << "\n";
  f.close();
  if (!f) throw std::runtime_error(path + ": write failed");
}

/// Checks the runs of all logs together: unique names, every role given by name used.
void checkDataset(const ImportMapping& mapping, const std::vector<ImportedLog>& logs) {
  std::map<std::string, std::string> seen;
  for (const auto& log : logs)
    for (const auto& r : log.runs) {
      const auto [it, fresh] = seen.emplace(r.name, log.path);
      if (!fresh)
        throw std::runtime_error(log.path + ": run '" + r.name + "' has the name of a run of " + it->second +
                                 " (set run_prefix in " + mapping.source + ", or import them separately)");
    }
  for (const auto& [name, role] : mapping.roles.by_run)
    if (!seen.count(name))
      throw std::runtime_error(mapping.source + ": roles: '" + name + "' is not a run of this import");
}

}  // namespace

ImportedLog importLog(const ImportMapping& mapping, const std::string& log_path) {
  return LogImporter(mapping, log_path).run();
}

std::vector<ImportedLog> importLogsToDataset(const ImportMapping& mapping, const std::vector<std::string>& log_paths,
                                             const std::string& out_dir) {
  if (log_paths.empty()) throw std::runtime_error("no log files to import");
  std::error_code ec;
  if (fs::exists(out_dir, ec) && !(fs::is_directory(out_dir, ec) && fs::is_empty(out_dir, ec)))
    throw std::runtime_error(out_dir + ": exists and is not an empty directory (nothing written)");
  std::vector<ImportedLog> logs;
  for (const auto& p : log_paths) logs.push_back(importLog(mapping, p));
  checkDataset(mapping, logs);

  const fs::path target = fs::absolute(fs::path(out_dir)).lexically_normal();
  const fs::path tmp = target.parent_path() / ("." + target.filename().string() + ".importing");
  fs::remove_all(tmp, ec);
  if (!fs::create_directories(tmp, ec) || ec)
    throw std::runtime_error(tmp.string() + ": cannot create the output directory: " + ec.message());
  try {
    for (const auto& log : logs)
      for (const auto& r : log.runs) writeRunCsv((tmp / r.name).string(), r);
    writeDatasetYaml((tmp / "dataset.yaml").string(), logs, mapping);
    if (fs::exists(target)) fs::remove(target);
    fs::rename(tmp, target);
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  return logs;
}

}  // namespace nursing_bed
