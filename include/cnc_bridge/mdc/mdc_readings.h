// From a Haas status (MdcMonitor) to what a machine-state message carries, and from the node's
// settings to what is polled: positions in metres (the control reports them in its own unit,
// docs/haas_mdc_node.md), the emergency stop as far as Q500 tells it, the macro variables a poll
// plan reads, and the periods of a per-query table.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/mdc/mdc_monitor.h"

namespace cnc_bridge
{
namespace mdc
{
/// \brief The unit positions are read in: the control's G20/G21 (#4006), or one fixed by the user.
enum class UnitSetting
{
  kAuto,
  kInch,
  kMillimetre
};

/// \brief "auto", "inch" or "mm". \throws ConfigError naming \p parameter otherwise.
UnitSetting parseUnitSetting(const std::string& text, const std::string& parameter);

/// \returns metres per position unit; 0 while the unit is not known (no position rather than a
/// wrong one).
double metresPerUnit(UnitSetting setting, Units reported);

/// \brief What unit a value read from the control (?Q600) is in, in words for an answer: a length is
/// in the control's unit ("inch (G20)", "mm (G21)", or that it is not known yet), other variables
/// in their own (rev/min, counts, ...).
std::string unitNote(UnitSetting setting, Units reported);

/// \brief The emergency stop as far as Q500 tells it.
enum class Estop
{
  kUnknown,
  kOn,
  kOff
};

/// \brief A status naming the e-stop is kOn; a status that is no alarm (idle, running, feed hold,
/// stopped) is kOff, since a Haas in e-stop reports ALARM; an alarm that does not name it, or a
/// status not known, is kUnknown.
Estop estopFrom(const MachineStatus& status);

/// \brief The macro variables a node polls, as configured.
struct PollVariables
{
  std::vector<int> position;  ///< machine position X Y Z (#5021-#5023), or none
  std::vector<int> work;      ///< work position X Y Z (#5041-#5043) for the work offset, or none
  std::vector<int> extra;     ///< more variables shown in diagnostics
  std::vector<int> watched;   ///< variables published when they change
  int spindle = 3027;         ///< spindle speed, rpm; 0 for none
  UnitSetting units = UnitSetting::kAuto;

  /// \brief position and work: 3 entries or none. \throws ConfigError naming \p parameter.
  void check(const std::string& parameter) const;
  /// \brief Adds the variables to \p plan: each once per poll cycle however many lists name it,
  /// the spindle's, and #4006 (G20/G21) among the slow ones when the unit comes from the control.
  void addTo(PollPlan& plan) const;
  /// \brief (machine, work) variable per axis, for MdcPoller::setWorkOffsetAxes(); empty unless
  /// both lists are given.
  std::vector<std::pair<int, int>> workOffsetAxes() const;
};

/// \brief The machine's position and work offset in metres, and its spindle speed.
struct Readings
{
  bool position_valid = false;
  std::array<double, 3> position{};  ///< m, machine coordinates
  bool work_offset_valid = false;
  std::array<double, 3> work_offset{};  ///< m, work zero in machine coordinates
  std::optional<double> spindle_rpm;
};

/// \brief What \p status says of the position (when every position variable has a value and the
/// unit is known), the work offset (with the position) and the spindle speed.
Readings readingsFrom(const MachineStatus& status, const PollVariables& variables);

/// \brief One entry of a per-query period table ({"Q500": 0.25, "Q600 5021": 0.1}): \p seconds
/// 0 (not polled) or positive, at least 1 ms. \throws ConfigError naming \p table and \p key.
std::pair<Query, Milliseconds> queryPeriod(const std::string& table, const std::string& key, double seconds);
}  // namespace mdc
}  // namespace cnc_bridge
