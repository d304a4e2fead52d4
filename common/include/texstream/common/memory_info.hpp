#pragma once
// How much memory this process may use: physical memory, or a memory cgroup's limit where that is lower (a
// container started with --memory, a systemd slice), and how much of it is free now.
//
// Why the server needs it: the RAM cache pre-faults its whole budget at start (cache_arena.hpp). A budget
// larger than what the machine or the cgroup allows got the server OOM-killed about every 1.5 s, for ever:
// the renderer restarted it each time and drew the colormap (measured: a 3 GiB budget in a 1.5 GiB cgroup).
// check_server_memory() turns the impossible case into a configuration error naming the key, before the
// renderer spawns a server; server_cache_budget() keeps a budget that fits the limit but not what is free
// now from taking the last of it.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"

namespace texstream {

struct MemoryInfo {
  uint64_t limit = 0;  // bytes: the lower of MemTotal and every memory cgroup limit above this process
  std::string
      limit_source;  // what `limit` is, for messages: "physical memory, MemTotal in /proc/meminfo" or the cgroup file
  uint64_t available = 0;  // bytes free for new allocations now: MemAvailable, or the cgroup's room if lower
};

// /proc/meminfo and the memory cgroup (v2 memory.max / memory.current / memory.stat, or v1
// memory.limit_in_bytes / memory.usage_in_bytes / memory.stat) of each level from this process's cgroup up to
// the root. `sys_root` and `proc_root` are "/sys" and "/proc" except in tests. Files that are missing or
// unreadable are skipped; with nothing readable at all, limit and available are UINT64_MAX ("unknown").
MemoryInfo read_memory_info(const std::filesystem::path& sys_root = "/sys",
                            const std::filesystem::path& proc_root = "/proc");

// Free bytes of the file system at `dir` (shared-memory segments live in /dev/shm, a tmpfs that containers
// often mount at 64 MiB), UINT64_MAX when it cannot be read.
uint64_t free_bytes_at(const std::filesystem::path& dir = "/dev/shm");

// "MemTotal:  24576000 kB" → bytes; nullopt if the field is missing or malformed.
std::optional<uint64_t> meminfo_bytes(const std::string& meminfo_text, const std::string& field);
// A cgroup limit file's text ("max\n", "9223372036854771712\n", "1610612736\n") → bytes; nullopt for no limit
// (v2 "max", v1's page-rounded INT64_MAX) or malformed text.
std::optional<uint64_t> cgroup_limit_bytes(const std::string& text);

// Bytes the server needs besides what it maps from the renderer's process: its RAM cache budget, the staging
// pool (shared memory is charged to whoever touches it first, and the server writes every slot), and
// kServerOverheadBytes for everything else (code, heaps, queues; texstream-bench server's memory phase holds
// the server to the same allowance).
inline constexpr uint64_t kServerOverheadBytes = 64ull << 20;
uint64_t server_memory_bytes(const Config& config);

// An error naming server.ram_cache_bytes when server_memory_bytes(config) exceeds memory.limit: such a server
// can never run (it would be OOM-killed once its cache filled, and again after each restart).
Status check_server_memory(const Config& config, const MemoryInfo& memory);

// The RAM cache budget to use: the configured one, or less when it does not fit what is free now minus a
// reserve (the larger of 256 MiB and an eighth of the limit) kept for the renderer and everything else.
// `why` (optional) gets a sentence for the log when the budget was lowered.
uint64_t server_cache_budget(uint64_t configured, const MemoryInfo& memory, std::string* why = nullptr);

}  // namespace texstream
