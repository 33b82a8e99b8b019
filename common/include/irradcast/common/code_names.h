// Names for the integer codes of C APIs (glTF component and element types, VkResult, Vulkan
// device types): a table of code and name, looked up with a fallback for codes not listed.
#pragma once

#include <cstddef>

namespace irradcast {

struct CodeName {
  long long code;
  const char* name;
};

// The name that `table` gives `code`, or `fallback` (which may be nullptr) when it has none.
template <std::size_t N>
const char* code_name(long long code, const CodeName (&table)[N], const char* fallback) {
  for (const CodeName& c : table)
    if (c.code == code) return c.name;
  return fallback;
}

}  // namespace irradcast
