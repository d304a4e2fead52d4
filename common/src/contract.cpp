#include "texstream/common/contract.hpp"

#include <cstdarg>

#include "texstream/common/result.hpp"

namespace texstream {

namespace detail {
void contract_failed(const char* file, int line, const char* condition, const char* fmt, ...) {
  std::fprintf(stderr, "texstream: contract violated at %s:%d: %s: ", file, line, condition);
  va_list args;
  va_start(args, fmt);
  std::vfprintf(stderr, fmt, args);
  va_end(args);
  std::fputc('\n', stderr);
  std::fflush(stderr);
  std::abort();
}
}  // namespace detail

const char* to_string(ErrorCode code) {
  switch (code) {
    case ErrorCode::kInvalidArgument:
      return "invalid argument";
    case ErrorCode::kNotFound:
      return "not found";
    case ErrorCode::kIo:
      return "i/o error";
    case ErrorCode::kCorrupt:
      return "corrupt";
    case ErrorCode::kUnsupported:
      return "unsupported";
    case ErrorCode::kProtocol:
      return "protocol violation";
    case ErrorCode::kPeerDead:
      return "peer dead";
    case ErrorCode::kTimeout:
      return "timeout";
    case ErrorCode::kUnavailable:
      return "unavailable";
    case ErrorCode::kVulkan:
      return "vulkan error";
    case ErrorCode::kResourceExhausted:
      return "resource exhausted";
    case ErrorCode::kNotAFile:
      return "not a file";
  }
  return "unknown";
}

}  // namespace texstream
