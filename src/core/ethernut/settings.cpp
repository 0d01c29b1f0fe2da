// Reader of the qCNC settings file (settings.h; docs/protocols/ethernut.md#settings-file).
#include "cnc_bridge/ethernut/settings.h"

#include <charconv>
#include <fstream>
#include <sstream>

namespace cnc_bridge
{
namespace ethernut
{
namespace
{
std::string trim(const std::string& text)
{
  const char* space = " \t\r\n\f\v";
  const size_t first = text.find_first_not_of(space);
  if (first == std::string::npos)
  {
    return "";
  }
  return text.substr(first, text.find_last_not_of(space) - first + 1);
}

bool hasWord(const std::string& line, const std::string& word)
{
  std::istringstream words(line);
  std::string w;
  while (words >> w)
  {
    if (w == word)
    {
      return true;
    }
  }
  return false;
}

template <typename T>
T parseNumber(const std::string& value, T low, T high, const std::string& where, const std::string& name)
{
  T result{};
  auto r = std::from_chars(value.data(), value.data() + value.size(), result);
  if (r.ec != std::errc() || r.ptr != value.data() + value.size() || result < low || result > high)
  {
    throw ConfigError(where + ": " + name + " must be a whole number from " + std::to_string(low) + " to " +
                      std::to_string(high) + ", not '" + value + "'");
  }
  return result;
}
}  // namespace

Settings parseSettings(std::istream& in, const std::string& source)
{
  Settings settings;
  bool marker = false;
  std::string raw;
  unsigned line_number = 0;
  while (std::getline(in, raw))
  {
    ++line_number;
    const std::string where = source + ":" + std::to_string(line_number);
    if (raw.size() > 4096)
    {
      throw ConfigError(where + ": line longer than 4096 bytes");
    }
    const std::string line = trim(raw.substr(0, raw.find('#')));
    if (line.empty())
    {
      continue;
    }
    const size_t bar = line.find('|');
    if (bar == std::string::npos)
    {
      // 'TSS' "has to be present somewhere": as a word of its own on a line without '|' ("TSS",
      // "qCNC TSS v2"), or as a setting's name (TSS|...). Not inside a comment, and not inside a
      // longer word; other lines without '|' are errors.
      if (hasWord(line, "TSS"))
      {
        marker = true;
        continue;
      }
      throw ConfigError(where + ": expected NAME|value, got '" + line + "'");
    }
    const std::string name = trim(line.substr(0, bar));
    const std::string value = trim(line.substr(bar + 1));
    if (name.empty())
    {
      throw ConfigError(where + ": setting without a name");
    }
    if (value.find('|') != std::string::npos)
    {
      throw ConfigError(where + ": a value may not contain '|'");
    }
    if (name == "TSS")
    {
      marker = true;
    }
    settings.values[name] = value;
    if (name == "INET_ADD")
    {
      if (value.empty())
      {
        throw ConfigError(where + ": INET_ADD is empty");
      }
      settings.address = value;
    }
    else if (name == "INET_PORT")
    {
      settings.port = parseNumber<uint16_t>(value, 1, 65535, where, name);
    }
    else if (name == "INET_DEL")
    {
      // qCNC's documentation writes "x ms"; accept a trailing "ms".
      std::string number = value;
      if (number.size() > 2 && number.compare(number.size() - 2, 2, "ms") == 0)
      {
        number = trim(number.substr(0, number.size() - 2));
      }
      settings.dead_link_ms = parseNumber<uint32_t>(number, 1, 3600000, where, name);
    }
    else if (name == "PROG_CNCkill")
    {
      settings.kill_enabled = parseNumber<int>(value, 0, 1, where, name) == 1;
    }
    else if (name == "SERIAL_DEV")
    {
      settings.serial_device = value;
    }
  }
  if (in.bad())
  {
    throw ConfigError(source + ": read error");
  }
  if (!marker)
  {
    throw ConfigError(source + ": not a qCNC settings file (no 'TSS' marker)");
  }
  return settings;
}

Settings readSettingsFile(const std::string& path)
{
  std::ifstream in(path);
  if (!in)
  {
    throw ConfigError("cannot open settings file " + path);
  }
  return parseSettings(in, path);
}
}  // namespace ethernut
}  // namespace cnc_bridge
