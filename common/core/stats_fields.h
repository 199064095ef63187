// One field list per statistics struct, from which both its JSON object and
// its text table are generated, so the two cannot drift apart.
//
// A statistics struct lists every field once, in a member template
//
//   template <class F> void forEachField(F&& f) const {
//     f(StatField{"time_ms", "time", "ms"}, timeMs);
//     f(StatField{"lines_cast", "lines cast", ""}, linesCast);
//   }
//
// and a static_assert on its size next to it catches a field added to the
// struct but not to the list. statsJson and statsTable
// (common/core/stats_output.h) read the list; so can anything else that
// walks the fields (sums, medians).
#pragma once

#include <string_view>

namespace vistream {

struct StatField {
  std::string_view key;    // JSON key, snake_case, unit included ("time_ms")
  std::string_view label;  // words for a table row ("time")
  std::string_view unit;   // "ms", "m", ...; empty for counts
};

}  // namespace vistream
