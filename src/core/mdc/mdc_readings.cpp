#include "cnc_bridge/mdc/mdc_readings.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace mdc
{
namespace
{
constexpr double kMetresPerInch = 0.0254;
constexpr double kMetresPerMillimetre = 0.001;

bool haveAll(const MachineStatus& status, const std::vector<int>& variables)
{
  return std::all_of(variables.begin(), variables.end(),
                     [&status](int variable) { return status.variables.count(variable) > 0; });
}
}  // namespace

UnitSetting parseUnitSetting(const std::string& text, const std::string& parameter)
{
  if (text == "auto")
    return UnitSetting::kAuto;
  if (text == "inch")
    return UnitSetting::kInch;
  if (text == "mm")
    return UnitSetting::kMillimetre;
  throw ConfigError(parameter + " must be auto, inch or mm, not " + text);
}

std::string unitNote(UnitSetting setting, Units reported)
{
  const double metres = metresPerUnit(setting, reported);
  const std::string lengths = metres == 0.0254  ? "inch (G20; x 0.0254 for metres)"
                              : metres == 0.001 ? "mm (G21; x 0.001 for metres)"
                                                : "the control's unit, not known yet (#4006 not read; ~units sets it)";
  return "as the control reports it: a length (a position, an offset) in " + lengths +
         ", any other variable in its own unit (rev/min, counts, seconds)";
}

double metresPerUnit(UnitSetting setting, Units reported)
{
  if (setting == UnitSetting::kInch)
    return kMetresPerInch;
  if (setting == UnitSetting::kMillimetre)
    return kMetresPerMillimetre;
  switch (reported)
  {
    case Units::kInch:
      return kMetresPerInch;
    case Units::kMillimetre:
      return kMetresPerMillimetre;
    default:
      return 0;
  }
}

Estop estopFrom(const MachineStatus& status)
{
  std::string text = status.status_text;
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::toupper(c); });
  if (text.find("ESTOP") != std::string::npos || text.find("E-STOP") != std::string::npos ||
      text.find("EMERGENCY") != std::string::npos)
    return Estop::kOn;
  if (status.execution == Execution::kAlarm || status.execution == Execution::kUnknown)
    return Estop::kUnknown;
  return Estop::kOff;
}

void PollVariables::check(const std::string& parameter) const
{
  if ((!position.empty() && position.size() != 3) || (!work.empty() && work.size() != 3))
    throw ConfigError(parameter + " and work_position_variables need 3 entries or none");
}

void PollVariables::addTo(PollPlan& plan) const
{
  for (const auto* list : {&position, &work, &extra, &watched})
  {
    for (int variable : *list)
    {
      if (std::find(plan.variables.begin(), plan.variables.end(), variable) == plan.variables.end())
        plan.variables.push_back(variable);
    }
  }
  if (spindle > 0)
    plan.variables.push_back(spindle);
  if (units == UnitSetting::kAuto && !position.empty())
    plan.slow_variables.push_back(4006);
}

std::vector<std::pair<int, int>> PollVariables::workOffsetAxes() const
{
  if (position.empty() || work.empty())
    return {};
  return {{position[0], work[0]}, {position[1], work[1]}, {position[2], work[2]}};
}

Readings readingsFrom(const MachineStatus& status, const PollVariables& variables)
{
  Readings readings;
  if (variables.spindle > 0 && status.variables.count(variables.spindle))
    readings.spindle_rpm = status.variables.at(variables.spindle);  // #3027 is in rev/min
  const double scale = metresPerUnit(variables.units, status.units);
  if (scale <= 0 || variables.position.empty() || !haveAll(status, variables.position))
    return readings;
  readings.position_valid = true;
  for (size_t axis = 0; axis < 3; ++axis)
    readings.position[axis] = status.variables.at(variables.position[axis]) * scale;
  if (status.work_offset[0] && status.work_offset[1] && status.work_offset[2])
  {
    // Work zero in machine coordinates, taken while the axes stood still (MdcMonitor).
    readings.work_offset_valid = true;
    for (size_t axis = 0; axis < 3; ++axis)
      readings.work_offset[axis] = *status.work_offset[axis] * scale;
  }
  return readings;
}

std::pair<Query, Milliseconds> queryPeriod(const std::string& table, const std::string& key, double seconds)
{
  if (!std::isfinite(seconds) || seconds < 0)
    throw ConfigError(table + "/" + key + " must be 0 (not polled) or a positive number of seconds");
  Query query;
  try
  {
    query = parseQueryKey(key);
  }
  catch (const ConfigError& e)
  {
    throw ConfigError(table + ": " + e.what());
  }
  const auto period =
      seconds == 0 ? Milliseconds(0) : std::max(Milliseconds(std::llround(seconds * 1000)), Milliseconds(1));
  return {query, period};
}
}  // namespace mdc
}  // namespace cnc_bridge
