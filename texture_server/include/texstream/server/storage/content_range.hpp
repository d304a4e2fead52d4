#pragma once
// HTTP range answers (RFC 9110 §14.4): parsing Content-Range and checking a 206 answer against the range that
// was asked. An origin that answers a different range than asked (a proxy bug, a file replaced mid-read) must
// never have its bytes taken for the asked ones: that would put the wrong texels in a mip.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "texstream/common/result.hpp"

namespace texstream::server {

struct ContentRange {
  // "bytes first-last/total"; an unsatisfied-range answer ("bytes */total") has no first/last.
  std::optional<uint64_t> first;
  std::optional<uint64_t> last;   // inclusive
  std::optional<uint64_t> total;  // nullopt for "*" (unknown length)
};

// Parses the header's value (leading/trailing blanks allowed). Errors: kCorrupt naming the text.
Result<ContentRange> parse_content_range(std::string_view value);

// For a 206 answer to a request of bytes [offset, offset + length): the number of body bytes that must follow.
// It must start at `offset`, end no later than asked, and end early only where the object ends (total known
// and last + 1 == total). Errors: kCorrupt, naming `url` and both ranges.
Result<uint64_t> check_range_answer(const ContentRange& range, uint64_t offset, uint64_t length,
                                    const std::string& url);

}  // namespace texstream::server
