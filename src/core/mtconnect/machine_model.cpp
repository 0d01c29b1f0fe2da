#include "cnc_bridge/mtconnect/machine_model.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::mtconnect
{
namespace
{
std::string upper(std::string text)
{
  for (char& c : text)
    c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return text;
}

struct Selector
{
  std::string id, name, type, sub_type, component;
};

Selector parseSelector(const std::string& field, const std::string& text)
{
  Selector s;
  auto bad = [&](const std::string& why)
  { return ConfigError("~mapping/" + field + ": selector '" + text + "' " + why); };
  if (text.rfind("id=", 0) == 0)
    s.id = text.substr(3);
  else if (text.rfind("name=", 0) == 0)
    s.name = text.substr(5);
  else
  {
    std::string rest = text;
    if (const auto at = rest.find('@'); at != std::string::npos)
    {
      s.component = upper(rest.substr(at + 1));
      rest = rest.substr(0, at);
      if (s.component.empty())
        throw bad("names no component after '@'");
    }
    if (const auto colon = rest.find(':'); colon != std::string::npos)
    {
      s.sub_type = upper(rest.substr(colon + 1));
      rest = rest.substr(0, colon);
      if (s.sub_type.empty())
        throw bad("names no subType after ':'");
    }
    s.type = upper(rest);
    if (s.type.empty() || s.type.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") != std::string::npos)
      throw bad("is not TYPE[:SUBTYPE][@COMPONENT], id=ID or name=NAME");
  }
  if (s.type.empty() && s.id.empty() && s.name.empty())
    throw bad("is empty");
  return s;
}

bool matches(const Selector& s, const DataItem& d)
{
  if (upper(d.category) == "CONDITION")
    return false;  // conditions have their own topic; a POSITION condition is no position
  if (!s.id.empty())
    return d.id == s.id;
  if (!s.name.empty())
    return d.name == s.name;
  if (upper(d.type) != s.type)
    return false;
  if (!s.sub_type.empty() && upper(d.sub_type) != s.sub_type)
    return false;
  return s.component.empty() || upper(d.component_name) == s.component;
}

std::optional<double> number(const std::string& text)
{
  if (text.empty())
    return std::nullopt;
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(value))
    return std::nullopt;
  return value;
}

std::optional<long long> integer(const std::string& text)
{
  const auto value = number(text);
  if (!value || *value != std::floor(*value) || std::fabs(*value) > 9e15)
    return std::nullopt;
  return static_cast<long long>(*value);
}

Execution executionOf(const std::string& v)
{
  if (v == "READY" || v == "PROGRAM_COMPLETED")
    return Execution::kReady;
  if (v == "ACTIVE")
    return Execution::kActive;
  if (v == "INTERRUPTED" || v == "FEED_HOLD" || v == "OPTIONAL_STOP" || v == "PROGRAM_OPTIONAL_STOP" || v == "WAIT")
    return Execution::kPaused;
  if (v == "STOPPED" || v == "PROGRAM_STOPPED")
    return Execution::kStopped;
  return Execution::kUnknown;
}

Mode modeOf(const std::string& v)
{
  if (v == "AUTOMATIC" || v == "SEMI_AUTOMATIC")
    return Mode::kAuto;
  if (v == "MANUAL")
    return Mode::kManual;
  if (v == "MANUAL_DATA_INPUT")
    return Mode::kMdi;
  if (v == "EDIT")
    return Mode::kEdit;
  return Mode::kUnknown;
}

ConditionLevel levelOf(const std::string& element)
{
  if (element == "Normal")
    return ConditionLevel::kNormal;
  if (element == "Warning")
    return ConditionLevel::kWarning;
  if (element == "Fault")
    return ConditionLevel::kFault;
  return ConditionLevel::kUnavailable;
}

bool running(Execution e)
{
  return e == Execution::kActive || e == Execution::kPaused;
}

/// Axis index of a position field (x_position -> 0), or -1.
int axisOf(const std::string& field)
{
  if (field.size() < 2 || field[1] != '_')
    return -1;
  const char axis = field[0];
  return axis == 'x' ? 0 : axis == 'y' ? 1 : axis == 'z' ? 2 : -1;
}

std::optional<std::time_t> epochSeconds(const std::string& stamp, double& fraction)
{
  std::tm tm{};
  int consumed = 0;
  // NOLINTNEXTLINE(cert-err34-c): every field is 2 or 4 digits and the count of fields is checked
  if (std::sscanf(stamp.c_str(), "%4d-%2d-%2dT%2d:%2d:%2d%n", &tm.tm_year, &tm.tm_mon, &tm.tm_mday, &tm.tm_hour,
                  &tm.tm_min, &tm.tm_sec, &consumed) != 6)
    return std::nullopt;
  tm.tm_year -= 1900;
  tm.tm_mon -= 1;
  fraction = 0;
  const char* rest = stamp.c_str() + consumed;
  if (*rest == '.')
  {
    char* end = nullptr;
    fraction = std::strtod(rest, &end);
  }
  return timegm(&tm);
}
}  // namespace

const std::vector<std::string>& mappingFields()
{
  static const std::vector<std::string> kFields = {
      "availability", "emergency_stop", "controller_mode", "execution",  "program",     "line",
      "part_count",   "x_position",     "y_position",      "z_position", "x_commanded", "y_commanded",
      "z_commanded",  "spindle_speed",  "feed_rate",       "tool",       "door"};
  return kFields;
}

Mapping defaultMapping()
{
  return {
      {"availability", {"AVAILABILITY"}},
      {"emergency_stop", {"EMERGENCY_STOP"}},
      {"controller_mode", {"CONTROLLER_MODE"}},
      {"execution", {"EXECUTION"}},
      {"program", {"PROGRAM:MAIN", "PROGRAM"}},
      {"line", {"LINE_NUMBER:INCREMENTAL", "LINE_NUMBER", "LINE"}},
      {"part_count", {"PART_COUNT:ALL", "PART_COUNT"}},
      {"x_position", {"POSITION:ACTUAL@X", "POSITION@X"}},
      {"y_position", {"POSITION:ACTUAL@Y", "POSITION@Y"}},
      {"z_position", {"POSITION:ACTUAL@Z", "POSITION@Z"}},
      {"x_commanded", {"POSITION:COMMANDED@X"}},
      {"y_commanded", {"POSITION:COMMANDED@Y"}},
      {"z_commanded", {"POSITION:COMMANDED@Z"}},
      {"spindle_speed", {"ROTARY_VELOCITY:ACTUAL", "SPINDLE_SPEED:ACTUAL", "ROTARY_VELOCITY", "SPINDLE_SPEED"}},
      {"feed_rate", {"PATH_FEEDRATE:ACTUAL", "PATH_FEEDRATE"}},
      {"tool", {"TOOL_NUMBER", "TOOL_ID"}},
      {"door", {"DOOR_STATE"}},
  };
}

Mapping mergeMapping(const Mapping& overrides)
{
  Mapping mapping = defaultMapping();
  for (const auto& [field, selectors] : overrides)
  {
    if (!mapping.count(field))
    {
      std::string known;
      for (const auto& f : mappingFields())
        known += (known.empty() ? "" : ", ") + f;
      throw ConfigError("~mapping: unknown field '" + field + "' (fields: " + known + ")");
    }
    for (const auto& s : selectors)
      parseSelector(field, s);   // throws on a bad one
    mapping[field] = selectors;  // an empty list: the field is not read
  }
  return mapping;
}

std::optional<double> siFactor(const std::string& units)
{
  static const std::map<std::string, double> kFactors = {{"MILLIMETER", 0.001},
                                                         {"INCH", 0.0254},
                                                         {"METER", 1.0},
                                                         {"MILLIMETER/SECOND", 0.001},
                                                         {"MILLIMETER/MINUTE", 0.001 / 60},
                                                         {"INCH/MINUTE", 0.0254 / 60},
                                                         {"INCH/SECOND", 0.0254},
                                                         {"METER/SECOND", 1.0},
                                                         {"REVOLUTION/MINUTE", 1.0},
                                                         {"REVOLUTION/SECOND", 60.0}};
  const auto it = kFactors.find(units);
  if (it == kFactors.end())
    return std::nullopt;
  return it->second;
}

std::optional<double> secondsBetween(const std::string& from, const std::string& to)
{
  double f1 = 0, f2 = 0;
  const auto a = epochSeconds(from, f1);
  const auto b = epochSeconds(to, f2);
  if (!a || !b)
    return std::nullopt;
  return static_cast<double>(*b - *a) + (f2 - f1);
}

MachineModel::MachineModel(Mapping mapping) : mapping_(std::move(mapping))
{
  for (const auto& [field, selectors] : mapping_)
  {
    for (const auto& s : selectors)
      parseSelector(field, s);
  }
}

void MachineModel::setDevice(const Device& device)
{
  field_of_item_.clear();
  field_of_item_inverse_.clear();
  scale_of_item_.clear();
  for (const auto& [field, selectors] : mapping_)
  {
    for (const auto& text : selectors)
    {
      const Selector s = parseSelector(field, text);
      const auto it = std::find_if(device.data_items.begin(), device.data_items.end(),
                                   [&](const DataItem& d) { return matches(s, d); });
      if (it == device.data_items.end())
        continue;
      field_of_item_[it->id].push_back(field);
      field_of_item_inverse_[field] = it->id;
      // Lengths and speeds in SI; MTConnect fixes POSITION in MILLIMETER, so a missing unit is mm.
      const bool length = axisOf(field) >= 0 || field == "feed_rate";
      const std::string units =
          it->units.empty() && length ? (field == "feed_rate" ? "MILLIMETER/SECOND" : "MILLIMETER") : it->units;
      scale_of_item_[it->id] = siFactor(units).value_or(1.0);
      break;
    }
  }
  forget();
  conditions_.clear();
  in_cycle_ = false;
  cycle_start_.clear();
}

std::vector<std::string> MachineModel::unmatched() const
{
  std::vector<std::string> out;
  for (const auto& f : mappingFields())
  {
    if (!field_of_item_inverse_.count(f))
      out.push_back(f);
  }
  return out;
}

void MachineModel::forget()
{
  const std::string timestamp = view_.timestamp;
  view_ = MachineView();
  view_.timestamp = timestamp;
}

std::vector<Condition> MachineModel::activeConditions() const
{
  std::vector<Condition> out;
  for (const auto& [item, by_code] : conditions_)
  {
    for (const auto& [code, c] : by_code)
    {
      if (c.level == ConditionLevel::kWarning || c.level == ConditionLevel::kFault)
        out.push_back(c);
    }
  }
  std::sort(out.begin(), out.end(), [](const Condition& a, const Condition& b) { return a.sequence < b.sequence; });
  return out;
}

void MachineModel::applyCondition(const Observation& o, ModelChanges& changes)
{
  Condition c;
  c.level = levelOf(o.element);
  c.data_item_id = o.data_item_id;
  c.condition_type = o.condition_type;
  c.native_code = o.native_code;
  c.native_severity = o.native_severity;
  c.qualifier = o.qualifier;
  c.text = o.value;
  c.timestamp = o.timestamp;
  c.sequence = o.sequence;
  auto& by_code = conditions_[o.data_item_id];
  switch (c.level)
  {
    case ConditionLevel::kUnavailable:
      by_code.clear();
      by_code[""] = c;
      break;
    case ConditionLevel::kNormal:
      // Normal with a code clears that code; without one, every condition of the data item.
      if (c.native_code.empty())
        by_code.clear();
      else
        by_code.erase(c.native_code);
      break;
    default:
      if (auto it = by_code.find(""); it != by_code.end() && it->second.level == ConditionLevel::kUnavailable)
        by_code.erase(it);
      by_code[c.native_code] = c;
  }
  changes.conditions.push_back(std::move(c));
}

void MachineModel::applyExecution(const Observation& o, Execution before, ModelChanges& changes, bool snapshot)
{
  const Execution now = view_.execution;
  if (now == Execution::kUnknown)
    return;  // UNAVAILABLE: whether a cycle runs is not known; its end will still be seen
  if (running(now) && !in_cycle_)
  {
    in_cycle_ = true;
    cycle_start_.clear();
    if (snapshot || before == Execution::kUnknown)
      return;  // joined mid-cycle: its start is not known
    cycle_start_ = o.timestamp;
    changes.events.push_back(
        {CycleEvent::kCycleStart, o.timestamp, "", -1, -1, "cycle start (Execution " + o.value + ")"});
  }
  else if (!running(now) && in_cycle_)
  {
    in_cycle_ = false;
    CycleEvent e{CycleEvent::kCycleEnd, o.timestamp, "", -1, -1, "cycle end (Execution " + o.value + ")"};
    if (!cycle_start_.empty())
      e.cycle_time = secondsBetween(cycle_start_, o.timestamp).value_or(-1);
    cycle_start_.clear();
    changes.events.push_back(e);
  }
}

void MachineModel::applyValue(const std::string& field, const Observation& o, ModelChanges& changes, bool snapshot)
{
  const std::string& v = o.value;
  const bool unavailable = o.unavailable();
  const double scale = scale_of_item_.count(o.data_item_id) ? scale_of_item_.at(o.data_item_id) : 1.0;
  if (const int axis = axisOf(field); axis >= 0)
  {
    auto& slot = field.find("commanded") != std::string::npos ? view_.commanded : view_.position;
    const auto value = number(v);
    slot[static_cast<size_t>(axis)] = value ? std::optional<double>(*value * scale) : std::nullopt;
  }
  else if (field == "availability")
    view_.available = unavailable ? std::nullopt : std::optional<bool>(v == "AVAILABLE");
  else if (field == "emergency_stop")
    view_.estop = v == "ARMED" ? Tristate::kOff : v == "TRIGGERED" ? Tristate::kOn : Tristate::kUnknown;
  else if (field == "controller_mode")
  {
    view_.mode = modeOf(v);
    view_.mode_text = v;
  }
  else if (field == "execution")
  {
    const Execution before = view_.execution;
    view_.execution = executionOf(v);
    view_.execution_text = v;
    applyExecution(o, before, changes, snapshot);
  }
  else if (field == "program")
    view_.program = unavailable ? "" : v;
  else if (field == "line")
  {
    const auto n = integer(v);
    view_.line = n && *n >= 0 && *n <= 0xffffffffLL ? static_cast<uint32_t>(*n) : 0;
  }
  else if (field == "part_count")
  {
    const int64_t before = view_.part_count;
    const auto n = integer(v);
    view_.part_count = n ? *n : -1;
    if (!snapshot && before >= 0 && view_.part_count > before)
    {
      changes.events.push_back(
          {CycleEvent::kPartCount, o.timestamp, "", view_.part_count, -1,
           "part counter rose from " + std::to_string(before) + " to " + std::to_string(view_.part_count)});
    }
  }
  else if (field == "spindle_speed")
  {
    const auto n = number(v);
    view_.spindle_rpm = n ? std::optional<double>(*n * scale) : std::nullopt;
  }
  else if (field == "feed_rate")
  {
    const auto n = number(v);
    view_.feed_rate = n ? std::optional<double>(*n * scale) : std::nullopt;
  }
  else if (field == "tool")
  {
    const auto n = integer(v);
    view_.tool = n && *n >= 0 && *n <= 0x7fffffffLL ? static_cast<int32_t>(*n) : -1;
  }
  else if (field == "door")
    view_.door = unavailable ? "" : v;
}

ModelChanges MachineModel::apply(const std::vector<Observation>& observations, bool snapshot)
{
  ModelChanges changes;
  if (snapshot)
  {
    // A snapshot after a gap: a cycle that ended meanwhile still ends, untimed.
    forget();
    changes.state = true;
  }
  for (const auto& o : observations)
  {
    if (!o.timestamp.empty())
      view_.timestamp = o.timestamp;
    if (o.category == "CONDITION")
    {
      applyCondition(o, changes);
      continue;
    }
    const auto it = field_of_item_.find(o.data_item_id);
    if (it == field_of_item_.end())
      continue;
    changes.state = true;
    for (const auto& field : it->second)
      applyValue(field, o, changes, snapshot);
  }
  // A cycle end and the part counter's step arrive together: the end counts the part, the step
  // alone is no event. Every event carries the state after the batch (program, parts).
  const bool cycle_end = std::any_of(changes.events.begin(), changes.events.end(),
                                     [](const CycleEvent& e) { return e.type == CycleEvent::kCycleEnd; });
  if (cycle_end)
  {
    changes.events.erase(std::remove_if(changes.events.begin(), changes.events.end(),
                                        [](const CycleEvent& e) { return e.type == CycleEvent::kPartCount; }),
                         changes.events.end());
  }
  for (auto& e : changes.events)
  {
    e.program = view_.program;
    e.part_count = view_.part_count;
  }
  return changes;
}
}  // namespace cnc_bridge::mtconnect
