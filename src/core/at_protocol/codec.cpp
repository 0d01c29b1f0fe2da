// Encoding, decoding and stream reassembly of the '@'-protocol (see codec.h for the wire format).
#include "cnc_bridge/at_protocol/codec.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
template <class... F>
struct Overloaded : F...
{
  using F::operator()...;
};
template <class... F>
Overloaded(F...) -> Overloaded<F...>;

bool isBlank(char c)
{
  return c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

std::string_view trim(std::string_view text)
{
  while (!text.empty() && isBlank(text.front()))
  {
    text.remove_prefix(1);
  }
  while (!text.empty() && isBlank(text.back()))
  {
    text.remove_suffix(1);
  }
  return text;
}

/// Printable form of received text for error messages: control bytes as \xNN, cut at 40 bytes.
std::string quote(std::string_view text)
{
  std::string out = "\"";
  for (size_t i = 0; i < text.size() && i < 40; ++i)
  {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f)
    {
      out += static_cast<char>(c);
    }
    else
    {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02X", c);
      out += hex;
    }
  }
  if (text.size() > 40)
  {
    out += "...";
  }
  return out + "\"";
}

/// Splits at runs of blanks.
std::vector<std::string_view> fields(std::string_view text)
{
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < text.size())
  {
    while (i < text.size() && isBlank(text[i]))
    {
      ++i;
    }
    const size_t start = i;
    while (i < text.size() && !isBlank(text[i]))
    {
      ++i;
    }
    if (i > start)
    {
      out.push_back(text.substr(start, i - start));
    }
  }
  return out;
}

/// A decimal integer with an optional sign, nothing else, within [low, high].
int64_t parseInt(std::string_view field, int64_t low, int64_t high, const char* what, std::string_view message)
{
  std::string_view digits = field;
  if (!digits.empty() && digits.front() == '+')
  {
    digits.remove_prefix(1);  // from_chars takes '-' but not '+'
  }
  int64_t value = 0;
  const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (digits.empty() || error == std::errc::invalid_argument || end != digits.data() + digits.size())
  {
    throw ProtocolError("'@'-protocol: " + std::string(what) + " " + quote(field) + " in " + quote(message) +
                        " is not an integer");
  }
  if (error == std::errc::result_out_of_range || value < low || value > high)
  {
    throw ProtocolError("'@'-protocol: " + std::string(what) + " " + quote(field) + " in " + quote(message) +
                        " is outside " + std::to_string(low) + ".." + std::to_string(high));
  }
  return value;
}

void checkRange(int64_t value, int64_t low, int64_t high, const char* what)
{
  if (value < low || value > high)
  {
    throw ProtocolError("'@'-protocol: " + std::string(what) + " " + std::to_string(value) + " is outside " +
                        std::to_string(low) + ".." + std::to_string(high));
  }
}

constexpr int64_t kMinPulses = std::numeric_limits<int32_t>::min();
constexpr int64_t kMaxPulses = std::numeric_limits<int32_t>::max();
// Tool numbers and lengths: the ESPRIT paper (docs/protocols/at_protocol.md#source) only says "integer"; these bounds
// reject garbage, not tools.
constexpr int64_t kMaxTool = 9999;
constexpr int64_t kMaxToolLengthMm = 10000;

/// Cuts \p data at any byte for which \p is_end is true; shared by both reassemblers.
template <class IsEnd>
CommandReassembler::Result cut(std::string& buffer, bool& overflow, const uint8_t* data, size_t size, IsEnd is_end,
                               const char* what)
{
  CommandReassembler::Result result;
  for (size_t i = 0; i < size; ++i)
  {
    const char c = static_cast<char>(data[i]);
    if (is_end(c))
    {
      if (overflow)
      {
        overflow = false;  // the end of the overlong message: resynchronised
      }
      else
      {
        const std::string_view message = trim(buffer);
        if (!message.empty() || c == '@')
        {
          result.messages.emplace_back(message);
        }
      }
      buffer.clear();
      continue;
    }
    if (overflow)
    {
      continue;
    }
    if (buffer.empty() && isBlank(c))
    {
      continue;
    }
    if (buffer.size() >= kMaxMessageLength)
    {
      result.errors.push_back(std::string("'@'-protocol: ") + what + " longer than " +
                              std::to_string(kMaxMessageLength) + " bytes dropped: " + quote(buffer));
      buffer.clear();
      overflow = true;
      continue;
    }
    buffer.push_back(c);
  }
  return result;
}
}  // namespace

char toChar(Axis axis)
{
  return "XYZ"[static_cast<int>(axis)];
}

Axis axisFromChar(char c)
{
  switch (c)
  {
    case 'X':
    case 'x':
      return Axis::kX;
    case 'Y':
    case 'y':
      return Axis::kY;
    case 'Z':
    case 'z':
      return Axis::kZ;
    default:
      throw ProtocolError("'@'-protocol: " + quote(std::string_view(&c, 1)) + " is not an axis (X, Y or Z)");
  }
}

int scaledValue(double value, double full_scale, const std::string& what)
{
  if (!std::isfinite(value) || !(value >= 0.0) || !(value <= full_scale))
  {
    char text[80];
    std::snprintf(text, sizeof text, "%.17g is outside 0..%g", value, full_scale);
    throw ProtocolError(what + " " + text);
  }
  return static_cast<int>(std::lround(value / full_scale * kMaxFeed));
}

ToolChange toolChangeFor(int64_t tool, double length_m)
{
  checkRange(tool, 0, kMaxTool, "tool number");
  const double length_mm = length_m * 1000.0;
  const auto refuse = [&](const char* why)
  {
    char text[120];
    std::snprintf(text, sizeof text, "'@'-protocol: tool length %.17g m %s", length_m, why);
    throw ProtocolError(text);
  };
  if (!std::isfinite(length_mm) || length_mm < 0.0 || length_mm > double(kMaxToolLengthMm))
  {
    refuse("is outside 0..10 m");
  }
  const double whole = std::round(length_mm);
  // A metre value of whole millimetres may be off by the binary fraction (0.05 * 1000): 1 nm slack.
  if (std::fabs(length_mm - whole) > 1e-6)
  {
    refuse("is not a whole millimetre (the tool change carries whole millimetres)");
  }
  return ToolChange{static_cast<int>(tool), static_cast<int>(whole)};
}

void appendSetpoint(const Setpoint& setpoint, std::string& out)
{
  const auto append_number = [&out](int64_t value)
  {
    char digits[24];  // an int64 needs at most 20
    auto* const end = std::to_chars(digits, digits + sizeof(digits), value).ptr;
    out.append(digits, static_cast<size_t>(end - digits));
  };
  for (int axis = 0; axis < 3; ++axis)
  {
    checkRange(setpoint.feed[axis], -kMaxFeed, kMaxFeed, "setpoint feed");
  }
  for (int axis = 0; axis < 3; ++axis)
  {
    append_number(setpoint.feed[axis]);
    out.push_back(' ');
    append_number(setpoint.position[axis]);
    out.push_back(axis < 2 ? ' ' : '@');
  }
}

std::string encode(const Command& command)
{
  return std::visit(Overloaded{[](const AutoMode&) { return std::string("A@"); },
                               [](const JogMode& c) { return std::string("J") + toChar(c.axis) + "@"; },
                               [](const Machining& c) { return std::string(c.start ? "M1@" : "M0@"); },
                               [](const StartOperation& c) { return std::string(c.coolant ? "P1@" : "P0@"); },
                               [](const Spindle& c)
                               {
                                 checkRange(c.speed, 0, kMaxFeed, "spindle speed");
                                 return "S" + std::to_string(c.speed) + "@";
                               },
                               [](const JogFeed& c)
                               {
                                 checkRange(c.feed, 0, kMaxFeed, "jog feedrate");
                                 return "F" + std::to_string(c.feed) + "@";
                               },
                               [](const ToolChange& c)
                               {
                                 checkRange(c.tool, 0, kMaxTool, "tool number");
                                 checkRange(c.length_mm, 0, kMaxToolLengthMm, "tool length (mm)");
                                 return "T" + std::to_string(c.tool) + " " + std::to_string(c.length_mm) + "@";
                               },
                               [](const Home&) { return std::string("H@"); },
                               [](const Setpoint& c)
                               {
                                 std::string out;
                                 appendSetpoint(c, out);
                                 return out;
                               },
                               [](const EndOperation&) { return std::string("#@"); }},
                    command);
}

Command decodeCommand(std::string_view raw)
{
  const std::string_view message = trim(raw);
  if (message.empty())
  {
    throw ProtocolError("'@'-protocol: empty message");
  }
  const char head = message.front();
  const std::string_view rest = message.substr(1);
  const auto no_argument = [&](Command command) -> Command
  {
    if (!trim(rest).empty())
    {
      throw ProtocolError("'@'-protocol: " + quote(message) + " has trailing characters");
    }
    return command;
  };
  const auto flag = [&](const char* what) -> bool
  {
    const std::string_view value = trim(rest);
    if (value != "0" && value != "1")
    {
      throw ProtocolError("'@'-protocol: " + std::string(what) + " " + quote(message) + " must be followed by 0 or 1");
    }
    return value == "1";
  };
  switch (head)
  {
    case 'A':
      return no_argument(AutoMode{});
    case 'H':
      return no_argument(Home{});
    case '#':
      return no_argument(EndOperation{});
    case 'J':
    {
      const std::string_view axis = trim(rest);
      if (axis.size() != 1)
      {
        throw ProtocolError("'@'-protocol: jog mode " + quote(message) + " must name one axis (JX, JY, JZ)");
      }
      return JogMode{axisFromChar(axis.front())};
    }
    case 'M':
      return Machining{flag("machining")};
    case 'P':
      return StartOperation{flag("operation start")};
    case 'S':
      return Spindle{static_cast<int>(parseInt(trim(rest), 0, kMaxFeed, "spindle speed", message))};
    case 'F':
      return JogFeed{static_cast<int>(parseInt(trim(rest), 0, kMaxFeed, "jog feedrate", message))};
    case 'T':
    {
      const auto parts = fields(rest);
      if (parts.size() != 2)
      {
        throw ProtocolError("'@'-protocol: tool change " + quote(message) + " must be T<tool> <length mm>");
      }
      return ToolChange{static_cast<int>(parseInt(parts[0], 0, kMaxTool, "tool number", message)),
                        static_cast<int>(parseInt(parts[1], 0, kMaxToolLengthMm, "tool length (mm)", message))};
    }
    default:
      break;
  }
  if (head == '-' || head == '+' || (head >= '0' && head <= '9'))
  {
    const auto parts = fields(message);
    if (parts.size() != 6)
    {
      throw ProtocolError("'@'-protocol: setpoint " + quote(message) + " has " + std::to_string(parts.size()) +
                          " fields, not 6 (feed and position per axis)");
    }
    Setpoint setpoint;
    for (size_t axis = 0; axis < 3; ++axis)
    {
      setpoint.feed[axis] = static_cast<int>(parseInt(parts[2 * axis], -kMaxFeed, kMaxFeed, "setpoint feed", message));
      setpoint.position[axis] =
          static_cast<int32_t>(parseInt(parts[2 * axis + 1], kMinPulses, kMaxPulses, "setpoint position", message));
    }
    return setpoint;
  }
  throw ProtocolError("'@'-protocol: unknown message " + quote(message));
}

std::string describe(const Command& command)
{
  return std::visit(Overloaded{[](const AutoMode&) { return std::string("auto mode (A@)"); },
                               [](const JogMode& c) { return std::string("jog mode (J") + toChar(c.axis) + "@)"; },
                               [](const Machining& c)
                               { return std::string(c.start ? "start of machining (M1@)" : "end of machining (M0@)"); },
                               [](const StartOperation&) { return std::string("start of operation (P@)"); },
                               [](const Spindle&) { return std::string("spindle speed (S@)"); },
                               [](const JogFeed&) { return std::string("jog feedrate (F@)"); },
                               [](const ToolChange&) { return std::string("tool change (T@)"); },
                               [](const Home&) { return std::string("go home (H@)"); },
                               [](const Setpoint&) { return std::string("setpoint"); },
                               [](const EndOperation&) { return std::string("end of operation (#@)"); }},
                    command);
}

CommandReassembler::Result CommandReassembler::feed(const uint8_t* data, size_t size)
{
  return cut(
      buffer_, overflow_, data, size, [](char c) { return c == '@'; }, "message");
}

std::string encode(const Report& report)
{
  return std::visit(Overloaded{[](const EStopReport& r) { return std::string(r.active ? "E1\n" : "E0\n"); },
                               [](const AutoModeReport&) { return std::string("A\n"); },
                               [](const JogModeReport& r) { return std::string("J") + toChar(r.axis) + "\n"; },
                               [](const PositionReport& r)
                               {
                                 return std::to_string(r.position[0]) + " " + std::to_string(r.position[1]) + " " +
                                        std::to_string(r.position[2]) + "\n";
                               },
                               [](const HomeReport&) { return std::string("H\n"); }},
                    report);
}

Report parseReport(std::string_view raw)
{
  const std::string_view line = trim(raw);
  if (line.empty())
  {
    throw ProtocolError("'@'-protocol: empty report line");
  }
  if (line == "A")
  {
    return AutoModeReport{};
  }
  if (line == "H")
  {
    return HomeReport{};
  }
  if (line == "E1" || line == "E0")
  {
    return EStopReport{line == "E1"};
  }
  if (line.size() == 2 && line.front() == 'J')
  {
    return JogModeReport{axisFromChar(line[1])};
  }
  const char head = line.front();
  if (head == '-' || head == '+' || (head >= '0' && head <= '9'))
  {
    const auto parts = fields(line);
    if (parts.size() != 3)
    {
      throw ProtocolError("'@'-protocol: position report " + quote(line) + " has " + std::to_string(parts.size()) +
                          " fields, not 3 (X Y Z in pulses)");
    }
    PositionReport report;
    for (int axis = 0; axis < 3; ++axis)
    {
      report.position[axis] = static_cast<int32_t>(parseInt(parts[axis], kMinPulses, kMaxPulses, "position", line));
    }
    return report;
  }
  throw ProtocolError("'@'-protocol: unknown report " + quote(line));
}

LineReassembler::Result LineReassembler::feed(const uint8_t* data, size_t size)
{
  return cut(
      buffer_, overflow_, data, size, [](char c) { return c == '\n' || c == '\r'; }, "report line");
}
}  // namespace at_protocol
}  // namespace cnc_bridge
