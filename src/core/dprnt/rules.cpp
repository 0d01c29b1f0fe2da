// RuleSet: YAML rules to typed outputs (format documented in config/dprnt_rules.yaml).
#include "cnc_bridge/dprnt/rules.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace dprnt
{
namespace
{
/// "state: position | commanded_position": the point is also the machine's position in the node's
/// state (and tf), which is in the machine frame.
StateField parseStateField(const YAML::Node& node, const std::string& frame, const std::string& where)
{
  if (!node)
    return StateField::kNone;
  const std::string text = node.as<std::string>();
  if (text != "position" && text != "commanded_position")
    throw ConfigError(where + R"(: "state" must be position or commanded_position, not ")" + text + "\"");
  if (frame != "machine")
    throw ConfigError(where + R"(: "state: )" + text +
                      R"(" needs "frame: machine" (the state's positions are in the machine frame; a work-frame )"
                      "point would need the work offset)");
  return text == "position" ? StateField::kPosition : StateField::kCommandedPosition;
}

ValueSource parseSource(const YAML::Node& node, const std::string& where)
{
  ValueSource source;
  if (!node)
  {
    return source;
  }
  const std::string text = node.as<std::string>();
  if (text.size() >= 2 && text[0] == '$' && std::isdigit(static_cast<unsigned char>(text[1])))
  {
    try
    {
      source.group = std::stoi(text.substr(1));
    }
    catch (const std::exception&)
    {
      throw ConfigError(where + ": bad capture group \"" + text + "\"");
    }
    return source;
  }
  source.label = text;
  return source;
}

CycleEventKind parseEvent(const std::string& text, const std::string& where)
{
  if (text == "start")
    return CycleEventKind::kStart;
  if (text == "end")
    return CycleEventKind::kEnd;
  if (text == "part_count")
    return CycleEventKind::kPartCount;
  if (text == "marker")
    return CycleEventKind::kMarker;
  if (text == "alarm")
    return CycleEventKind::kAlarm;
  throw ConfigError(where + ": event \"" + text + "\" is not one of start, end, part_count, marker, alarm");
}

bool validName(const std::string& name)
{
  if (name.empty())
    return false;
  return std::all_of(name.begin(), name.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; });
}

// Resolves a source on one line. Capture groups are parsed with the tolerant line parser, so
// "$1" may hold "- 1.5" or "1.5000" alike.
/// A part count is a whole, non-negative number a double holds exactly (below 2^53). Anything else
/// (a negative count, a fraction, a garbled line's 1e37) leaves the count unknown rather than
/// publishing a wrapped or truncated one.
bool isPartCount(double number)
{
  constexpr double kLargestExact = 9007199254740992.0;  // 2^53
  return number >= 0 && number <= kLargestExact && std::floor(number) == number;
}

bool resolve(const ValueSource& source, const std::vector<LabeledValue>& values, const std::smatch* match,
             double& value)
{
  if (source.group >= 0)
  {
    if (!match || static_cast<size_t>(source.group) >= match->size() || !(*match)[source.group].matched)
      return false;
    thread_local std::vector<LabeledValue> group_values;
    if (LineParser::parse((*match)[source.group].str(), group_values) == 0)
      return false;
    value = group_values.front().value;
    return true;
  }
  if (source.label.empty())
  {
    if (values.empty())
      return false;
    value = values.front().value;
    return true;
  }
  const LabeledValue* found = findLabel(values, source.label);
  if (!found)
    return false;
  value = found->value;
  return true;
}
}  // namespace

double RuleSet::unitScale(const std::string& units)
{
  // Programs run in inches under G20 and millimetres under G21; messages carry metres (REP-103).
  if (units == "inch")
    return 0.0254;
  if (units == "mm")
    return 0.001;
  if (units == "m" || units == "none")
    return 1.0;
  throw ConfigError("units \"" + units + "\" is not one of inch, mm, m, none");
}

namespace
{
// name, type, topic: what the rule is called and publishes. Appends the name to \p where.
void parseIdentity(const YAML::Node& node, Rule& rule, std::string& where, std::set<std::string>& names)
{
  if (!node.IsMap())
    throw ConfigError(where + ": expected a map");
  rule.name = node["name"] ? node["name"].as<std::string>() : "";
  if (!validName(rule.name))
    throw ConfigError(where + ": \"name\" must be letters, digits and _ (it names a topic)");
  where += " (" + rule.name + ")";
  if (!names.insert(rule.name).second)
    throw ConfigError(where + ": duplicate name");
  const std::string type = node["type"] ? node["type"].as<std::string>() : "";
  if (type == "point")
    rule.type = OutputType::kPoint;
  else if (type == "float64")
    rule.type = OutputType::kFloat64;
  else if (type == "cycle_event")
    rule.type = OutputType::kCycleEvent;
  else
    throw ConfigError(where + ": \"type\" must be point, float64 or cycle_event");
  rule.topic = node["topic"] ? node["topic"].as<std::string>() : "dprnt/" + rule.name;
  if (rule.topic.empty() || rule.topic[0] == '/')
    throw ConfigError(where + ": \"topic\" must be a relative name");
}

// regex, labels: which lines the rule matches.
void parseMatch(const YAML::Node& node, Rule& rule, const std::string& where)
{
  if (node["regex"])
  {
    rule.regex_text = node["regex"].as<std::string>();
    try
    {
      rule.regex = std::regex(rule.regex_text, std::regex::ECMAScript | std::regex::optimize);
    }
    catch (const std::regex_error& e)
    {
      throw ConfigError(where + ": bad regex \"" + rule.regex_text + "\": " + e.what());
    }
    rule.has_regex = true;
  }
  if (node["labels"])
  {
    for (const auto& label : node["labels"])
      rule.labels.push_back(label.as<std::string>());
  }
  if (!rule.has_regex && rule.labels.empty())
    throw ConfigError(where + R"(: give "regex", "labels" or both)");
}

// x, y, z, value, part_count, cycle_time, program: where the numbers come from.
void parseSources(const YAML::Node& node, Rule& rule, const std::string& where)
{
  rule.x = parseSource(node["x"], where);
  rule.y = parseSource(node["y"], where);
  rule.z = parseSource(node["z"], where);
  rule.value = parseSource(node["value"], where);
  rule.part_count = parseSource(node["part_count"], where);
  rule.cycle_time = parseSource(node["cycle_time"], where);
  if (node["program"])
  {
    const ValueSource program = parseSource(node["program"], where);
    if (program.group < 0)
      throw ConfigError(where + R"(: "program" must be a capture group ("$1"))");
    rule.program_group = program.group;
  }
}

// units, frame, state, event: what each type of output needs.
void parseOutput(const YAML::Node& node, Rule& rule, const std::string& where, const std::string& default_units)
{
  if (rule.type != OutputType::kPoint && node["state"])
    throw ConfigError(where + ": \"state\" is for point rules (a position)");
  switch (rule.type)
  {
    case OutputType::kPoint:
      // A probe hit is a length in all three axes: the program's unit unless told otherwise.
      rule.units = node["units"] ? node["units"].as<std::string>() : default_units;
      if (rule.x.empty())
        rule.x.label = "X";
      if (rule.y.empty())
        rule.y.label = "Y";
      if (rule.z.empty())
        rule.z.label = "Z";
      rule.frame = node["frame"] ? node["frame"].as<std::string>() : "work";
      if (rule.frame.empty())
        throw ConfigError(where + ": \"frame\" is empty");
      rule.state = parseStateField(node["state"], rule.frame, where);
      break;
    case OutputType::kFloat64:
      // A plain number is not necessarily a length: scaled only when units are given.
      rule.units = node["units"] ? node["units"].as<std::string>() : "none";
      break;
    case OutputType::kCycleEvent:
      rule.units = "none";
      rule.event = parseEvent(node["event"] ? node["event"].as<std::string>() : "", where);
      break;
  }
  if (rule.units == "program")
    rule.units = default_units;
  rule.scale = RuleSet::unitScale(rule.units);
}

// Every capture group a source names exists in the regex.
void checkGroups(const Rule& rule, const std::string& where)
{
  const auto check_group = [&](const ValueSource& source)
  {
    if (source.group > 0 && (!rule.has_regex || static_cast<size_t>(source.group) > rule.regex.mark_count()))
      throw ConfigError(where + ": capture group " + source.describe() + " does not exist in the regex");
  };
  for (const ValueSource* source : {&rule.x, &rule.y, &rule.z, &rule.value, &rule.part_count, &rule.cycle_time})
    check_group(*source);
  if (rule.program_group > 0)
    check_group(ValueSource{"", rule.program_group});
}

// One rule of the list; errors name it ("DPRNT rule #2 (probe): ...").
Rule parseRule(const YAML::Node& node, size_t index, const std::string& default_units, std::set<std::string>& names)
{
  Rule rule;
  std::string where = "DPRNT rule #" + std::to_string(index + 1);
  try
  {
    parseIdentity(node, rule, where, names);
    parseMatch(node, rule, where);
    parseSources(node, rule, where);
    parseOutput(node, rule, where, default_units);
    checkGroups(rule, where);
  }
  catch (const YAML::Exception& e)
  {
    throw ConfigError(where + ": " + e.what());
  }
  catch (const ConfigError& e)
  {
    const std::string message = e.what();
    throw ConfigError(message.rfind("DPRNT rule", 0) == 0 ? message : where + ": " + message);
  }
  return rule;
}
}  // namespace

RuleSet RuleSet::fromYaml(const std::string& text, const std::string& default_units)
{
  YAML::Node root;
  try
  {
    root = YAML::Load(text);
  }
  catch (const YAML::Exception& e)
  {
    throw ConfigError(std::string("DPRNT rules: invalid YAML: ") + e.what());
  }
  const YAML::Node list = root.IsMap() ? root["rules"] : root;
  RuleSet set;
  if (!list || list.IsNull())
  {
    return set;
  }
  if (!list.IsSequence())
  {
    throw ConfigError("DPRNT rules: expected a list under \"rules\"");
  }
  unitScale(default_units);
  std::set<std::string> names;
  for (size_t i = 0; i < list.size(); ++i)
  {
    set.rules_.push_back(parseRule(list[i], i, default_units, names));
  }
  return set;
}

RuleSet RuleSet::fromFile(const std::string& path, const std::string& default_units)
{
  std::ifstream file(path);
  if (!file)
  {
    throw ConfigError("DPRNT rules: cannot read " + path);
  }
  std::ostringstream text;
  text << file.rdbuf();
  try
  {
    return fromYaml(text.str(), default_units);
  }
  catch (const ConfigError& e)
  {
    throw ConfigError(path + ": " + e.what());
  }
}

size_t RuleSet::evaluate(std::string_view line, const std::vector<LabeledValue>& values,
                         std::vector<RuleOutput>& out) const
{
  out.clear();
  const std::string text(line);
  std::smatch match;
  for (size_t i = 0; i < rules_.size(); ++i)
  {
    const Rule& rule = rules_[i];
    bool all_labels = true;
    for (const auto& label : rule.labels)
    {
      if (!findLabel(values, label))
      {
        all_labels = false;
        break;
      }
    }
    if (!all_labels)
      continue;
    const std::smatch* groups = nullptr;
    if (rule.has_regex)
    {
      if (!std::regex_search(text, match, rule.regex))
        continue;
      groups = &match;
    }
    RuleOutput output;
    output.rule = i;
    bool complete = true;
    switch (rule.type)
    {
      case OutputType::kPoint:
        complete = resolve(rule.x, values, groups, output.x) && resolve(rule.y, values, groups, output.y) &&
                   resolve(rule.z, values, groups, output.z);
        output.x *= rule.scale;
        output.y *= rule.scale;
        output.z *= rule.scale;
        break;
      case OutputType::kFloat64:
        complete = resolve(rule.value, values, groups, output.value);
        output.value *= rule.scale;
        break;
      case OutputType::kCycleEvent:
      {
        double number = 0;
        if (!rule.part_count.empty() && resolve(rule.part_count, values, groups, number) && isPartCount(number))
          output.part_count = static_cast<int64_t>(number);
        if (!rule.cycle_time.empty() && resolve(rule.cycle_time, values, groups, number) && std::isfinite(number) &&
            number >= 0)
          output.cycle_time = number;
        if (rule.program_group > 0 && groups && static_cast<size_t>(rule.program_group) < groups->size())
          output.program = (*groups)[rule.program_group].str();
        break;
      }
    }
    if (complete)
    {
      out.push_back(std::move(output));
    }
  }
  return out.size();
}
}  // namespace dprnt
}  // namespace cnc_bridge
