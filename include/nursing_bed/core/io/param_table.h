// Parameter tables: every scalar parameter of a Params struct as (key, meaning with unit, get,
// set). One table serves the YAML files, the ROS parameter server and the docs, so all accept
// exactly the same keys, and a mistyped key is an error instead of a silently ignored value.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace YAML {
class Node;
}

namespace nursing_bed {

template <typename Params>
struct ParamField {
  std::string key;          ///< "group/name_unit", e.g. "structure/film_thickness_m"
  std::string description;  ///< meaning and unit
  bool integer = false;     ///< must be a whole number
  std::function<double(const Params&)> get;
  std::function<void(Params&, double)> set;
};

template <typename Params>
using ParamTable = std::vector<ParamField<Params>>;

/// A field read and written through `member`, a function returning a reference into Params.
template <typename Params, typename Member>
ParamField<Params> realField(const std::string& key, const std::string& description, Member member) {
  ParamField<Params> f;
  f.key = key;
  f.description = description;
  // The member accessor is non-const so that one lambda serves both directions.
  f.get = [member](const Params& p) { return static_cast<double>(member(const_cast<Params&>(p))); };
  f.set = [member](Params& p, double v) { member(p) = v; };
  return f;
}

/// Same for an integer member (whole numbers only).
template <typename Params, typename Member>
ParamField<Params> integerField(const std::string& key, const std::string& description, Member member) {
  ParamField<Params> f = realField<Params>(key, description, member);
  f.integer = true;
  f.set = [member](Params& p, double v) { member(p) = static_cast<int>(v); };
  return f;
}

/// The table of a nested struct, its keys prefixed, reached through `member`.
template <typename Outer, typename Inner, typename Member>
void appendNested(ParamTable<Outer>* outer, const ParamTable<Inner>& inner, const std::string& prefix, Member member) {
  for (const auto& f : inner) {
    ParamField<Outer> g;
    g.key = prefix + f.key;
    g.description = f.description;
    g.integer = f.integer;
    g.get = [get = f.get, member](const Outer& o) { return get(member(const_cast<Outer&>(o))); };
    g.set = [set = f.set, member](Outer& o, double v) { set(member(o), v); };
    outer->push_back(g);
  }
}

/// A scalar leaf of a parameter tree, flattened to a "a/b/c" key.
struct FlatValue {
  bool numeric = false;
  double value = 0.0;
  std::string text;  ///< the value as written, for messages
};
using FlatParams = std::map<std::string, FlatValue>;

/// Flattens a YAML map tree to "a/b/c" keys; throws std::runtime_error naming `source` and the
/// key when a leaf is not a scalar.
FlatParams flattenYaml(const YAML::Node& root, const std::string& source);
/// Parses YAML text and flattens it; throws on syntax errors (naming `source`).
FlatParams flattenYamlText(const std::string& yaml_text, const std::string& source);
/// Reads and flattens a YAML file; throws when it cannot be read or parsed.
FlatParams flattenYamlFile(const std::string& path);

/// Applies the values whose keys start with `prefix` (which is stripped) onto `params`. Throws
/// std::runtime_error naming `source` and the key for an unknown key, a non-numeric value or a
/// fractional value of an integer parameter. Keys outside `prefix` are ignored.
template <typename Params>
void applyFlatParams(const FlatParams& values, const std::string& source, const ParamTable<Params>& table,
                     Params* params, const std::string& prefix = "");

/// "key: value  # description" lines, grouped as YAML maps.
template <typename Params>
std::string paramsToYaml(const Params& params, const ParamTable<Params>& table);

// ---- implementation --------------------------------------------------------------------------

/// Throw the standard errors for a value or key that the table rejects.
[[noreturn]] void throwParamError(const std::string& source, const std::string& key, const std::string& what);
[[noreturn]] void throwUnknownParam(const std::string& source, const std::string& key);
bool isWholeNumber(double value);
std::string formatParamValue(double value);

/// One "key: value  # description" line of paramsToYaml; "a/b/c" keys become nested maps
/// (lines of one group must be adjacent).
struct YamlParamLine {
  std::string key;
  double value = 0.0;
  std::string description;
};
/// The lines as YAML (yaml-cpp's emitter), values in formatParamValue's spelling.
std::string emitParamsYaml(const std::vector<YamlParamLine>& lines);

template <typename Params>
void applyFlatParams(const FlatParams& values, const std::string& source, const ParamTable<Params>& table,
                     Params* params, const std::string& prefix) {
  std::map<std::string, const ParamField<Params>*> by_key;
  for (const auto& f : table) by_key[f.key] = &f;
  for (const auto& [full_key, v] : values) {
    if (full_key.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string key = full_key.substr(prefix.size());
    const auto it = by_key.find(key);
    if (it == by_key.end()) throwUnknownParam(source, full_key);
    if (!v.numeric) throwParamError(source, full_key, "must be a number, got '" + v.text + "'");
    if (it->second->integer && !isWholeNumber(v.value)) throwParamError(source, full_key, "must be a whole number");
    it->second->set(*params, v.value);
  }
}

template <typename Params>
std::string paramsToYaml(const Params& params, const ParamTable<Params>& table) {
  std::vector<YamlParamLine> lines;
  for (const auto& f : table) lines.push_back({f.key, f.get(params), f.description});
  return emitParamsYaml(lines);
}

}  // namespace nursing_bed
