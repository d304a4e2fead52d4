#include "texstream/common/camera_path.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <system_error>

#include "texstream/common/contract.hpp"

namespace texstream {

namespace {

// Splits a line into whitespace-separated fields (at most `max` + 1, so that extra fields are noticed).
std::vector<std::string_view> split_fields(std::string_view line, size_t max) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < line.size() && out.size() <= max) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    if (i == line.size()) break;
    const size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    out.push_back(line.substr(start, i - start));
  }
  return out;
}

bool parse_double(std::string_view s, double& out) {
  const char* end = s.data() + s.size();
  const auto [ptr, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc() && ptr == end && std::isfinite(out);
}

void append_double(std::string& out, double v) {
  char buf[64];
  // Shortest representation that reads back to the same double: to_text() round-trips exactly.
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  TS_ASSERT(ec == std::errc(), "to_chars failed");
  out.append(buf, ptr);
}

// Signed difference b - a folded into [-180, 180): the shorter way round the circle.
double shortest_arc_deg(double a, double b) {
  double d = std::fmod(b - a, 360.0);
  if (d < -180.0) d += 360.0;
  if (d >= 180.0) d -= 360.0;
  return d;
}

}  // namespace

Result<CameraPath> CameraPath::load(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::error_code ec;
    const bool exists = std::filesystem::exists(file, ec);
    return make_error(exists ? ErrorCode::kIo : ErrorCode::kNotFound,
                      file.string() + (exists ? ": cannot open" : ": not found"));
  }
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return make_error(ErrorCode::kIo, file.string() + ": read failed");
  return parse(text.str(), file.string());
}

Result<CameraPath> CameraPath::parse(const std::string& text, const std::string& what) {
  static constexpr const char* kFieldNames[6] = {"time_s", "x", "y", "z", "yaw_deg", "pitch_deg"};
  std::vector<CameraKey> keys;
  size_t line_no = 0;
  size_t pos = 0;
  while (pos <= text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    std::string_view line(text.data() + pos, eol - pos);
    pos = eol + 1;
    ++line_no;
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const auto fields = split_fields(line, 6);
    if (fields.empty()) continue;
    const std::string where = what + ":" + std::to_string(line_no) + ": ";
    if (fields.size() != 6)
      return make_error(ErrorCode::kInvalidArgument,
                        where + "expected 6 fields 'time_s x y z yaw_deg pitch_deg', found " +
                            (fields.size() > 6 ? std::string("more") : std::to_string(fields.size())));
    double v[6];
    for (size_t f = 0; f < 6; ++f)
      if (!parse_double(fields[f], v[f]))
        return make_error(ErrorCode::kInvalidArgument, where + "field '" + kFieldNames[f] + "' = '" +
                                                           std::string(fields[f]) + "' is not a finite number");
    if (v[0] < 0.0) return make_error(ErrorCode::kInvalidArgument, where + "time_s is negative");
    if (!keys.empty() && v[0] < keys.back().time_s)
      return make_error(ErrorCode::kInvalidArgument,
                        where + "time_s goes backwards (" + std::string(fields[0]) + " after a later keyframe)");
    if (v[5] < -90.0 || v[5] > 90.0)
      return make_error(ErrorCode::kInvalidArgument, where + "pitch_deg must lie in [-90, 90]");
    keys.push_back(CameraKey{v[0], CameraPose{{v[1], v[2], v[3]}, v[4], v[5]}});
  }
  if (keys.empty()) return make_error(ErrorCode::kInvalidArgument, what + ": no keyframes");
  return CameraPath(std::move(keys));
}

std::string CameraPath::to_text() const {
  std::string out = "# time_s x y z yaw_deg pitch_deg   (map coordinates in metres; equal times = cut)\n";
  for (const CameraKey& k : keys_) {
    const double v[6] = {k.time_s,           k.pose.position[0], k.pose.position[1],
                         k.pose.position[2], k.pose.yaw_deg,     k.pose.pitch_deg};
    for (int f = 0; f < 6; ++f) {
      if (f != 0) out += ' ';
      append_double(out, v[f]);
    }
    out += '\n';
  }
  return out;
}

CameraPose CameraPath::sample(double time_s) const {
  TS_ASSERT(!keys_.empty(), "CameraPath::sample on an empty path");
  // The first key strictly after t; the key before it is the latest one at or before t. At a cut (two keys
  // with the same time) this picks the later of the pair, so the new view holds from the cut time on.
  const auto next =
      std::upper_bound(keys_.begin(), keys_.end(), time_s, [](double t, const CameraKey& k) { return t < k.time_s; });
  if (next == keys_.begin()) return keys_.front().pose;
  if (next == keys_.end()) return keys_.back().pose;
  const CameraKey& a = *(next - 1);
  const CameraKey& b = *next;
  const double f = (time_s - a.time_s) / (b.time_s - a.time_s);  // b.time_s > a.time_s by upper_bound
  CameraPose p;
  for (int i = 0; i < 3; ++i) p.position[i] = a.pose.position[i] + (b.pose.position[i] - a.pose.position[i]) * f;
  p.yaw_deg = a.pose.yaw_deg + shortest_arc_deg(a.pose.yaw_deg, b.pose.yaw_deg) * f;
  p.pitch_deg = a.pose.pitch_deg + (b.pose.pitch_deg - a.pose.pitch_deg) * f;
  return p;
}

}  // namespace texstream
