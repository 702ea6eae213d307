#include "nursing_bed/core/hardware/register_map.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/hardware/thread_priority.h"
#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
namespace {

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw std::runtime_error(where + ": " + what);
}

void checkKeys(const YAML::Node& node, const std::set<std::string>& allowed, const std::string& where) {
  if (!node.IsMap()) fail(where, "must be a map");
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (!allowed.count(key)) fail(where, "unknown key '" + key + "'");
  }
}

template <typename T>
T get(const YAML::Node& node, const std::string& key, const std::string& where, const T& fallback) {
  if (!node[key]) return fallback;
  try {
    return node[key].as<T>();
  } catch (const YAML::Exception&) {
    fail(where + "." + key, "not a valid value: '" + YAML::Dump(node[key]) + "'");
  }
}

template <typename T>
T require(const YAML::Node& node, const std::string& key, const std::string& where) {
  if (!node[key]) fail(where, "missing '" + key + "'");
  return get<T>(node, key, where, T{});
}

ValveOutput readValve(const YAML::Node& node, const std::string& where) {
  checkKeys(node, {"coil", "holding_register", "full_scale"}, where);
  ValveOutput v;
  if (node["coil"] && node["holding_register"]) fail(where, "either 'coil' or 'holding_register', not both");
  if (node["coil"]) {
    v.kind = ValveOutput::kCoil;
    v.address = require<int>(node, "coil", where);
  } else {
    v.kind = ValveOutput::kHoldingRegister;
    v.address = require<int>(node, "holding_register", where);
    v.full_scale = get<double>(node, "full_scale", where, v.full_scale);
  }
  return v;
}

/// An input {input_register, scale_<unit>, offset_<unit>}.
AnalogInput readInput(const YAML::Node& node, const std::string& unit, const std::string& where) {
  checkKeys(node, {"input_register", "scale_" + unit, "offset_" + unit}, where);
  AnalogInput in;
  in.address = require<int>(node, "input_register", where);
  in.scale = require<double>(node, "scale_" + unit, where);
  in.offset = get<double>(node, "offset_" + unit, where, 0.0);
  return in;
}

CellRegisters readCell(const YAML::Node& node, const std::string& where) {
  checkKeys(node, {"cell", "inlet", "vent", "pressure", "height", "inflow"}, where);
  CellRegisters c;
  c.cell_id = require<std::uint32_t>(node, "cell", where);
  const std::string at = where + " (cell " + std::to_string(c.cell_id) + ")";
  if (!node["inlet"] || !node["vent"]) fail(at, "needs both 'inlet' and 'vent' valves");
  if (!node["pressure"]) fail(at, "needs a 'pressure' input");
  c.inlet = readValve(node["inlet"], at + ".inlet");
  c.vent = readValve(node["vent"], at + ".vent");
  c.pressure_pa = readInput(node["pressure"], "pa", at + ".pressure");
  if (node["height"]) c.height_m = readInput(node["height"], "m", at + ".height");
  if (node["inflow"]) c.inflow_kg_s = readInput(node["inflow"], "kg_s", at + ".inflow");
  return c;
}

/// cell_block: `count` cells from `first_cell`, consecutive addresses from each `*_start`.
std::vector<CellRegisters> readBlock(const YAML::Node& node, const std::string& where) {
  checkKeys(node,
            {"first_cell", "count", "valves", "inlet_start", "vent_start", "valve_full_scale", "pressure_start",
             "pressure_scale_pa", "pressure_offset_pa", "height_start", "height_scale_m", "height_offset_m"},
            where);
  const auto first = require<std::uint32_t>(node, "first_cell", where);
  const int count = require<int>(node, "count", where);
  if (count < 1 || count > 10000) fail(where + ".count", "must lie in 1..10000");
  const std::string kind = get<std::string>(node, "valves", where, "coil");
  if (kind != "coil" && kind != "holding_register")
    fail(where + ".valves", "must be 'coil' or 'holding_register', got '" + kind + "'");
  CellRegisters proto;
  proto.inlet.kind = proto.vent.kind = kind == "coil" ? ValveOutput::kCoil : ValveOutput::kHoldingRegister;
  proto.inlet.full_scale = proto.vent.full_scale = get<double>(node, "valve_full_scale", where, 1000.0);
  proto.pressure_pa.scale = require<double>(node, "pressure_scale_pa", where);
  proto.pressure_pa.offset = get<double>(node, "pressure_offset_pa", where, 0.0);
  proto.height_m.scale = get<double>(node, "height_scale_m", where, 1e-5);
  proto.height_m.offset = get<double>(node, "height_offset_m", where, 0.0);
  const int inlet = require<int>(node, "inlet_start", where), vent = require<int>(node, "vent_start", where);
  const int pressure = require<int>(node, "pressure_start", where);
  const int height = get<int>(node, "height_start", where, -1);
  std::vector<CellRegisters> cells;
  for (int k = 0; k < count; ++k) {
    CellRegisters c = proto;
    c.cell_id = first + static_cast<std::uint32_t>(k);
    c.inlet.address = inlet + k;
    c.vent.address = vent + k;
    c.pressure_pa.address = pressure + k;
    c.height_m.address = height >= 0 ? height + k : -1;
    cells.push_back(c);
  }
  return cells;
}

TerminalMap readTerminal(const YAML::Node& node, const std::string& where) {
  checkKeys(node,
            {"name", "host", "port", "unit_id", "response_timeout_s", "link_loss_after_s", "reconnect_interval_s",
             "watchdog_s", "cycle_s", "stale_after_s", "realtime_priority", "supply_pressure", "cell_block", "cells"},
            where);
  TerminalMap t;
  t.name = get<std::string>(node, "name", where, where);
  const std::string at = where + " (" + t.name + ")";
  t.host = require<std::string>(node, "host", at);
  t.port = require<int>(node, "port", at);
  t.unit_id = get<int>(node, "unit_id", at, t.unit_id);
  t.response_timeout_s = get<double>(node, "response_timeout_s", at, t.response_timeout_s);
  t.link_loss_after_s = get<double>(node, "link_loss_after_s", at, t.link_loss_after_s);
  t.reconnect_interval_s = get<double>(node, "reconnect_interval_s", at, t.reconnect_interval_s);
  t.watchdog_s = get<double>(node, "watchdog_s", at, t.watchdog_s);
  t.cycle_s = get<double>(node, "cycle_s", at, t.cycle_s);
  t.stale_after_s = get<double>(node, "stale_after_s", at, t.stale_after_s);
  t.realtime_priority = get<int>(node, "realtime_priority", at, t.realtime_priority);
  if (node["supply_pressure"]) t.supply_pressure_pa = readInput(node["supply_pressure"], "pa", at + ".supply_pressure");
  if (node["cell_block"]) t.cells = readBlock(node["cell_block"], at + ".cell_block");
  if (node["cells"]) {
    if (!node["cells"].IsSequence()) fail(at + ".cells", "must be a list");
    for (std::size_t i = 0; i < node["cells"].size(); ++i)
      t.cells.push_back(readCell(node["cells"][i], at + ".cells[" + std::to_string(i) + "]"));
  }
  return t;
}

// --- validation ------------------------------------------------------------------------------

constexpr double kMaxLinkLossAfterS = 0.4;  ///< [s]
constexpr double kFaultReportS = 0.5;       ///< a silent terminal's cells report a fault within this [s]

/// link_loss_after_s against the request timing: one unanswered request tolerated, a silent
/// terminal reported within kFaultReportS.
void checkLinkLoss(const TerminalMap& t, const std::string& at, ErrorList& err) {
  const double l = t.link_loss_after_s, request_s = t.response_timeout_s + t.cycle_s;
  if (!(l > 0.0 && l <= kMaxLinkLossAfterS)) {
    err.add(at, ": link_loss_after_s ", l, " must lie in (0, ", kMaxLinkLossAfterS, "] s");
  } else if (!(l > request_s)) {
    err.add(at, ": link_loss_after_s ", l, " must exceed response_timeout_s + cycle_s (", request_s,
            " s), or one unanswered request takes the link down");
  } else if (l + request_s > kFaultReportS) {
    err.add(at, ": link_loss_after_s + response_timeout_s + cycle_s (", l + request_s, " s) must not exceed ",
            kFaultReportS, " s, the time in which a silent terminal is reported");
  }
}

void checkTerminalValues(const TerminalMap& t, ErrorList& err) {
  const std::string at = "terminal '" + t.name + "'";
  if (t.host.empty()) err.add(at, ": host is empty");
  if (t.port < 1 || t.port > 65535) err.add(at, ": port ", t.port, " not in 1..65535");
  if (t.unit_id < 0 || t.unit_id > 247) err.add(at, ": unit_id ", t.unit_id, " not in 0..247");
  if (!(t.response_timeout_s > 0.0 && t.response_timeout_s <= 1.0))
    err.add(at, ": response_timeout_s must lie in (0, 1] s");
  if (!(t.reconnect_interval_s > 0.0)) err.add(at, ": reconnect_interval_s must be > 0");
  if (!(t.cycle_s > 0.0 && t.cycle_s <= 0.1)) err.add(at, ": cycle_s must lie in (0, 0.1] s");
  if (!(t.stale_after_s > t.cycle_s)) err.add(at, ": stale_after_s must exceed cycle_s");
  if (!(t.watchdog_s > t.cycle_s && t.watchdog_s <= 60.0))
    err.add(at, ": watchdog_s ", t.watchdog_s, " must exceed cycle_s and be at most 60 s");
  const Status priority = checkRealtimePriority(t.realtime_priority);
  if (!priority) err.add(at, ": realtime_priority ", t.realtime_priority, " ", priority.message());
  checkLinkLoss(t, at, err);
  if (t.cells.empty()) err.add(at, ": serves no cells");
}

void checkInput(const AnalogInput& in, const std::string& at, ErrorList& err) {
  if (!in.present()) return;
  if (!(std::isfinite(in.scale) && in.scale != 0.0)) err.add(at, ": scale ", in.scale, " must be finite and non-zero");
  if (!std::isfinite(in.offset)) err.add(at, ": offset must be finite");
  if (in.address > 65535) err.add(at, ": address ", in.address, " not in 0..65535");
}

void checkValve(const ValveOutput& v, const std::string& at, ErrorList& err) {
  if (v.address < 0 || v.address > 65535) err.add(at, ": address ", v.address, " not in 0..65535");
  if (v.kind == ValveOutput::kHoldingRegister && !(v.full_scale >= 1.0 && v.full_scale <= 65535.0))
    err.add(at, ": full_scale ", v.full_scale, " must lie in [1, 65535]");
}

/// Every address of one space (coils, holding or input registers) used once per terminal.
class AddressBook {
 public:
  void use(int address, const std::string& who, ErrorList& err) {
    if (address < 0) return;
    const auto it = users_.find(address);
    if (it != users_.end()) {
      err.add(who, " uses address ", address, ", already used by ", it->second);
      return;
    }
    users_[address] = who;
  }

 private:
  std::map<int, std::string> users_;
};

void checkTerminalCells(const TerminalMap& t, ErrorList& err) {
  AddressBook coils, holding, inputs;
  auto output = [&](const ValveOutput& v, const std::string& who) {
    (v.kind == ValveOutput::kCoil ? coils : holding)
        .use(v.address, who + " (" + (v.kind == ValveOutput::kCoil ? "coil" : "holding register") + ")", err);
  };
  if (t.supply_pressure_pa.present()) {
    checkInput(t.supply_pressure_pa, "terminal '" + t.name + "' supply_pressure", err);
    inputs.use(t.supply_pressure_pa.address, "terminal '" + t.name + "' supply_pressure", err);
  }
  for (const CellRegisters& c : t.cells) {
    const std::string at = "terminal '" + t.name + "' cell " + std::to_string(c.cell_id);
    checkValve(c.inlet, at + " inlet", err);
    checkValve(c.vent, at + " vent", err);
    output(c.inlet, at + " inlet");
    output(c.vent, at + " vent");
    if (!c.pressure_pa.present()) err.add(at, ": no pressure input");
    const std::pair<const AnalogInput*, const char*> ins[] = {
        {&c.pressure_pa, " pressure"}, {&c.height_m, " height"}, {&c.inflow_kg_s, " inflow"}};
    for (const auto& in : ins) {
      checkInput(*in.first, at + in.second, err);
      inputs.use(in.first->address, at + in.second, err);
    }
  }
}

void checkCellCoverage(const RegisterMap& map, std::uint32_t expected_cells, ErrorList& err) {
  std::map<std::uint32_t, std::string> served;
  std::set<std::string> endpoints;
  for (const TerminalMap& t : map.terminals) {
    if (!endpoints.insert(t.endpoint()).second)
      err.add("terminal '", t.name, "': ", t.endpoint(), " is used by another terminal");
    for (const CellRegisters& c : t.cells) {
      if (expected_cells > 0 && c.cell_id >= expected_cells)
        err.add("terminal '", t.name, "' cell ", c.cell_id, ": not in the bed (cells 0..", expected_cells - 1, ")");
      const auto it = served.find(c.cell_id);
      if (it != served.end())
        err.add("cell ", c.cell_id, " is mapped twice (terminals '", it->second, "' and '", t.name, "')");
      served.emplace(c.cell_id, t.name);
    }
  }
  int missing = 0;
  for (std::uint32_t id = 0; id < expected_cells; ++id) {
    if (served.count(id)) continue;
    if (++missing <= 5) err.add("cell ", id, " is missing from the register map");
  }
  if (missing > 5) err.add("(", missing, " cells missing in all)");
}

}  // namespace

std::uint16_t AnalogInput::toCount(double value) const {
  const double count = std::round((value - offset) / scale);
  return static_cast<std::uint16_t>(std::clamp(count, 0.0, 65535.0));
}

bool RegisterMap::find(std::uint32_t cell_id, std::size_t* terminal, std::size_t* slot) const {
  for (std::size_t t = 0; t < terminals.size(); ++t) {
    for (std::size_t s = 0; s < terminals[t].cells.size(); ++s) {
      if (terminals[t].cells[s].cell_id != cell_id) continue;
      *terminal = t;
      *slot = s;
      return true;
    }
  }
  return false;
}

Status validateRegisterMap(const RegisterMap& map, std::uint32_t expected_cells) {
  ErrorList err;
  if (map.terminals.empty()) err.add("no terminals");
  for (const TerminalMap& t : map.terminals) {
    checkTerminalValues(t, err);
    checkTerminalCells(t, err);
  }
  checkCellCoverage(map, expected_cells, err);
  return err.status();
}

RegisterMap parseRegisterMap(const std::string& yaml_text, const std::string& source, std::uint32_t expected_cells) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    fail(source, std::string("not valid YAML: ") + e.what());
  }
  checkKeys(root, {"terminals"}, source);
  const YAML::Node terminals = root["terminals"];
  if (!terminals || !terminals.IsSequence()) fail(source, "'terminals' must be a list");
  RegisterMap map;
  for (std::size_t i = 0; i < terminals.size(); ++i)
    map.terminals.push_back(readTerminal(terminals[i], source + ": terminals[" + std::to_string(i) + "]"));
  const Status valid = validateRegisterMap(map, expected_cells);
  if (!valid) fail(source, "bad register map: " + valid.message());
  return map;
}

RegisterMap loadRegisterMap(const std::string& path, std::uint32_t expected_cells) {
  std::ifstream file(path);
  if (!file) throw std::runtime_error("register map '" + path + "' cannot be read");
  std::stringstream text;
  text << file.rdbuf();
  return parseRegisterMap(text.str(), path, expected_cells);
}

}  // namespace nursing_bed
