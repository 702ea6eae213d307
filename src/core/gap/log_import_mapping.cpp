// The column-mapping file of `gap import` (doc/formats/import_mapping.md): YAML read into an
// ImportMapping, every key checked, every error naming the file, the line and the key.
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/gap/log_import.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace {

constexpr int kMappingVersion = 1;
/// 1 cmH2O = 1 cm of water at 1000 kg/m^3 under standard gravity [Pa].
constexpr double kPaPerCmH2O = 98.0665;

const std::vector<LogUnit>& unitTable() {
  static const std::vector<LogUnit> units = {
      {"s", Quantity::kTime, 1.0},
      {"ms", Quantity::kTime, 1e-3},
      {"Pa", Quantity::kPressure, 1.0},
      {"hPa", Quantity::kPressure, 100.0},
      {"kPa", Quantity::kPressure, 1e3},
      {"mbar", Quantity::kPressure, 100.0},
      {"bar", Quantity::kPressure, 1e5},
      {"cmH2O", Quantity::kPressure, kPaPerCmH2O},
      {"mmHg", Quantity::kPressure, kPaPerMmHg},
      {"psi", Quantity::kPressure, 6894.757293168},
      {"m3/s", Quantity::kVolumeFlow, 1.0},
      {"L/s", Quantity::kVolumeFlow, 1e-3},
      {"mL/s", Quantity::kVolumeFlow, 1e-6},
      {"L/min", Quantity::kVolumeFlow, 1e-3 / 60.0},
      {"mL/min", Quantity::kVolumeFlow, 1e-6 / 60.0},
      {"kg/s", Quantity::kMassFlow, 1.0},
      {"g/s", Quantity::kMassFlow, 1e-3},
      {"m3", Quantity::kVolume, 1.0},
      {"L", Quantity::kVolume, 1e-3},
      {"mL", Quantity::kVolume, 1e-6},
      {"m", Quantity::kLength, 1.0},
      {"cm", Quantity::kLength, 1e-2},
      {"mm", Quantity::kLength, 1e-3},
      {"N", Quantity::kForce, 1.0},
      {"K", Quantity::kTemperature, 1.0},
      {"degC", Quantity::kTemperature, 1.0, 273.15},
      {"1", Quantity::kRatio, 1.0},
      {"%", Quantity::kRatio, 1e-2},
  };
  return units;
}

const char* quantityName(Quantity q) {
  switch (q) {
    case Quantity::kTime: return "time";
    case Quantity::kPressure: return "pressure";
    case Quantity::kVolumeFlow: return "volume flow";
    case Quantity::kMassFlow: return "mass flow";
    case Quantity::kVolume: return "volume";
    case Quantity::kLength: return "length";
    case Quantity::kForce: return "force";
    case Quantity::kTemperature: return "temperature";
    case Quantity::kRatio: return "ratio";
  }
  return "?";
}

/// Reads one mapping file; `fail` names the file and the node's line.
class MappingParser {
 public:
  MappingParser(const std::string& text, const std::string& source) : text_(text) { m_.source = source; }

  ImportMapping parse() {
    YAML::Node root;
    try {
      root = YAML::Load(text_);
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(m_.source + ": " + e.what());
    }
    if (!root.IsMap()) throw fail(root, "expected a map with the keys import_mapping, log, time, signals, run");
    checkKeys(root, "",
              {"import_mapping", "log", "time", "signals", "gas", "run", "cycles", "roles", "run_prefix", "metadata",
               "files"},
              {"import_mapping", "time", "signals", "run"});
    const int version = scalar<int>(root["import_mapping"], "import_mapping");
    if (version != kMappingVersion)
      throw fail(root["import_mapping"], "import_mapping: unsupported version " + std::to_string(version) +
                                             " (this reader knows " + std::to_string(kMappingVersion) + ")");
    if (root["log"]) parseLog(root["log"]);
    parseTime(root["time"]);
    parseSignals(root["signals"]);
    if (root["gas"]) {
      checkKeys(root["gas"], "gas", {"density_kg_m3"}, {"density_kg_m3"});
      m_.density_kg_m3 = positive(root["gas"]["density_kg_m3"], "gas/density_kg_m3");
    }
    parseOutputs(root["run"]);
    if (root["cycles"]) parseCycles(root["cycles"]);
    if (root["roles"]) parseRoles(root["roles"]);
    if (root["run_prefix"]) m_.run_prefix = scalar<std::string>(root["run_prefix"], "run_prefix");
    if (root["metadata"]) m_.metadata = stringMap(root["metadata"], "metadata");
    if (root["files"]) parseFiles(root["files"]);
    checkReferences();
    return m_;
  }

 private:
  std::runtime_error fail(const YAML::Node& node, const std::string& what) const {
    const int line = node.Mark().line;
    return std::runtime_error(m_.source + (line >= 0 ? ":" + std::to_string(line + 1) : std::string()) + ": " + what);
  }

  /// Every key of `node` known, the required ones present.
  void checkKeys(const YAML::Node& node, const std::string& where, const std::set<std::string>& known,
                 const std::set<std::string>& required) const {
    if (!node.IsMap()) throw fail(node, (where.empty() ? "the file" : where) + ": expected a map");
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    for (const auto& kv : node) {
      const std::string key = kv.first.as<std::string>();
      if (!known.count(key))
        throw fail(kv.first, "unknown key '" + (where.empty() ? key : where + "/" + key) + "' (known: " + list + ")");
    }
    for (const auto& r : required)
      if (!node[r]) throw fail(node, "missing key '" + (where.empty() ? r : where + "/" + r) + "'");
  }

  template <typename T>
  T scalar(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) throw fail(node, key + ": expected a single value");
    try {
      return node.as<T>();
    } catch (const YAML::Exception&) {
      throw fail(node, key + ": cannot read '" + node.Scalar() + "' as " +
                           (std::is_same<T, std::string>::value ? "text" : "a number"));
    }
  }

  double finite(const YAML::Node& node, const std::string& key) const {
    const double v = scalar<double>(node, key);
    if (!std::isfinite(v)) throw fail(node, key + ": must be finite");
    return v;
  }

  double positive(const YAML::Node& node, const std::string& key) const {
    const double v = finite(node, key);
    if (!(v > 0.0)) throw fail(node, key + ": must be > 0, got " + node.Scalar());
    return v;
  }

  std::map<std::string, std::string> stringMap(const YAML::Node& node, const std::string& key) const {
    if (!node.IsMap()) throw fail(node, key + ": expected a map of key: value");
    std::map<std::string, std::string> out;
    for (const auto& kv : node) {
      const std::string k = kv.first.as<std::string>();
      if (k == "nursing_bed_run") throw fail(kv.first, key + ": 'nursing_bed_run' is written by the importer");
      out[k] = scalar<std::string>(kv.second, key + "/" + k);
    }
    return out;
  }

  LogUnit unit(const YAML::Node& node, const std::string& key) const {
    const std::string name = scalar<std::string>(node, key);
    const auto u = findLogUnit(name);
    if (!u) throw fail(node, key + ": unknown unit '" + name + "' (known: " + logUnitNames() + ")");
    return *u;
  }

  void parseLog(const YAML::Node& node) {
    checkKeys(node, "log", {"comment", "delimiter"}, {});
    if (node["comment"]) {
      m_.comment = scalar<std::string>(node["comment"], "log/comment");
      if (m_.comment.empty()) throw fail(node["comment"], "log/comment: must not be empty");
    }
    if (node["delimiter"]) {
      const std::string d = scalar<std::string>(node["delimiter"], "log/delimiter");
      const std::map<std::string, char> known = {{"whitespace", 0}, {"comma", ','}, {"semicolon", ';'}, {"tab", '\t'}};
      const auto it = known.find(d);
      if (it == known.end())
        throw fail(node["delimiter"], "log/delimiter: expected whitespace, comma, semicolon or tab, got '" + d + "'");
      m_.delimiter = it->second;
    }
  }

  void parseTime(const YAML::Node& node) {
    checkKeys(node, "time", {"column", "unit"}, {"column"});
    m_.time_column = scalar<std::string>(node["column"], "time/column");
    if (node["unit"]) {
      const LogUnit u = unit(node["unit"], "time/unit");
      if (u.quantity != Quantity::kTime) throw fail(node["unit"], "time/unit: '" + u.name + "' is not a unit of time");
      m_.time_to_s = u.to_si;
    }
  }

  void parseSignals(const YAML::Node& node) {
    if (!node.IsMap() || node.size() == 0) throw fail(node, "signals: expected a map of signal name: {column, unit}");
    for (const auto& kv : node) {
      SignalSpec s;
      s.name = kv.first.as<std::string>();
      s.line = kv.first.Mark().line + 1;
      const std::string where = "signals/" + s.name;
      const YAML::Node& v = kv.second;
      if (v.IsMap() && v["venturi"]) {
        checkKeys(v, where, {"venturi"}, {"venturi"});
        s.venturi = parseVenturi(v["venturi"], where + "/venturi");
      } else {
        parseColumnSignal(v, where, &s);
      }
      m_.signals.push_back(s);
    }
  }

  void parseColumnSignal(const YAML::Node& v, const std::string& where, SignalSpec* s) const {
    checkKeys(v, where, {"column", "unit", "detect", "scale", "offset", "sign", "meter_density_kg_m3"},
              {"column", "unit"});
    s->column = scalar<std::string>(v["column"], where + "/column");
    const YAML::Node& u = v["unit"];
    if (u.IsSequence()) {
      if (u.size() < 2) throw fail(u, where + "/unit: a list gives at least two candidates");
      for (const auto& c : u) s->units.push_back(unit(c, where + "/unit").name);
      if (!v["detect"]) throw fail(u, where + "/unit: candidate units need a 'detect' rule to choose from them");
      s->detect = parseDetection(v["detect"], where + "/detect");
    } else {
      s->units.push_back(unit(u, where + "/unit").name);
      if (v["detect"]) throw fail(v["detect"], where + "/detect: only for a list of candidate units");
    }
    const Quantity q = findLogUnit(s->units[0])->quantity;
    for (const auto& name : s->units)
      if (findLogUnit(name)->quantity != q)
        throw fail(u, where + "/unit: candidates of different quantities (" + s->units[0] + ", " + name + ")");
    if (v["scale"]) s->scale = finite(v["scale"], where + "/scale");
    if (v["offset"]) s->offset = finite(v["offset"], where + "/offset");
    if (v["sign"]) {
      s->sign = finite(v["sign"], where + "/sign");
      if (s->sign != 1.0 && s->sign != -1.0) throw fail(v["sign"], where + "/sign: expected 1 or -1");
    }
    if (v["meter_density_kg_m3"]) {
      if (q != Quantity::kVolumeFlow)
        throw fail(v["meter_density_kg_m3"], where + ": meter_density_kg_m3 is for volume flows");
      s->meter_density_kg_m3 = positive(v["meter_density_kg_m3"], where + "/meter_density_kg_m3");
    }
  }

  UnitDetection parseDetection(const YAML::Node& node, const std::string& where) const {
    checkKeys(node, where, {"reference", "at", "window_s", "ratio"}, {"reference", "ratio"});
    UnitDetection d;
    d.reference = scalar<std::string>(node["reference"], where + "/reference");
    if (node["at"]) {
      d.at = scalar<std::string>(node["at"], where + "/at");
      if (d.at != "cycle_end" && d.at != "all")
        throw fail(node["at"], where + "/at: expected cycle_end or all, got '" + d.at + "'");
    }
    if (node["window_s"]) d.window_s = positive(node["window_s"], where + "/window_s");
    const YAML::Node& r = node["ratio"];
    if (!r.IsSequence() || r.size() != 2) throw fail(r, where + "/ratio: expected [min, max]");
    d.ratio_min = positive(r[0], where + "/ratio");
    d.ratio_max = positive(r[1], where + "/ratio");
    if (!(d.ratio_min < d.ratio_max)) throw fail(r, where + "/ratio: min must be below max");
    return d;
  }

  VenturiSpec parseVenturi(const YAML::Node& node, const std::string& where) const {
    checkKeys(node, where, {"forward", "reverse", "discharge_coefficient", "inlet_diameter_m", "throat_diameter_m"},
              {"forward", "inlet_diameter_m", "throat_diameter_m"});
    VenturiSpec v;
    v.forward_dp = scalar<std::string>(node["forward"], where + "/forward");
    if (node["reverse"]) v.reverse_dp = scalar<std::string>(node["reverse"], where + "/reverse");
    if (node["discharge_coefficient"])
      v.discharge_coefficient = positive(node["discharge_coefficient"], where + "/discharge_coefficient");
    v.inlet_diameter_m = positive(node["inlet_diameter_m"], where + "/inlet_diameter_m");
    v.throat_diameter_m = positive(node["throat_diameter_m"], where + "/throat_diameter_m");
    if (!(v.throat_diameter_m < v.inlet_diameter_m))
      throw fail(node["throat_diameter_m"], where + ": the throat must be narrower than the inlet");
    return v;
  }

  void parseOutputs(const YAML::Node& node) {
    if (!node.IsMap()) throw fail(node, "run: expected a map of run column: signal");
    for (const auto& kv : node) {
      const std::string column = kv.first.as<std::string>();
      if (!importRunColumns().count(column)) {
        std::string list;
        for (const auto& c : importRunColumns()) list += (list.empty() ? "" : ", ") + c.first;
        throw fail(kv.first, "run: unknown run column '" + column + "' (known: " + list + ")");
      }
      m_.outputs[column] = scalar<std::string>(kv.second, "run/" + column);
      output_line_[column] = kv.first;
    }
    if (!m_.outputs.count("p_gauge_pa")) throw fail(node, "run: missing key 'p_gauge_pa' (the measured pressure)");
    if (!m_.outputs.count("mdot_in_kg_s") && !m_.outputs.count("valve_cmd"))
      throw fail(node, "run: missing key 'mdot_in_kg_s' (a run without a flow meter needs valve_cmd instead)");
  }

  void parseCycles(const YAML::Node& node) {
    checkKeys(node, "cycles", {"signal", "cycles_per_run", "keep_typical"}, {"signal"});
    CycleSpec c;
    c.signal = scalar<std::string>(node["signal"], "cycles/signal");
    if (node["cycles_per_run"]) {
      const YAML::Node& n = node["cycles_per_run"];
      if (n.IsScalar() && n.Scalar() == "all") {
        c.cycles_per_run = 0;
      } else {
        c.cycles_per_run = scalar<int>(n, "cycles/cycles_per_run");
        if (c.cycles_per_run < 1) throw fail(n, "cycles/cycles_per_run: expected a whole number >= 1 or 'all'");
      }
    }
    if (node["keep_typical"]) {
      const YAML::Node& k = node["keep_typical"];
      checkKeys(k, "cycles/keep_typical", {"flow", "factor"}, {"flow", "factor"});
      TypicalCycles t;
      t.flow = scalar<std::string>(k["flow"], "cycles/keep_typical/flow");
      t.factor = finite(k["factor"], "cycles/keep_typical/factor");
      if (!(t.factor > 1.0))
        throw fail(k["factor"], "cycles/keep_typical/factor: must be > 1, got " + k["factor"].Scalar());
      c.keep_typical = t;
    }
    m_.cycles = c;
    cycles_node_ = node;
  }

  static bool isRole(const std::string& r) { return r == "fit" || r == "withheld"; }

  void parseRoles(const YAML::Node& node) {
    if (node.IsScalar()) {
      const std::string r = node.Scalar();
      if (r == "alternate") m_.roles.pattern = {"fit", "withheld"};
      else if (isRole(r)) m_.roles.pattern = {r};
      else if (r != "none")
        throw fail(node, "roles: expected alternate, fit, withheld, none, a list or a map, got '" + r + "'");
    } else if (node.IsSequence()) {
      if (node.size() == 0) throw fail(node, "roles: an empty list");
      for (const auto& r : node) {
        const std::string role = scalar<std::string>(r, "roles");
        if (!isRole(role)) throw fail(r, "roles: expected fit or withheld, got '" + role + "'");
        m_.roles.pattern.push_back(role);
      }
    } else if (node.IsMap()) {
      for (const auto& kv : node) {
        const std::string run = kv.first.as<std::string>();
        const std::string role = scalar<std::string>(kv.second, "roles/" + run);
        if (!isRole(role)) throw fail(kv.second, "roles/" + run + ": expected fit or withheld, got '" + role + "'");
        m_.roles.by_run[run] = role;
      }
    } else {
      throw fail(node, "roles: expected alternate, fit, withheld, none, a list or a map");
    }
  }

  void parseFiles(const YAML::Node& node) {
    if (!node.IsMap()) throw fail(node, "files: expected a map of log file name: {metadata key: value}");
    for (const auto& kv : node) {
      const std::string file = kv.first.as<std::string>();
      m_.file_metadata[file] = stringMap(kv.second, "files/" + file);
    }
  }

  const SignalSpec* signal(const std::string& name) const {
    for (const auto& s : m_.signals)
      if (s.name == name) return &s;
    return nullptr;
  }

  /// The quantity a signal delivers (mass flow for a venturi).
  Quantity quantityOf(const SignalSpec& s) const {
    return s.venturi ? Quantity::kMassFlow : findLogUnit(s.units[0])->quantity;
  }

  /// A signal named by another key: it exists, is read from a column, has one unit (`fixed`).
  const SignalSpec& columnSignal(const std::string& name, const std::string& key, int line, bool fixed) const {
    const SignalSpec* s = signal(name);
    const std::string at = m_.source + ":" + std::to_string(line) + ": ";
    if (!s) throw std::runtime_error(at + key + ": no signal named '" + name + "'");
    if (s->venturi)
      throw std::runtime_error(at + key + ": '" + name + "' is derived; name a signal read from a column");
    if (fixed && s->units.size() != 1)
      throw std::runtime_error(at + key + ": '" + name + "' has candidate units; name a signal with one unit");
    return *s;
  }

  void checkReferences() const {
    for (const auto& s : m_.signals) {
      const std::string where = "signals/" + s.name;
      if (s.detect) {
        const SignalSpec& ref = columnSignal(s.detect->reference, where + "/detect/reference", s.line, true);
        if (quantityOf(ref) != quantityOf(s))
          throw std::runtime_error(m_.source + ":" + std::to_string(s.line) + ": " + where + "/detect/reference: '" +
                                   ref.name + "' is a " + quantityName(quantityOf(ref)) + ", not a " +
                                   quantityName(quantityOf(s)));
        if (s.detect->at == "cycle_end" && !m_.cycles)
          throw std::runtime_error(m_.source + ":" + std::to_string(s.line) + ": " + where +
                                   "/detect/at: cycle_end needs a 'cycles' section (or use at: all)");
      }
      if (s.venturi) {
        for (const std::string* dp : {&s.venturi->forward_dp, &s.venturi->reverse_dp}) {
          if (dp->empty()) continue;
          const SignalSpec& d = columnSignal(*dp, where + "/venturi", s.line, false);
          if (quantityOf(d) != Quantity::kPressure)
            throw std::runtime_error(m_.source + ":" + std::to_string(s.line) + ": " + where + "/venturi: '" + d.name +
                                     "' is a " + quantityName(quantityOf(d)) + ", not a differential pressure");
        }
      }
    }
    for (const auto& [column, name] : m_.outputs) {
      const YAML::Node& key = output_line_.at(column);
      const SignalSpec* s = signal(name);
      if (!s) throw fail(key, "run/" + column + ": no signal named '" + name + "'");
      Quantity q = quantityOf(*s);
      if (q == Quantity::kVolumeFlow) q = Quantity::kMassFlow;  // converted with the gas density
      const Quantity want = importRunColumns().at(column);
      if (q != want)
        throw fail(key, "run/" + column + ": '" + name + "' is a " + quantityName(quantityOf(*s)) +
                            ", the column takes a " + quantityName(want));
    }
    if (m_.cycles && !signal(m_.cycles->signal))
      throw fail(cycles_node_["signal"], "cycles/signal: no signal named '" + m_.cycles->signal + "'");
    if (m_.cycles && signal(m_.cycles->signal)->venturi)
      throw fail(cycles_node_["signal"],
                 "cycles/signal: '" + m_.cycles->signal + "' is derived; name a setpoint column");
    if (m_.cycles && m_.cycles->keep_typical) {
      const YAML::Node& key = cycles_node_["keep_typical"]["flow"];
      const std::string& name = m_.cycles->keep_typical->flow;
      const SignalSpec* s = signal(name);
      if (!s) throw fail(key, "cycles/keep_typical/flow: no signal named '" + name + "'");
      const Quantity q = quantityOf(*s);
      if (q != Quantity::kVolumeFlow && q != Quantity::kMassFlow)
        throw fail(key, "cycles/keep_typical/flow: '" + name + "' is a " + quantityName(q) + ", not a flow");
    }
  }

  const std::string text_;
  ImportMapping m_;
  std::map<std::string, YAML::Node> output_line_;
  YAML::Node cycles_node_;
};

}  // namespace

std::optional<LogUnit> findLogUnit(const std::string& name) {
  for (const auto& u : unitTable())
    if (u.name == name) return u;
  return std::nullopt;
}

std::string logUnitNames() {
  std::string s;
  for (const auto& u : unitTable()) s += (s.empty() ? "" : ", ") + u.name;
  return s;
}

const std::map<std::string, Quantity>& importRunColumns() {
  static const std::map<std::string, Quantity> columns = {{"p_gauge_pa", Quantity::kPressure},
                                                          {"mdot_in_kg_s", Quantity::kMassFlow},
                                                          {"mdot_uncorrected_kg_s", Quantity::kMassFlow},
                                                          {"p_setpoint_gauge_pa", Quantity::kPressure},
                                                          {"h_m", Quantity::kLength},
                                                          {"load_n", Quantity::kForce},
                                                          {"valve_cmd", Quantity::kRatio},
                                                          {"p_supply_gauge_pa", Quantity::kPressure},
                                                          {"t_gas_k", Quantity::kTemperature}};
  return columns;
}

ImportMapping parseImportMapping(const std::string& yaml_text, const std::string& source) {
  return MappingParser(yaml_text, source).parse();
}

ImportMapping loadImportMapping(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open mapping file");
  std::stringstream text;
  text << in.rdbuf();
  return parseImportMapping(text.str(), path);
}

}  // namespace nursing_bed
