#pragma once
// A config key whose value is one of a few names (controller.mode, cache.format, ...). Its enum has one
// table {value, "name", "doc"} (a `ChoiceTable<E>` specialisation next to the enum); the parser, the error
// that lists the allowed names, the docs line and every user's name <-> enum conversion read that table,
// so a value is added in one place. docs/design/config_choices.md says why a table and not a macro.
#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include "texstream/common/result.hpp"

namespace texstream {

template <class E>
struct ChoiceEntry {
  E value;
  std::string_view name;  // as written in TOML and --set
  std::string_view doc;   // what the value does, for docs/config.md; empty: the name says it
};

// Specialise with `static constexpr std::array<ChoiceEntry<E>, N> kEntries{...}`; the first entry is not
// special (the default lives in the config struct).
template <class E>
struct ChoiceTable;

template <class E>
concept ConfigChoice = std::is_enum_v<E> && requires {
  ChoiceTable<E>::kEntries.size();
};

template <ConfigChoice E>
constexpr std::optional<E> choice_from_name(std::string_view name) {
  for (const ChoiceEntry<E>& e : ChoiceTable<E>::kEntries) {
    if (e.name == name) return e.value;
  }
  return std::nullopt;
}

// The value's name; a value outside the table (a cast from a bad integer) is a bug and reads "?".
template <ConfigChoice E>
constexpr std::string_view choice_name(E value) {
  for (const ChoiceEntry<E>& e : ChoiceTable<E>::kEntries) {
    if (e.value == value) return e.name;
  }
  return "?";
}

namespace detail {
// "a", "a or b", "a, b or c": `item(entry)` gives each entry's text.
template <class E, class F>
std::string join_choices(F&& item) {
  const auto& entries = ChoiceTable<E>::kEntries;
  std::string out;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    if (i > 0) out += i + 1 == entries.size() ? " or " : ", ";
    out += item(entries[i]);
  }
  return out;
}
}  // namespace detail

// The allowed names, "adaptive, none or fixed": error messages.
template <ConfigChoice E>
std::string choice_names() {
  return detail::join_choices<E>([](const ChoiceEntry<E>& e) { return std::string(e.name); });
}

// The allowed names with what each does, "adaptive (Eq. 4-7), none (...) or fixed": docs and TOML comments.
template <ConfigChoice E>
std::string choice_docs() {
  return detail::join_choices<E>([](const ChoiceEntry<E>& e) {
    return e.doc.empty() ? std::string(e.name) : std::string(e.name) + " (" + std::string(e.doc) + ")";
  });
}

// For a name that arrives outside a config file (a bench's flag, a test): the error names `key` and lists
// the allowed names, "server.cache_policy must be lru or level, not 'mru'".
template <ConfigChoice E>
Result<E> parse_choice(std::string_view key, std::string_view name) {
  if (std::optional<E> v = choice_from_name<E>(name)) return *v;
  return make_error(ErrorCode::kInvalidArgument,
                    std::string(key) + " must be " + choice_names<E>() + ", not '" + std::string(name) + "'");
}

}  // namespace texstream
