#include "nursing_bed/core/io/param_table.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace {

void flattenInto(const YAML::Node& node, const std::string& prefix, const std::string& source, FlatParams* out) {
  for (const auto& entry : node) {
    const std::string key = prefix + entry.first.as<std::string>();
    const YAML::Node& value = entry.second;
    if (value.IsMap()) {
      flattenInto(value, key + "/", source, out);
    } else if (value.IsScalar()) {
      FlatValue v;
      v.text = value.Scalar();
      try {
        v.value = value.as<double>();
        v.numeric = std::isfinite(v.value);
      } catch (const YAML::Exception&) {
        v.numeric = false;
      }
      (*out)[key] = v;
    } else {
      throwParamError(source, key, "must be a number or a map of parameters");
    }
  }
}

}  // namespace

void throwParamError(const std::string& source, const std::string& key, const std::string& what) {
  throw std::runtime_error(source + ": parameter '" + key + "' " + what);
}

void throwUnknownParam(const std::string& source, const std::string& key) {
  throw std::runtime_error(source + ": unknown parameter '" + key + "' (a typo? see the documented keys)");
}

bool isWholeNumber(double value) { return value == std::floor(value); }

std::string formatParamValue(double value) {
  // Written for YAML 1.1 readers too (rosparam, PyYAML): a float there needs a '.', so 5e-06
  // would be read back as a string (sim.launch refused a calibrated file for it); infinities
  // and NaN have their own spelling.
  if (std::isnan(value)) return ".nan";
  if (std::isinf(value)) return value > 0.0 ? ".inf" : "-.inf";
  std::ostringstream s;
  s.precision(10);
  s << value;
  std::string text = s.str();
  const std::size_t e = text.find_first_of("eE");
  if (e != std::string::npos && text.find('.') == std::string::npos) text.insert(e, ".0");
  return text;
}

std::string emitParamsYaml(const std::vector<YamlParamLine>& lines) {
  if (lines.empty()) return "";
  YAML::Emitter e;
  e << YAML::BeginMap;
  std::vector<std::string> open_groups;
  for (const YamlParamLine& line : lines) {
    std::vector<std::string> groups;
    std::size_t start = 0, slash;
    while ((slash = line.key.find('/', start)) != std::string::npos) {
      groups.push_back(line.key.substr(start, slash - start));
      start = slash + 1;
    }
    std::size_t common = 0;
    while (common < groups.size() && common < open_groups.size() && groups[common] == open_groups[common]) ++common;
    for (; open_groups.size() > common; open_groups.pop_back()) e << YAML::EndMap;
    for (std::size_t i = common; i < groups.size(); ++i) {
      e << YAML::Key << groups[i] << YAML::Value << YAML::BeginMap;
      open_groups.push_back(groups[i]);
    }
    // The value goes as its text so that it keeps formatParamValue's YAML 1.1 spelling.
    e << YAML::Key << line.key.substr(start) << YAML::Value << formatParamValue(line.value)
      << YAML::Comment(line.description);
  }
  for (; !open_groups.empty(); open_groups.pop_back()) e << YAML::EndMap;
  e << YAML::EndMap;
  return std::string(e.c_str()) + "\n";
}

FlatParams flattenYaml(const YAML::Node& root, const std::string& source) {
  FlatParams out;
  if (root.IsNull()) return out;
  if (!root.IsMap()) throw std::runtime_error(source + ": expected a map of parameter groups at the top level");
  flattenInto(root, "", source, &out);
  return out;
}

FlatParams flattenYamlText(const std::string& yaml_text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(source + ": YAML syntax error: " + e.what());
  }
  return flattenYaml(root, source);
}

FlatParams flattenYamlFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open parameter file");
  std::stringstream text;
  text << in.rdbuf();
  return flattenYamlText(text.str(), path);
}

}  // namespace nursing_bed
