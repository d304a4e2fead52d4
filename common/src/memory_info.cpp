#include "texstream/common/memory_info.hpp"

#include <sys/statvfs.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <vector>

namespace texstream {

uint64_t free_bytes_at(const std::filesystem::path& dir) {
  struct statvfs fs {};
  if (::statvfs(dir.c_str(), &fs) != 0) return UINT64_MAX;
  return uint64_t{fs.f_bavail} * fs.f_frsize;
}
namespace {

constexpr uint64_t kUnknown = std::numeric_limits<uint64_t>::max();
// v1 reports "no limit" as INT64_MAX rounded down to a page; anything this large is no limit.
constexpr uint64_t kNoLimitAbove = 1ull << 60;

std::optional<std::string> read_text(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return std::nullopt;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::optional<uint64_t> parse_u64(const std::string& text) {
  size_t i = 0;
  while (i < text.size() && text[i] == ' ') ++i;
  if (i == text.size() || text[i] < '0' || text[i] > '9') return std::nullopt;
  uint64_t v = 0;
  for (; i < text.size() && text[i] >= '0' && text[i] <= '9'; ++i) {
    const uint64_t d = static_cast<uint64_t>(text[i] - '0');
    if (v > (kUnknown - d) / 10) return std::nullopt;  // overflow
    v = v * 10 + d;
  }
  return v;
}

// "name value" lines (memory.stat): the value of `name`, if present.
std::optional<uint64_t> stat_field(const std::string& text, const std::string& name) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.size() > name.size() && line.compare(0, name.size(), name) == 0 && line[name.size()] == ' ') {
      return parse_u64(line.substr(name.size() + 1));
    }
  }
  return std::nullopt;
}

struct CgroupFiles {
  std::filesystem::path mount;  // where this hierarchy is mounted
  const char* limit;
  const char* usage;
  const char* inactive_file;  // memory.stat field: page cache the kernel reclaims before it OOM-kills
};

// The limit and the room left of every level from `path` up to the hierarchy's root: the lowest of each.
void walk_cgroup(const CgroupFiles& f, std::filesystem::path path, MemoryInfo& m) {
  for (;;) {
    const std::filesystem::path dir = f.mount / path.relative_path();
    const auto text = read_text(dir / f.limit);
    if (const std::optional<uint64_t> limit = text ? cgroup_limit_bytes(*text) : std::nullopt) {
      if (*limit < m.limit) {
        m.limit = *limit;
        m.limit_source = "the memory cgroup limit in " + (dir / f.limit).string();
      }
      const auto usage_text = read_text(dir / f.usage);
      if (const std::optional<uint64_t> usage = usage_text ? parse_u64(*usage_text) : std::nullopt) {
        const auto stat = read_text(dir / "memory.stat");
        const uint64_t reclaimable = stat ? stat_field(*stat, f.inactive_file).value_or(0) : 0;
        const uint64_t used = *usage - std::min(*usage, reclaimable);
        m.available = std::min(m.available, *limit - std::min(*limit, used));
      }
    }
    if (path == path.root_path() || path.empty() || !path.has_relative_path()) break;
    path = path.parent_path();
  }
}

}  // namespace

std::optional<uint64_t> meminfo_bytes(const std::string& meminfo_text, const std::string& field) {
  std::istringstream in(meminfo_text);
  std::string line;
  const std::string key = field + ":";
  while (std::getline(in, line)) {
    if (line.compare(0, key.size(), key) != 0) continue;
    const std::optional<uint64_t> kb = parse_u64(line.substr(key.size()));
    if (!kb || line.find(" kB") == std::string::npos || *kb > kUnknown / 1024) return std::nullopt;
    return *kb * 1024;
  }
  return std::nullopt;
}

std::optional<uint64_t> cgroup_limit_bytes(const std::string& text) {
  const std::optional<uint64_t> v = parse_u64(text);
  if (!v || *v >= kNoLimitAbove) return std::nullopt;  // "max", malformed, or v1's "no limit"
  return v;
}

MemoryInfo read_memory_info(const std::filesystem::path& sys_root, const std::filesystem::path& proc_root) {
  MemoryInfo m;
  m.limit = kUnknown;
  m.available = kUnknown;
  if (const auto meminfo = read_text(proc_root / "meminfo")) {
    if (const auto total = meminfo_bytes(*meminfo, "MemTotal")) {
      m.limit = *total;
      m.limit_source = "physical memory, MemTotal in " + (proc_root / "meminfo").string();
    }
    if (const auto avail = meminfo_bytes(*meminfo, "MemAvailable")) m.available = *avail;
  }
  // /proc/self/cgroup: "0::/path" (v2) and "N:memory:/path" or "N:cpu,memory:/path" (v1).
  if (const auto cgroups = read_text(proc_root / "self" / "cgroup")) {
    std::istringstream in(*cgroups);
    std::string line;
    while (std::getline(in, line)) {
      const size_t a = line.find(':');
      const size_t b = a == std::string::npos ? a : line.find(':', a + 1);
      if (b == std::string::npos) continue;
      const std::string id = line.substr(0, a), controllers = line.substr(a + 1, b - a - 1);
      const std::filesystem::path path = line.substr(b + 1);
      if (id == "0" && controllers.empty()) {
        walk_cgroup({sys_root / "fs" / "cgroup", "memory.max", "memory.current", "inactive_file"}, path, m);
      } else if (("," + controllers + ",").find(",memory,") != std::string::npos) {
        walk_cgroup({sys_root / "fs" / "cgroup" / "memory", "memory.limit_in_bytes", "memory.usage_in_bytes",
                     "total_inactive_file"},
                    path, m);
      }
    }
  }
  m.available = std::min(m.available, m.limit);
  return m;
}

uint64_t server_memory_bytes(const Config& config) {
  // Auto slots (staging_slot_bytes = 0) count their smallest size here: the renderer checks again with the
  // scene's real slot size (StreamClient::start) before it starts a server.
  const StagingShape staging = effective_staging(config.protocol, 0);
  return static_cast<uint64_t>(config.server.ram_cache_bytes) + staging.slot_count * staging.slot_bytes +
         kServerOverheadBytes;
}

Status check_server_memory(const Config& config, const MemoryInfo& memory) {
  const uint64_t need = server_memory_bytes(config);
  if (memory.limit == kUnknown || need <= memory.limit) return ok_status();
  const StagingShape shape = effective_staging(config.protocol, 0);
  const uint64_t staging = shape.slot_count * shape.slot_bytes;
  return make_error(ErrorCode::kInvalidArgument,
                    "config: key 'server.ram_cache_bytes': the server needs " + std::to_string(need) +
                        " bytes (a RAM cache of " + std::to_string(config.server.ram_cache_bytes) +
                        " bytes, a staging pool of " + std::to_string(staging) + " and " +
                        std::to_string(kServerOverheadBytes >> 20) + " MiB of its own) but this machine allows " +
                        std::to_string(memory.limit) + " (" + memory.limit_source +
                        "); lower server.ram_cache_bytes: a server that cannot fit is OOM-killed again after every "
                        "restart");
}

uint64_t server_cache_budget(uint64_t configured, const MemoryInfo& memory, std::string* why) {
  if (memory.available == kUnknown) return configured;
  const uint64_t reserve = std::max<uint64_t>(256ull << 20, memory.limit == kUnknown ? 0 : memory.limit / 8);
  const uint64_t usable = memory.available > reserve ? memory.available - reserve : 0;
  if (configured <= usable) return configured;
  if (why) {
    *why = "server.ram_cache_bytes = " + std::to_string(configured) + " lowered to " + std::to_string(usable) +
           " bytes: " + std::to_string(memory.available) + " bytes are free now (" + memory.limit_source + " allows " +
           std::to_string(memory.limit) + "), less a reserve of " + std::to_string(reserve) +
           " for the renderer and everything else";
  }
  return usable;
}

}  // namespace texstream
