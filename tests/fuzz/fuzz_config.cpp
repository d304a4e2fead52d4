// libFuzzer: configuration parsing. Input = TOML text; the last line, if it looks like part.key=value, is also
// applied as an override. Invariant: no crash, no exception escapes; a config that parses and validates
// survives a round trip through to_toml.
#include <cstdint>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> overrides;
  if (const size_t nl = text.rfind('\n'); nl != std::string::npos && text.find('=', nl) != std::string::npos) {
    overrides.push_back(text.substr(nl + 1));
  }
  auto config = texstream::parse_config(text, "fuzz.toml", overrides);
  if (!config || !config->validate().ok()) return 0;
  auto again = texstream::parse_config(texstream::to_toml(*config), "round trip", {});
  if (!again) __builtin_trap();  // what we wrote we must read back
  return 0;
}
