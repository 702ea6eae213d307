#include "nursing_bed/core/gap/run_data.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nursing_bed {
namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
const char* const kVersionKey = "nursing_bed_run";
/// Always required (h_m may be empty throughout: no height sensor); mdot_in_kg_s too unless the
/// run is valve-driven (valve_cmd and a supply pressure; doc/formats/run_data.md).
const char* const kRequiredColumns[] = {"t_s", "p_gauge_pa", "h_m"};
const char* const kSupplyKey = "p_supply_gauge_pa";

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> splitFields(const std::string& line) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    out.push_back(trim(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

enum class ParseResult { kOk, kNotNumeric, kNotFinite };

// Locale-independent number: empty or "nan" -> NaN; a leading '+' is allowed.
ParseResult parseNumber(const std::string& text, double* value) {
  if (text.empty()) {
    *value = kNaN;
    return ParseResult::kOk;
  }
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  if (*begin == '+' && end - begin > 1 && begin[1] != '-') ++begin;
  double v = 0.0;
  const auto r = std::from_chars(begin, end, v);
  if (r.ec == std::errc::result_out_of_range && r.ptr == end) {
    // Overflow is not finite; underflow reads as zero.
    const std::string digits(begin, end);
    const auto e = digits.find_first_of("eE");
    const bool tiny = e != std::string::npos && digits.find('-', e) != std::string::npos;
    if (!tiny) return ParseResult::kNotFinite;
    *value = 0.0;
    return ParseResult::kOk;
  }
  if (r.ec != std::errc() || r.ptr != end) return ParseResult::kNotNumeric;
  if (std::isinf(v)) return ParseResult::kNotFinite;
  *value = std::isnan(v) ? kNaN : v;
  return ParseResult::kOk;
}

std::string formatNumber(double v) {
  if (std::isnan(v)) return "";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

std::string fileName(const std::string& path) { return fs::path(path).filename().string(); }

}  // namespace

double RunData::loadAt(std::size_t i) const {
  if (i < load_n_series.size() && std::isfinite(load_n_series[i])) return load_n_series[i];
  return load_n;
}

namespace {

/// Reads one run CSV line by line: metadata, the header, the data rows (doc/formats/run_data.md). Every
/// error names the file and line (and the column where there is one).
class RunCsvReader {
 public:
  explicit RunCsvReader(const std::string& path) : path_(path) {
    run_.name = fileName(path);
    run_.source = path;
  }

  RunData read() {
    std::ifstream in(path_);
    if (!in) throw std::runtime_error(path_ + ": cannot open run file");
    std::string line;
    while (std::getline(in, line)) {
      ++line_no_;
      const std::string text = trim(line);
      if (header_.empty()) {
        if (text.empty()) continue;
        if (text[0] == '#') metadataLine(text);
        else headerLine(text);
      } else if (!text.empty() && text[0] != '#') {
        dataRow(text);
      }
    }
    if (in.bad()) throw std::runtime_error(path_ + ": read error");
    const std::size_t last = std::max<std::size_t>(line_no_, 1);
    if (header_.empty()) {
      checkVersionAndLoad(last);
      throw fail(last, "no header line (expected t_s,mdot_in_kg_s,p_gauge_pa,h_m)");
    }
    if (run_.t_s.size() < 2)
      throw fail(line_no_, std::to_string(run_.t_s.size()) + " data row(s), a run needs at least 2");
    fillAbsentColumns();
    return std::move(run_);
  }

 private:
  std::runtime_error fail(std::size_t line, const std::string& what) const {
    return std::runtime_error(path_ + ":" + std::to_string(line) + ": " + what);
  }

  /// "# key: value" before the header; a line without a colon is a plain comment.
  void metadataLine(const std::string& text) {
    const std::string body = trim(text.substr(1));
    const auto colon = body.find(':');
    if (colon == std::string::npos) return;
    const std::string key = trim(body.substr(0, colon));
    if (key.empty()) return;
    run_.meta[key] = trim(body.substr(colon + 1));
    meta_line_[key] = line_no_;
  }

  /// The known metadata, checked once the header (or the end of the file) is reached.
  void checkVersionAndLoad(std::size_t at_line) {
    const auto v = run_.meta.find(kVersionKey);
    if (v == run_.meta.end())
      throw fail(at_line, std::string("missing format version: the file must start with '# ") + kVersionKey + ": " +
                              std::to_string(kRunCsvVersion) + "'");
    if (v->second != std::to_string(kRunCsvVersion))
      throw fail(meta_line_[kVersionKey], "unsupported format version '" + v->second + "' (this reader knows " +
                                              std::to_string(kRunCsvVersion) + ")");
    const auto l = run_.meta.find("load_n");
    if (l != run_.meta.end()) {
      double value = 0.0;
      if (parseNumber(l->second, &value) != ParseResult::kOk || !std::isfinite(value))
        throw fail(meta_line_["load_n"],
                   "metadata load_n: expected a finite number of newtons, got '" + l->second + "'");
      run_.load_n = value;
    }
    const auto a = run_.meta.find("airbag");
    if (a != run_.meta.end()) run_.airbag = a->second;
    const auto s = run_.meta.find(kFlowSamplingKey);
    if (s != run_.meta.end()) {
      if (s->second != "instant" && s->second != "interval_mean")
        throw fail(meta_line_[kFlowSamplingKey], std::string("metadata ") + kFlowSamplingKey +
                                                     ": expected instant or interval_mean, got '" + s->second + "'");
      run_.flow_interval_means = s->second == "interval_mean";
    }
  }

  /// The header: every column named once, the required ones present, each bound to its series.
  void headerLine(const std::string& text) {
    header_line_ = line_no_;
    checkVersionAndLoad(line_no_);
    header_ = splitFields(text);
    std::set<std::string> seen;
    const std::map<std::string, std::vector<double>*> known = {{"t_s", &run_.t_s},
                                                               {"mdot_in_kg_s", &run_.mdot_in_kg_s},
                                                               {"p_gauge_pa", &run_.p_gauge_pa},
                                                               {"h_m", &run_.h_m},
                                                               {"load_n", &run_.load_n_series},
                                                               {"valve_cmd", &run_.valve_cmd},
                                                               {"p_supply_gauge_pa", &run_.p_supply_gauge_pa},
                                                               {"t_gas_k", &run_.t_gas_k},
                                                               {"mdot_uncorrected_kg_s", &run_.mdot_uncorrected_kg_s},
                                                               {"p_setpoint_gauge_pa", &run_.p_setpoint_gauge_pa}};
    for (std::size_t c = 0; c < header_.size(); ++c) {
      const std::string& name = header_[c];
      if (name.empty()) throw fail(line_no_, "column " + std::to_string(c + 1) + " has no name");
      if (!seen.insert(name).second)
        throw fail(line_no_, "column '" + name + "' (" + std::to_string(c + 1) + ") appears twice");
      const auto k = known.find(name);
      if (name == "t_s") time_column_ = static_cast<int>(c);
      target_.push_back(k == known.end() ? nullptr : k->second);
    }
    for (const char* required : kRequiredColumns)
      if (!seen.count(required)) throw fail(line_no_, std::string("missing required column '") + required + "'");
    const bool supply = seen.count(kSupplyKey) || run_.meta.count(kSupplyKey);
    if (!seen.count("mdot_in_kg_s") && !(seen.count("valve_cmd") && supply))
      throw fail(line_no_,
                 "missing required column 'mdot_in_kg_s' (a run without a flow meter needs the columns "
                 "valve_cmd and p_supply_gauge_pa, or a '# p_supply_gauge_pa:' metadata key)");
    if (!seen.count("p_supply_gauge_pa") && run_.meta.count(kSupplyKey) &&
        parseNumber(run_.meta[kSupplyKey], &supply_) != ParseResult::kOk)
      throw fail(meta_line_[kSupplyKey],
                 "metadata p_supply_gauge_pa: expected a number of pascals, got '" + run_.meta[kSupplyKey] + "'");
    if (std::isnan(run_.load_n) && !seen.count("load_n"))
      throw fail(line_no_, "missing load_n: give '# load_n: <N>' before the header or a load_n column");
  }

  void dataRow(const std::string& text) {
    const std::vector<std::string> fields = splitFields(text);
    if (fields.size() != header_.size())
      throw fail(line_no_, "expected " + std::to_string(header_.size()) + " fields (header at line " +
                               std::to_string(header_line_) + "), got " + std::to_string(fields.size()));
    for (std::size_t c = 0; c < fields.size(); ++c) {
      if (!target_[c]) continue;
      double value = 0.0;
      const ParseResult r = parseNumber(fields[c], &value);
      const std::string where = "column '" + header_[c] + "' (" + std::to_string(c + 1) + "): ";
      if (r == ParseResult::kNotNumeric) throw fail(line_no_, where + "non-numeric field '" + fields[c] + "'");
      if (r == ParseResult::kNotFinite) throw fail(line_no_, where + "field '" + fields[c] + "' is not finite");
      if (static_cast<int>(c) == time_column_) checkTime(value, where);
      target_[c]->push_back(value);
    }
  }

  /// A run without a flow meter: its flow all NaN; a supply pressure given as metadata becomes a
  /// constant column.
  void fillAbsentColumns() {
    const std::size_t n = run_.t_s.size();
    if (run_.mdot_in_kg_s.empty()) run_.mdot_in_kg_s.assign(n, kNaN);
    if (run_.p_supply_gauge_pa.empty() && std::isfinite(supply_)) run_.p_supply_gauge_pa.assign(n, supply_);
  }

  void checkTime(double value, const std::string& where) {
    if (std::isnan(value)) throw fail(line_no_, where + "time missing (t_s must be given on every row)");
    if (!run_.t_s.empty() && !(value > run_.t_s.back()))
      throw fail(line_no_, where + "time not strictly increasing (" + formatNumber(value) + " s after " +
                               formatNumber(run_.t_s.back()) + " s on line " + std::to_string(last_time_line_) + ")");
    last_time_line_ = line_no_;
  }

  const std::string path_;
  RunData run_;
  std::map<std::string, std::size_t> meta_line_;
  std::vector<std::string> header_;
  std::size_t header_line_ = 0, line_no_ = 0, last_time_line_ = 0;
  std::vector<std::vector<double>*> target_;  ///< per column: where its values go (null: ignored)
  int time_column_ = -1;
  double supply_ = kNaN;  ///< p_supply_gauge_pa from the metadata
};

}  // namespace

RunData readRunCsv(const std::string& path) { return RunCsvReader(path).read(); }

void writeRunCsv(const std::string& path, const RunData& run) {
  const std::size_t n = run.t_s.size();
  struct Column {
    const char* name;
    const std::vector<double>* values;
  };
  auto measured = [](const std::vector<double>& v) {
    return std::any_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
  };
  std::vector<Column> columns = {{"t_s", &run.t_s}, {"p_gauge_pa", &run.p_gauge_pa}, {"h_m", &run.h_m}};
  // No flow meter (a valve-driven run): the column is left out.
  if (measured(run.mdot_in_kg_s) || run.valve_cmd.empty())
    columns.insert(columns.begin() + 1, {"mdot_in_kg_s", &run.mdot_in_kg_s});
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i].values->size() != n)
      throw std::runtime_error(path + ": column " + columns[i].name + " has " +
                               std::to_string(columns[i].values->size()) + " values, t_s has " + std::to_string(n));
  const std::vector<Column> optional = {{"load_n", &run.load_n_series},
                                        {"valve_cmd", &run.valve_cmd},
                                        {"p_supply_gauge_pa", &run.p_supply_gauge_pa},
                                        {"t_gas_k", &run.t_gas_k},
                                        {"mdot_uncorrected_kg_s", &run.mdot_uncorrected_kg_s},
                                        {"p_setpoint_gauge_pa", &run.p_setpoint_gauge_pa}};
  for (const Column& c : optional) {
    if (c.values->empty()) continue;
    if (c.values->size() != n)
      throw std::runtime_error(path + ": column " + c.name + " has " + std::to_string(c.values->size()) +
                               " values, t_s has " + std::to_string(n));
    columns.push_back(c);
  }
  if (!std::isfinite(run.load_n) && run.load_n_series.empty())
    throw std::runtime_error(path + ": a run needs a finite load_n or a load_n column");

  std::ostringstream out;
  out << "# " << kVersionKey << ": " << kRunCsvVersion << "\n";
  if (std::isfinite(run.load_n)) out << "# load_n: " << formatNumber(run.load_n) << "\n";
  if (!run.airbag.empty()) out << "# airbag: " << run.airbag << "\n";
  if (run.flow_interval_means) out << "# " << kFlowSamplingKey << ": interval_mean\n";
  for (const auto& [key, value] : run.meta) {
    if (key == kVersionKey || key == "load_n" || key == "airbag" || key == kFlowSamplingKey) continue;
    std::string v = value;
    std::replace(v.begin(), v.end(), '\n', ' ');
    out << "# " << key << ": " << v << "\n";
  }
  for (std::size_t c = 0; c < columns.size(); ++c) out << (c ? "," : "") << columns[c].name;
  out << "\n";
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t c = 0; c < columns.size(); ++c) out << (c ? "," : "") << formatNumber((*columns[c].values)[i]);
    out << "\n";
  }
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error(path + ": cannot open for writing");
  const std::string text = out.str();
  f.write(text.data(), static_cast<std::streamsize>(text.size()));
  f.close();
  if (!f) throw std::runtime_error(path + ": write failed");
}

std::vector<RunData> readDataset(const std::string& dir, std::vector<RunData> extra_runs) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw std::runtime_error(dir + ": not a readable directory");
  std::vector<std::string> csv_files;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".csv" && it->is_regular_file()) csv_files.push_back(it->path().string());
  }
  if (ec) throw std::runtime_error(dir + ": cannot list: " + ec.message());
  std::sort(csv_files.begin(), csv_files.end());

  std::vector<RunData> runs;
  for (const auto& file : csv_files) runs.push_back(readRunCsv(file));
  for (auto& r : extra_runs) runs.push_back(std::move(r));
  if (runs.empty()) throw std::runtime_error(dir + ": no runs found (no *.csv files, no runs from bags)");
  std::sort(runs.begin(), runs.end(), [](const RunData& a, const RunData& b) { return a.name < b.name; });
  for (std::size_t i = 1; i < runs.size(); ++i)
    if (runs[i].name == runs[i - 1].name) throw std::runtime_error(dir + ": two runs named '" + runs[i].name + "'");

  const fs::path yaml_path = fs::path(dir) / "dataset.yaml";
  if (!fs::exists(yaml_path)) return runs;
  const std::string source = yaml_path.string();
  auto fail = [&source](const YAML::Node& node, const std::string& what) -> std::runtime_error {
    const int line = node.Mark().line;
    return std::runtime_error(source + (line >= 0 ? ":" + std::to_string(line + 1) : std::string()) + ": " + what);
  };
  YAML::Node root;
  try {
    root = YAML::LoadFile(source);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(source + ": " + e.what());
  }
  if (root.IsNull()) return runs;
  if (!root.IsMap()) throw fail(root, "expected a map with the keys airbag and runs");
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    const YAML::Node& value = kv.second;
    if (key == "airbag") {
      if (!value.IsScalar()) throw fail(value, "airbag: expected a parameter file name or path");
      const std::string airbag = value.as<std::string>();
      for (auto& r : runs)
        if (r.airbag.empty()) r.airbag = airbag;
    } else if (key == "runs") {
      if (value.IsNull()) continue;
      if (!value.IsMap()) throw fail(value, "runs: expected a map {run file: fit|withheld}");
      for (const auto& entry : value) {
        const std::string run_name = entry.first.as<std::string>();
        if (!entry.second.IsScalar()) throw fail(entry.second, "runs: " + run_name + ": expected fit or withheld");
        const std::string role = entry.second.as<std::string>();
        if (role != "fit" && role != "withheld")
          throw fail(entry.second, "runs: " + run_name + ": bad role '" + role + "' (expected fit or withheld)");
        bool found = false;
        for (auto& r : runs) {
          if (r.name == run_name || (!r.source.empty() && fileName(r.source) == run_name)) {
            r.role = role;
            found = true;
          }
        }
        if (!found) {
          std::string names;
          for (const auto& r : runs) names += (names.empty() ? "" : ", ") + r.name;
          throw fail(entry.first,
                     "runs: role given for '" + run_name + "', which is not a run of the dataset (" + names + ")");
        }
      }
    } else {
      throw fail(kv.first, "unknown key '" + key + "' (known: airbag, runs)");
    }
  }
  return runs;
}

std::string resolveAirbagParamsFile(const std::string& airbag, const std::string& dataset_dir) {
  if (airbag.empty()) return defaultCellParamsFile();
  const fs::path config = findPackageFile("config");
  std::vector<fs::path> tried;
  tried.push_back(fs::path(airbag));
  if (!dataset_dir.empty() && fs::path(airbag).is_relative()) tried.push_back(fs::path(dataset_dir) / airbag);
  tried.push_back(config / airbag);
  tried.push_back(config / (airbag + ".yaml"));
  tried.push_back(config / ("airbag_" + airbag + ".yaml"));
  std::error_code ec;
  for (const auto& p : tried)
    if (fs::is_regular_file(p, ec)) return p.string();
  std::string list;
  for (const auto& p : tried) list += (list.empty() ? "" : ", ") + p.string();
  throw std::runtime_error("airbag '" + airbag + "': no parameter file found (tried " + list + ")");
}

}  // namespace nursing_bed
