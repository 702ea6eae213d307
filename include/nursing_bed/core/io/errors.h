// Collects the problems a validate() finds and joins them with "; " into one message, so that a
// caller reports every problem of a configuration at once.
#pragma once

#include <sstream>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

class ErrorList {
 public:
  /// One problem, its parts streamed as an std::ostream writes them (numbers in its default
  /// format), e.g. add("face_side_m must be positive, got ", value).
  template <typename... Parts>
  void add(const Parts&... parts) {
    std::ostringstream s;
    (s << ... << parts);
    errors_.push_back(s.str());
  }
  /// add(parts...) when `bad`.
  template <typename... Parts>
  void addIf(bool bad, const Parts&... parts) {
    if (bad) add(parts...);
  }
  /// A nested check's problems as one entry, prefixed with `prefix` ("material: ..."); nothing
  /// when the nested check passed.
  void addNested(const Status& nested, const std::string& prefix = "") {
    if (!nested.ok()) errors_.push_back(prefix + nested.message());
  }
  /// The same for a nested check that still reports an empty string for success.
  void addNested(const std::string& nested_error, const std::string& prefix = "") {
    if (!nested_error.empty()) errors_.push_back(prefix + nested_error);
  }

  bool ok() const { return errors_.empty(); }
  /// The problems joined with "; " (empty when there are none).
  std::string text() const;
  /// Success, or an error with text().
  Status status() const { return ok() ? Status::success() : Status::error(text()); }

 private:
  std::vector<std::string> errors_;
};

}  // namespace nursing_bed
