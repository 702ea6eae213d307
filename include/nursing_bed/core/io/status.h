// The result of an operation that either succeeds or fails with a message: what validate() and
// similar checks return instead of a string that is empty on success.
#pragma once

#include <string>
#include <utility>

namespace nursing_bed {

class Status {
 public:
  /// Success (no message).
  static Status success() { return Status(); }
  /// Failure with `message`, which names what is wrong (an empty message still fails).
  static Status error(std::string message) {
    Status s;
    s.ok_ = false;
    s.message_ = std::move(message);
    return s;
  }

  /// Success when `message` is empty, else an error with it: for checks that still report an
  /// empty string for success.
  static Status fromMessage(std::string message) { return message.empty() ? success() : error(std::move(message)); }

  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  /// What is wrong; empty on success.
  const std::string& message() const { return message_; }

 private:
  Status() = default;
  bool ok_ = true;
  std::string message_;
};

}  // namespace nursing_bed
