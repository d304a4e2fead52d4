#pragma once
// A shared-memory segment name no other test process or earlier test of this process uses. Header-only;
// included as "../support/unique_name.hpp".
#include <unistd.h>

#include <atomic>
#include <string>

namespace texstream::test {

inline std::string unique_name(const char* what) {
  static std::atomic<int> n{0};
  return "texstream-test-" + std::string(what) + "-" + std::to_string(::getpid()) + "-" + std::to_string(n++);
}

}  // namespace texstream::test
