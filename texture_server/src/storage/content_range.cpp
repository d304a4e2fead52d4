#include "texstream/server/storage/content_range.hpp"

#include <fmt/format.h>

#include <charconv>

namespace texstream::server {

namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r' || s.back() == '\n'))
    s.remove_suffix(1);
  return s;
}

std::optional<uint64_t> parse_u64(std::string_view s) {
  if (s.empty()) return std::nullopt;
  uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

Error bad(std::string_view text, const char* why) {
  return Error{ErrorCode::kCorrupt, fmt::format("bad Content-Range '{}': {}", text, why)};
}

}  // namespace

Result<ContentRange> parse_content_range(std::string_view value) {
  const std::string_view text = trim(value);
  constexpr std::string_view kUnit = "bytes ";
  if (text.substr(0, kUnit.size()) != kUnit) return bad(text, "expected the unit 'bytes'");
  const std::string_view rest = text.substr(kUnit.size());
  const size_t slash = rest.find('/');
  if (slash == std::string_view::npos) return bad(text, "no '/'");
  const std::string_view span = rest.substr(0, slash);
  const std::string_view total = rest.substr(slash + 1);
  ContentRange r;
  if (total != "*") {
    r.total = parse_u64(total);
    if (!r.total) return bad(text, "complete length is not a number");
  }
  if (span == "*") {
    if (!r.total) return bad(text, "neither a range nor a complete length");
    return r;
  }
  const size_t dash = span.find('-');
  if (dash == std::string_view::npos) return bad(text, "no '-' in the range");
  r.first = parse_u64(span.substr(0, dash));
  r.last = parse_u64(span.substr(dash + 1));
  if (!r.first || !r.last) return bad(text, "range bounds are not numbers");
  if (*r.last < *r.first) return bad(text, "last byte before first byte");
  if (r.total && *r.last >= *r.total) return bad(text, "range ends beyond the complete length");
  return r;
}

Result<uint64_t> check_range_answer(const ContentRange& range, uint64_t offset, uint64_t length,
                                    const std::string& url) {
  auto wrong = [&](const char* why) {
    return Error{ErrorCode::kCorrupt,
                 fmt::format("'{}': asked bytes {}-{}, the origin answered Content-Range bytes {}/{}: {}", url, offset,
                             offset + length - 1,
                             range.first ? fmt::format("{}-{}", *range.first, *range.last) : std::string("*"),
                             range.total ? std::to_string(*range.total) : std::string("*"), why)};
  };
  if (length == 0) return wrong("an empty range was asked");
  if (!range.first) return wrong("no range in a 206 answer");
  if (*range.first != offset) return wrong("it does not start where asked");
  const uint64_t asked_last = offset + length - 1;
  if (*range.last > asked_last) return wrong("it ends after the asked range");
  if (*range.last < asked_last && !(range.total && *range.last + 1 == *range.total)) {
    return wrong("it ends early but the object does not end there");
  }
  return *range.last - *range.first + 1;
}

}  // namespace texstream::server
