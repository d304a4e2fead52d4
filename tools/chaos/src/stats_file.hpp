#pragma once
// The `key value` lines StreamClient writes to $TEXSTREAM_STREAM_STATS (StreamClient::stats_text).
#include <filesystem>
#include <map>
#include <string>

#include "texstream/common/result.hpp"

namespace texstream::chaos {

struct StatsFile {
  std::map<std::string, std::string> values;
  static Result<StatsFile> load(const std::filesystem::path& file);
  // A number, or `fallback` when the key is absent or not a number.
  double number(const std::string& key, double fallback = 0.0) const;
};

}  // namespace texstream::chaos
