// A value or the reason there is none. Estimators return this instead of throwing or producing
// NaN, so that a process can count the rejection and carry on (C++20 has no std::expected).
#pragma once

#include <optional>
#include <string>
#include <utility>

namespace rcal::estimation {

template <class T>
class Result {
 public:
  Result(T value) : value_(std::move(value)) {}  // NOLINT: implicit on purpose
  static Result Error(std::string reason) {
    Result r;
    r.error_ = std::move(reason);
    return r;
  }
  bool ok() const { return value_.has_value(); }
  explicit operator bool() const { return ok(); }
  /// The value. Precondition: ok().
  const T& value() const { return *value_; }
  const T& operator*() const { return *value_; }
  const T* operator->() const { return &*value_; }
  /// Why there is no value (names the offending field); empty when ok().
  const std::string& error() const { return error_; }

 private:
  Result() = default;
  std::optional<T> value_;
  std::string error_;
};

/// Result of an operation that yields no value: ok, or the reason it was refused.
class Status {
 public:
  static Status Ok() { return Status(); }
  static Status Error(std::string reason) {
    Status s;
    s.error_ = std::move(reason);
    return s;
  }
  bool ok() const { return error_.empty(); }
  explicit operator bool() const { return ok(); }
  const std::string& error() const { return error_; }

 private:
  std::string error_;
};

}  // namespace rcal::estimation
