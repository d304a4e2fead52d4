#include "stats_file.hpp"

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace texstream::chaos {

Result<StatsFile> StatsFile::load(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return make_error(ErrorCode::kNotFound, "no stream statistics file '" + file.string() + "'");
  StatsFile s;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream l(line);
    std::string k, v;
    if (l >> k >> v) s.values[k] = v;
  }
  return s;
}

double StatsFile::number(const std::string& key, double fallback) const {
  const auto it = values.find(key);
  if (it == values.end()) return fallback;
  char* end = nullptr;
  const double v = std::strtod(it->second.c_str(), &end);
  return (end && *end == '\0') ? v : fallback;
}

}  // namespace texstream::chaos
