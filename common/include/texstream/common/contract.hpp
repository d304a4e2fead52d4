#pragma once
// Bugs (broken invariants) abort loudly: file, line, condition and a formatted message go to stderr, then
// std::abort(). Never used for bad input or a dead peer: those are Result errors.
#include <cstdio>
#include <cstdlib>

namespace texstream::detail {
[[noreturn]] void contract_failed(const char* file, int line, const char* condition, const char* fmt, ...)
    __attribute__((format(printf, 4, 5)));
}  // namespace texstream::detail

#define TS_ASSERT(cond, ...)                                                                                        \
  do {                                                                                                              \
    if (__builtin_expect(!(cond), 0)) ::texstream::detail::contract_failed(__FILE__, __LINE__, #cond, __VA_ARGS__); \
  } while (0)

#define TS_UNREACHABLE(...) ::texstream::detail::contract_failed(__FILE__, __LINE__, "unreachable", __VA_ARGS__)
