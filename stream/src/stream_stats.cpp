#include "texstream/stream/stream_stats.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace texstream::stream {

const char* to_string(StreamServerState state) {
  switch (state) {
    case StreamServerState::kExternal:
      return "external";
    case StreamServerState::kRunning:
      return "running";
    case StreamServerState::kBackingOff:
      return "backing off";
    case StreamServerState::kColormapOnly:
      return "colormap only";
    case StreamServerState::kBroken:
      return "broken";
  }
  return "?";
}

double IpcTimeHistogram::quantile_us(double q) const {
  const uint64_t samples = h_.count();
  if (samples == 0) return 0.0;
  const auto rank = static_cast<uint64_t>(std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(samples)));
  const uint32_t bucket = h_.bucket_at_rank(std::max<uint64_t>(rank, 1));
  const double max_us = static_cast<double>(h_.max()) / 1e3;
  // The last bucket holds everything from 20.47 ms up: there the exact maximum is the answer.
  if (bucket >= h_.kBuckets - 1) return max_us;
  return std::min(static_cast<double>((h_.bucket_upper(bucket) + 1) * kBucketNs) / 1e3, max_us);
}

IpcSummary IpcSummary::of(const IpcTimeHistogram& h) {
  IpcSummary s;
  s.frames = static_cast<double>(h.samples());
  s.total_ms = h.total_ms();
  s.p50_us = h.quantile_us(0.5);
  s.p99_us = h.quantile_us(0.99);
  s.p999_us = h.quantile_us(0.999);
  s.p9999_us = h.quantile_us(0.9999);
  s.max_us = static_cast<double>(h.max_ns()) / 1e3;
  s.frames_over_1ms = static_cast<double>(h.above(1'000'000));
  return s;
}

namespace {

uint64_t failed_sum(const StreamStats& s) {
  uint64_t failed = 0;
  for (uint64_t f : s.completions_failed) failed += f;
  return failed;
}

}  // namespace

std::string format_stream_stats(const StreamStats& s, const IpcTimeHistogram& ipc_time) {
  std::ostringstream o;
  for (const StreamCounterField& f : kStreamCounters) o << f.name << " " << s.*f.member << "\n";
  o << "completions_failed " << failed_sum(s) << "\n"
    << "server_state " << to_string(s.server_state) << "\n";
  const IpcSummary ipc = IpcSummary::of(ipc_time);
  for (const IpcField& f : kIpcFields) o << f.name << " " << ipc.*f.member << "\n";
  return o.str();
}

nlohmann::json stream_stats_json(const StreamStats& s, const IpcTimeHistogram& ipc_time) {
  nlohmann::json j = nlohmann::json::object();
  for (const StreamCounterField& f : kStreamCounters) j[std::string(f.name)] = s.*f.member;
  j["completions_failed"] = failed_sum(s);
  j["server_state"] = to_string(s.server_state);
  const IpcSummary ipc = IpcSummary::of(ipc_time);
  for (const IpcField& f : kIpcFields) j[std::string(f.name)] = ipc.*f.member;
  return j;
}

Result<StreamStatsText> parse_stream_stats(std::string_view text, const std::string& source) {
  StreamStatsText out;
  size_t line_no = 0;
  while (!text.empty()) {
    const size_t end = text.find('\n');
    const std::string_view line = text.substr(0, end);
    text = end == std::string_view::npos ? std::string_view{} : text.substr(end + 1);
    ++line_no;
    if (line.empty()) continue;
    const size_t space = line.find(' ');
    const std::string_view key = line.substr(0, space);
    const std::string value(space == std::string_view::npos ? std::string_view{} : line.substr(space + 1));
    const auto bad = [&](std::string_view what) {
      return make_error(ErrorCode::kCorrupt, fmt::format("{}:{}: '{}' {}", source, line_no, key, what));
    };
    if (key == "server_state") {
      out.server_state = value;
      continue;
    }
    char* rest = nullptr;
    errno = 0;
    const double number = std::strtod(value.c_str(), &rest);
    if (value.empty() || rest == value.c_str() || *rest != '\0' || errno == ERANGE)
      return bad(fmt::format("has no number ('{}')", value));
    if (key == "completions_failed") {
      out.stats.completions_failed[0] = static_cast<uint64_t>(number);
      continue;
    }
    const auto counter = std::find_if(kStreamCounters.begin(), kStreamCounters.end(),
                                      [&](const StreamCounterField& f) { return f.name == key; });
    if (counter != kStreamCounters.end()) {
      if (number < 0) return bad("is negative");
      out.stats.*counter->member = static_cast<uint64_t>(number);
      continue;
    }
    const auto ipc =
        std::find_if(kIpcFields.begin(), kIpcFields.end(), [&](const IpcField& f) { return f.name == key; });
    if (ipc == kIpcFields.end()) return bad("is no key of the stream statistics");
    out.ipc.*ipc->member = number;
  }
  return out;
}

}  // namespace texstream::stream
