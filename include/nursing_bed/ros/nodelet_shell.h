// The nodelet shell shared by every nursing_bed node class: the same class runs as a node (a
// ~10-line main) and as a nodelet (this template).
#pragma once

#include <nodelet/nodelet.h>

#include <memory>

namespace nursing_bed {

/// Runs `Node` in a nodelet. A construction error is logged and leaves the nodelet inert
/// (throwing from onInit would take the whole manager, and every cell in it, down).
template <typename Node>
class NodeletShell : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      node_ = std::make_unique<Node>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      NODELET_FATAL("%s", e.what());
    }
  }
  std::unique_ptr<Node> node_;
};

}  // namespace nursing_bed
