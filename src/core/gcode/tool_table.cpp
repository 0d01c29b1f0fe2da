// Tool tables for cutter compensation: LinuxCNC's .tbl format (one tool a line, words T P D Z ...
// and a ';' comment, D the diameter; see the LinuxCNC manual, "Tool Table Format") and a small
// YAML form for shops without LinuxCNC.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace gcode
{
void ToolTable::setRadius(int32_t tool, double radius_mm)
{
  auto it = std::lower_bound(radius_mm_.begin(), radius_mm_.end(), tool,
                             [](const std::pair<int32_t, double>& e, int32_t t) { return e.first < t; });
  if (it != radius_mm_.end() && it->first == tool)
  {
    it->second = radius_mm;
  }
  else
  {
    radius_mm_.insert(it, {tool, radius_mm});
  }
}

double ToolTable::radius(int32_t tool) const
{
  auto it = std::lower_bound(radius_mm_.begin(), radius_mm_.end(), tool,
                             [](const std::pair<int32_t, double>& e, int32_t t) { return e.first < t; });
  return it != radius_mm_.end() && it->first == tool ? it->second : -1.0;
}

ToolTable ToolTable::parseLinuxCnc(std::istream& in, const std::string& name, Units units)
{
  ToolTable table;
  const double scale = units == Units::kInches ? 25.4 : 1.0;
  std::string line;
  int number = 0;
  while (std::getline(in, line))
  {
    ++number;
    const auto semicolon = line.find(';');
    if (semicolon != std::string::npos)
    {
      line.resize(semicolon);
    }
    std::istringstream words(line);
    std::string word;
    long tool = -1;
    double diameter = -1.0;
    while (words >> word)
    {
      const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(word[0])));
      const std::string rest = word.substr(1);
      char* end = nullptr;
      const double value = std::strtod(rest.c_str(), &end);
      if (rest.empty() || *end != '\0' || !std::isfinite(value))
      {
        throw ConfigError("tool table " + name + " line " + std::to_string(number) + ": \"" + word +
                          "\" is not a letter and a number");
      }
      if (letter == 'T')
      {
        tool = static_cast<long>(value);
      }
      else if (letter == 'D')
      {
        diameter = value;
      }
    }
    if (tool < 0 && diameter < 0)
    {
      continue;  // blank or comment line
    }
    if (tool < 0 || diameter < 0)
    {
      throw ConfigError("tool table " + name + " line " + std::to_string(number) +
                        ": a tool needs T (number) and D (diameter, not negative)");
    }
    table.setRadius(static_cast<int32_t>(tool), diameter * scale / 2.0);
  }
  return table;
}

ToolTable ToolTable::parseYaml(const std::string& text, const std::string& name)
{
  ToolTable table;
  try
  {
    const YAML::Node root = YAML::Load(text);
    const YAML::Node tools = root["tools"];
    if (!tools || !tools.IsMap())
    {
      throw ConfigError("tool table " + name + ": needs a map 'tools: {1: {diameter: 6.0}}' (mm)");
    }
    for (const auto& entry : tools)
    {
      const int32_t tool = entry.first.as<int32_t>();
      const YAML::Node& v = entry.second;
      double radius = -1.0;
      if (v["radius"])
      {
        radius = v["radius"].as<double>();
      }
      else if (v["diameter"])
      {
        radius = v["diameter"].as<double>() / 2.0;
      }
      if (!(radius >= 0.0) || !std::isfinite(radius))
      {
        throw ConfigError("tool table " + name + ": tool " + std::to_string(tool) +
                          " needs 'diameter' or 'radius' (mm, not negative)");
      }
      table.setRadius(tool, radius);
    }
  }
  catch (const YAML::Exception& e)
  {
    throw ConfigError("tool table " + name + ": " + e.what());
  }
  return table;
}

ToolTable ToolTable::load(const std::string& path, Units units)
{
  std::ifstream in(path);
  if (!in)
  {
    throw ConfigError("cannot read tool table " + path);
  }
  const bool yaml = path.size() > 5 &&
                    (path.compare(path.size() - 5, 5, ".yaml") == 0 || path.compare(path.size() - 4, 4, ".yml") == 0);
  if (yaml)
  {
    std::ostringstream text;
    text << in.rdbuf();
    return parseYaml(text.str(), path);
  }
  return parseLinuxCnc(in, path, units);
}
}  // namespace gcode
}  // namespace cnc_bridge
