#include "nursing_bed/ros/airbag_hardware.h"

#include <pluginlib/class_loader.hpp>

#include <memory>
#include <mutex>
#include <sstream>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {
namespace {

/// Reads a string under `key` privately, else from the defaults namespace.
std::string layeredString(const ros::NodeHandle& pnh, const std::string& defaults_ns, const std::string& key,
                          const std::string& fallback) {
  std::string value;
  if (pnh.getParam(key, value)) return value;
  if (pnh.getParam(defaults_ns + "/" + key, value)) return value;
  return fallback;
}

pluginlib::ClassLoader<CellHardware>& hardwareLoader() {
  // One loader per process, never destroyed: plugins it made may outlive any static (a
  // destroyed loader unloads their library under them at exit).
  static auto* loader = new pluginlib::ClassLoader<CellHardware>("nursing_bed", "nursing_bed::CellHardware");
  return *loader;
}

}  // namespace

Status AirbagHardwareParams::validate() const {
  ErrorList errors;
  errors.addIf(plugin.empty(), "hardware/plugin is empty");
  errors.addIf(!simulated() && plugin == "nursing_bed/ModbusTcpHardware" && register_map.empty(),
               "hardware/register_map must name the register map YAML for nursing_bed/ModbusTcpHardware");
  errors.addNested(observer.validate(), "observer/: ");
  errors.addNested(gas_check.validate(), "observer/: ");
  errors.addNested(monitor.validate(), "observer/monitor_: ");
  try {
    effectsFromText(observer_effects, 1);
  } catch (const std::invalid_argument& e) {
    errors.add("observer/effects: ", e.what());
  }
  return errors.status();
}

AirbagHardwareParams AirbagHardwareParams::load(const ros::NodeHandle& pnh, const std::string& defaults_ns) {
  AirbagHardwareParams p;
  p.plugin = layeredString(pnh, defaults_ns, "hardware/plugin", p.plugin);
  p.register_map = layeredString(pnh, defaults_ns, "hardware/register_map", p.register_map);
  p.observer_cell_params = layeredString(pnh, defaults_ns, "observer/cell_params", p.observer_cell_params);
  p.observer_effects = layeredString(pnh, defaults_ns, "observer/effects", p.observer_effects);
  FlatParams values = layeredRosParams(pnh, defaults_ns, {"observer"});
  for (const char* text_key : {"observer/cell_params", "observer/effects"}) values.erase(text_key);
  values.erase("observer/force");
  if (!pnh.getParam("observer/force", p.observer_force))
    pnh.getParam(defaults_ns + "/observer/force", p.observer_force);
  applyObserverParams(values, "parameters of " + pnh.getNamespace(), &p.observer, &p.gas_check, &p.monitor,
                      "observer/");
  return p;
}

CellHardwarePtr loadCellHardware(const AirbagHardwareParams& params, const HardwareConfig& config) {
  static std::mutex mutex;
  std::lock_guard<std::mutex> lock(mutex);
  CellHardwarePtr hardware;
  try {
    hardware = hardwareLoader().createSharedInstance(params.plugin);
  } catch (const pluginlib::PluginlibException& e) {
    throw std::runtime_error("hardware/plugin '" + params.plugin + "' cannot be loaded: " + e.what());
  }
  hardware->configure(config);
  return hardware;
}

AirbagObserverSetup observerSetup(const AirbagHardwareParams& params, const CellParams& cell, std::uint32_t seed) {
  AirbagObserverSetup setup;
  setup.params = params.observer;
  setup.gas_check = params.gas_check;
  setup.monitor = params.monitor;
  setup.model = params.observer_cell_params.empty() ? cell : loadCellParamsYaml(params.observer_cell_params);
  setup.effects = effectsFromText(params.observer_effects, seed);
  setup.force = params.observer_force;
  return setup;
}

}  // namespace nursing_bed
