#include "nursing_bed/ros/ros_params.h"

#include <XmlRpcValue.h>

#include <stdexcept>

namespace nursing_bed {
namespace {

void flattenInto(XmlRpc::XmlRpcValue& value, const std::string& key, const std::string& source, FlatParams* out) {
  switch (value.getType()) {
    case XmlRpc::XmlRpcValue::TypeStruct:
      for (auto it = value.begin(); it != value.end(); ++it)
        flattenInto(it->second, key.empty() ? it->first : key + "/" + it->first, source, out);
      break;
    case XmlRpc::XmlRpcValue::TypeDouble: {
      FlatValue v;
      v.numeric = true;
      v.value = static_cast<double>(value);
      v.text = std::to_string(v.value);
      (*out)[key] = v;
      break;
    }
    case XmlRpc::XmlRpcValue::TypeInt: {
      FlatValue v;
      v.numeric = true;
      v.value = static_cast<int>(value);
      v.text = std::to_string(static_cast<int>(value));
      (*out)[key] = v;
      break;
    }
    case XmlRpc::XmlRpcValue::TypeString: {
      FlatValue v;
      v.text = static_cast<std::string>(value);
      (*out)[key] = v;
      break;
    }
    default: throw std::runtime_error(source + ": parameter '" + key + "' must be a number or a map of parameters");
  }
}

}  // namespace

FlatParams flattenRosParams(const ros::NodeHandle& nh, const std::string& ns) {
  FlatParams out;
  XmlRpc::XmlRpcValue tree;
  if (!nh.getParam(ns, tree)) return out;
  const std::string source = "parameter server " + nh.resolveName(ns);
  if (tree.getType() != XmlRpc::XmlRpcValue::TypeStruct)
    throw std::runtime_error(source + ": expected a map of parameters");
  flattenInto(tree, "", source, &out);
  return out;
}

FlatParams layeredRosParams(const ros::NodeHandle& private_nh, const std::string& defaults_ns,
                            const std::vector<std::string>& sections) {
  FlatParams merged;
  for (const ros::NodeHandle* nh_ns : {static_cast<const ros::NodeHandle*>(nullptr), &private_nh}) {
    for (const std::string& section : sections) {
      const FlatParams values =
          nh_ns ? flattenRosParams(*nh_ns, section) : flattenRosParams(private_nh, defaults_ns + "/" + section);
      for (const auto& [key, v] : values) merged[section + "/" + key] = v;
    }
  }
  return merged;
}

}  // namespace nursing_bed
