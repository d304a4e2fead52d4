#pragma once
// Recoverable faults travel as values: Result<T> holds a T or an Error whose message names the file, key or
// field at fault (the vk-bootstrap style). Exceptions are for start-up only; ring and frame code use this.
#include <string>
#include <utility>
#include <variant>

#include "texstream/common/contract.hpp"

namespace texstream {

enum class ErrorCode {
  kInvalidArgument,  // a bad value from a user (config key, command line)
  kNotFound,         // a file or key that is not there
  kIo,               // a read or write that failed
  kCorrupt,          // data that does not match its own header or checksum
  kUnsupported,      // a format or feature we do not handle
  kProtocol,         // a peer broke the shared-memory protocol
  kPeerDead,         // the other process is gone
  kTimeout,
  kUnavailable,  // a storage origin that does not answer now (refused, reset, 502/503/504): try later
  kVulkan,
  kResourceExhausted,  // a bounded pool or budget is full
  kNotAFile,           // a path that names a FIFO, directory, socket or device where a regular file belongs
};

const char* to_string(ErrorCode code);

struct Error {
  ErrorCode code;
  std::string message;
};

template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor): mirrors std::expected
  Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & {
    TS_ASSERT(ok(), "Result::value() on an error: %s", std::get<1>(v_).message.c_str());
    return std::get<0>(v_);
  }
  const T& value() const& {
    TS_ASSERT(ok(), "Result::value() on an error: %s", std::get<1>(v_).message.c_str());
    return std::get<0>(v_);
  }
  T&& value() && {
    TS_ASSERT(ok(), "Result::value() on an error: %s", std::get<1>(v_).message.c_str());
    return std::get<0>(std::move(v_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const {
    TS_ASSERT(!ok(), "Result::error() on a value");
    return std::get<1>(v_);
  }

 private:
  std::variant<T, Error> v_;
};

// Result<void>: success or an Error.
struct Ok {};
using Status = Result<Ok>;
inline Status ok_status() { return Status(Ok{}); }

inline Error make_error(ErrorCode code, std::string message) { return Error{code, std::move(message)}; }

}  // namespace texstream

// Propagates an error from an expression returning Result<...> out of a function returning Result<...>.
#define TS_TRY(expr)                                         \
  do {                                                       \
    auto&& ts_try_result_ = (expr);                          \
    if (!ts_try_result_.ok()) return ts_try_result_.error(); \
  } while (0)
