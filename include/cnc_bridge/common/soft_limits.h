// Soft travel limits per axis (the control profiles' ~soft_limits): a request whose coordinates
// leave them is refused before anything is sent. An axis without limits is not checked.
#pragma once

#include <array>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>

namespace cnc_bridge
{
/// \brief [min, max] in metres per axis X, Y, Z; an axis left empty has no soft limit.
struct SoftLimits
{
  std::array<std::optional<std::pair<double, double>>, 3> axes;
  /// The parameter the limits came from, named in a refusal ("/cell/router/ethernut_node/soft_limits").
  std::string setting = "soft_limits";

  bool empty() const { return !axes[0] && !axes[1] && !axes[2]; }

  /// \brief "" if \p metres (X, Y, Z) is inside every limit; otherwise the first axis outside, its
  /// value and its limits: "Y 0.75 m is outside the soft limits 0..0.5 m (<setting>)".
  std::string violation(const std::array<double, 3>& metres) const
  {
    for (int a = 0; a < 3; ++a)
    {
      const auto& limit = axes[static_cast<size_t>(a)];
      if (limit && !(metres[static_cast<size_t>(a)] >= limit->first && metres[static_cast<size_t>(a)] <= limit->second))
      {
        char text[160];
        std::snprintf(text, sizeof text, "%c %.9g m is outside the soft limits %.9g..%.9g m (", "XYZ"[a],
                      metres[static_cast<size_t>(a)], limit -> first, limit -> second);
        return text + setting + ")";
      }
    }
    return "";
  }
};
}  // namespace cnc_bridge
