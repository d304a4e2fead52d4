#include "texstream/render/measure/frame_log.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

namespace texstream::render {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// One column: its name and how a record's field is written and read.
struct Column {
  const char* name;
  double FrameRecord::*real = nullptr;
  uint64_t FrameRecord::*count = nullptr;
  bool FrameRecord::*flag = nullptr;
};

const std::vector<Column>& columns() {
  static const std::vector<Column> c = {
      {"frame", nullptr, &FrameRecord::index},
      {"time_s", &FrameRecord::time_s},
      {"wall_s", &FrameRecord::wall_s},
      {"latency_ms", &FrameRecord::latency_ms},
      {"waited_ms", &FrameRecord::waited_ms},
      {"tw_ms", &FrameRecord::tw_ms},
      {"load_size_mb", &FrameRecord::load_size_mb},
      {"mip_bias", &FrameRecord::mip_bias},
      {"mips", nullptr, &FrameRecord::mips},
      {"bytes", nullptr, &FrameRecord::bytes},
      {"bound_pages", nullptr, &FrameRecord::bound_pages},
      {"server_hit_rate", &FrameRecord::server_hit_rate},
      {"in_flight", nullptr, &FrameRecord::in_flight},
      {"camera_still", nullptr, nullptr, &FrameRecord::camera_still},
      {"mse", &FrameRecord::mse},
      {"psnr_db", &FrameRecord::psnr_db},
      {"ssim", &FrameRecord::ssim},
      {"popin_mse", &FrameRecord::popin_mse},
      {"latency_off_ms", &FrameRecord::latency_off_ms},
      {"list_fresh", nullptr, nullptr, &FrameRecord::list_fresh},
      {"mip_deficit", &FrameRecord::mip_deficit},
      {"wasted_bytes", nullptr, &FrameRecord::wasted_bytes},
      {"plan_ms", &FrameRecord::plan_ms},
      {"intake_ms", &FrameRecord::intake_ms},
      {"bind_ms", &FrameRecord::bind_ms},
      {"record_ms", &FrameRecord::record_ms},
      {"gpu_ms", &FrameRecord::gpu_ms},
      {"cycle_ms", &FrameRecord::cycle_ms},
      {"pace_mips", &FrameRecord::pace_mips},
  };
  return c;
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  for (char ch : line) {
    if (ch == ',') {
      out.push_back(cur);
      cur.clear();
    } else if (ch != '\r') {
      cur += ch;
    }
  }
  out.push_back(cur);
  return out;
}

}  // namespace

const std::vector<std::string>& frame_log_columns() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const Column& c : columns()) n.emplace_back(c.name);
    return n;
  }();
  return names;
}

std::string frame_log_csv(const std::vector<FrameRecord>& frames) {
  std::string out;
  for (size_t i = 0; i < columns().size(); ++i) {
    if (i) out += ',';
    out += columns()[i].name;
  }
  out += "\n";
  char buf[64];
  for (const FrameRecord& f : frames) {
    for (size_t i = 0; i < columns().size(); ++i) {
      const Column& c = columns()[i];
      if (i) out += ",";
      if (c.count) {
        std::snprintf(buf, sizeof buf, "%llu", static_cast<unsigned long long>(f.*c.count));
      } else if (c.flag) {
        std::snprintf(buf, sizeof buf, "%d", f.*c.flag ? 1 : 0);
      } else if (std::isfinite(f.*c.real)) {
        // 17 significant digits: a value read back is the same double (lock-step reruns compare exactly).
        std::snprintf(buf, sizeof buf, "%.17g", f.*c.real);
      } else {
        buf[0] = '\0';  // NaN: not measured in this frame
      }
      out += buf;
    }
    out += "\n";
  }
  return out;
}

Status write_frame_log(const std::filesystem::path& file, const std::vector<FrameRecord>& frames) {
  std::ofstream out(file);
  out << frame_log_csv(frames);
  out.close();
  if (!out) return make_error(ErrorCode::kIo, file.string() + ": write failed");
  return ok_status();
}

Result<std::vector<FrameRecord>> parse_frame_log(const std::string& text, const std::string& what) {
  std::istringstream in(text);
  std::string line;
  if (!std::getline(in, line)) return make_error(ErrorCode::kCorrupt, what + ": empty, no header");
  const std::vector<std::string> header = split(line);
  if (header != frame_log_columns()) {
    return make_error(ErrorCode::kCorrupt, what + ": line 1: header '" + line + "' is not the frames.csv header");
  }
  std::vector<FrameRecord> frames;
  size_t line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line == "\r") continue;
    const std::vector<std::string> fields = split(line);
    const std::string where = what + ": line " + std::to_string(line_no);
    if (fields.size() != columns().size()) {
      return make_error(ErrorCode::kCorrupt, where + ": " + std::to_string(fields.size()) + " fields, expected " +
                                                 std::to_string(columns().size()));
    }
    FrameRecord f;
    for (size_t i = 0; i < fields.size(); ++i) {
      const Column& c = columns()[i];
      const std::string& s = fields[i];
      const char* end = s.data() + s.size();
      if (c.count || c.flag) {
        uint64_t v = 0;
        const auto r = std::from_chars(s.data(), end, v);
        if (s.empty() || r.ec != std::errc() || r.ptr != end) {
          return make_error(ErrorCode::kCorrupt, where + ": column " + c.name + ": '" + s + "' is not a count");
        }
        if (c.count)
          f.*c.count = v;
        else
          f.*c.flag = v != 0;
      } else if (s.empty()) {
        f.*c.real = kNaN;
      } else {
        double v = 0;
        const auto r = std::from_chars(s.data(), end, v);
        if (r.ec != std::errc() || r.ptr != end) {
          return make_error(ErrorCode::kCorrupt, where + ": column " + c.name + ": '" + s + "' is not a number");
        }
        f.*c.real = v;
      }
    }
    frames.push_back(f);
  }
  return frames;
}

Result<std::vector<FrameRecord>> read_frame_log(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return make_error(ErrorCode::kNotFound, file.string() + ": cannot be read");
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_frame_log(ss.str(), file.string());
}

}  // namespace texstream::render
