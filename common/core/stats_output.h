// JSON objects and text tables generated from a statistics struct's field
// list (see common/core/stats_fields.h): every field appears in both, under
// the key and the label the list gives it, in the list's order.
#pragma once

#include <fmt/format.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <type_traits>

#include "common/core/stats_fields.h"

namespace vistream {

// One JSON member per field. Values keep their type: counts are integers,
// times floating point, flags booleans.
template <class Stats>
nlohmann::json statsJson(const Stats& stats) {
  nlohmann::json out = nlohmann::json::object();
  stats.forEachField(
      [&](const StatField& field, const auto& value) { out[std::string(field.key)] = value; });
  return out;
}

// One line per field: `indent`, "label (unit)" left-aligned in a column as
// wide as the longest label (at least 34), the value right-aligned in 12
// (floating point with 3 decimals, flags as yes/no), a newline.
template <class Stats>
std::string statsTable(const Stats& stats, std::string_view indent = "  ") {
  auto labelOf = [](const StatField& field) {
    return field.unit.empty() ? std::string(field.label)
                              : fmt::format("{} ({})", field.label, field.unit);
  };
  size_t width = 34;
  stats.forEachField(
      [&](const StatField& field, const auto&) { width = std::max(width, labelOf(field).size()); });
  std::string out;
  stats.forEachField([&](const StatField& field, const auto& value) {
    using Value = std::decay_t<decltype(value)>;
    if constexpr (std::is_same_v<Value, bool>)
      out += fmt::format("{}{:<{}} {:>12}\n", indent, labelOf(field), width, value ? "yes" : "no");
    else if constexpr (std::is_floating_point_v<Value>)
      out += fmt::format("{}{:<{}} {:>12.3f}\n", indent, labelOf(field), width, value);
    else
      out += fmt::format("{}{:<{}} {:>12}\n", indent, labelOf(field), width, value);
  });
  return out;
}

}  // namespace vistream
