#pragma once
// A folder of its own for each unit test: <tmp>/<prefix>_<pid>_<test name>, emptied first (a crashed earlier
// run may have left it), so tests that run in parallel processes or one after another never share files.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace texstream::test {

// Removes whatever is there; creates the folder when `create` (some code under test must create it itself).
inline std::filesystem::path fresh_test_dir(const std::string& prefix, bool create = true) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / (prefix + "_" + std::to_string(::getpid()) + "_" +
                                                ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::remove_all(dir);
  if (create) std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace texstream::test
