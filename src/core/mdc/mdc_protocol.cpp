// Haas MDC query text, reply parsing, reply matching and state mapping (see mdc_protocol.h).
#include "cnc_bridge/mdc/mdc_protocol.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace mdc
{
namespace
{
bool isSpace(char c)
{
  return c == ' ' || c == '\t';
}

std::string trim(const std::string& text)
{
  size_t begin = 0, end = text.size();
  while (begin < end && isSpace(text[begin]))
    ++begin;
  while (end > begin && isSpace(text[end - 1]))
    --end;
  return text.substr(begin, end - begin);
}

// Upper case with runs of spaces collapsed to one: "p.o.  time" -> "P.O. TIME".
std::string normalise(const std::string& text)
{
  std::string out;
  for (char c : trim(text))
  {
    if (isSpace(c))
    {
      if (!out.empty() && out.back() != ' ')
        out.push_back(' ');
      continue;
    }
    out.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  return out;
}

bool isDigit(char c)
{
  return c >= '0' && c <= '9';
}

struct KeyEntry
{
  const char* key;
  ReplyKind kind;
};

// First field of each reply, as the Haas MDC documentation lists them, compared with their spaces
// removed (see keyOf).
constexpr KeyEntry kKeys[] = {
    {"SERIALNUMBER", ReplyKind::kSerialNumber},
    {"SOFTWAREVERSION", ReplyKind::kSoftwareVersion},
    {"SOFTWAREVER", ReplyKind::kSoftwareVersion},
    {"MODEL", ReplyKind::kModel},
    {"MODE", ReplyKind::kMode},
    {"TOOLCHANGES", ReplyKind::kToolChanges},
    {"USINGTOOL", ReplyKind::kToolInUse},
    {"P.O.TIME", ReplyKind::kPowerOnTime},
    {"C.S.TIME", ReplyKind::kMotionTime},
    {"LASTCYCLE", ReplyKind::kLastCycle},
    {"PREVCYCLE", ReplyKind::kPreviousCycle},
    {"M30#1", ReplyKind::kPartsCounter1},
    {"M30#2", ReplyKind::kPartsCounter2},
    {"PROGRAM", ReplyKind::kProgramStatus},
    {"STATUS", ReplyKind::kProgramStatus},
    {"MACRO", ReplyKind::kMacro},
    {"?", ReplyKind::kUnknownQuery},
    // The Classic serial port's answers to a query it does not know or cannot read (Haas operator's
    // manual, Setting 143; the Atsora Pomamo Haas serial module reads both).
    {"UNKNOWN", ReplyKind::kUnknownQuery},
    {"INVALIDNUMBER", ReplyKind::kUnknownQuery},
    {"!", ReplyKind::kWriteAck},
};

// A reply key as compared with kKeys: upper case, no spaces, no trailing full stop. Real replies
// and client code spell the same key "C.S. TIME" and "C.S.TIME", and the manual quotes "UNKNOWN.".
std::string keyOf(const std::string& field)
{
  std::string key;
  for (char c : normalise(field))
    if (c != ' ')
      key.push_back(c);
  if (key.size() > 1 && key.back() == '.')
    key.pop_back();
  return key;
}

// A rejection that names no query: the Classic "UNKNOWN" / "INVALID NUMBER".
bool isUnnamedRejection(const Reply& reply)
{
  return reply.kind == ReplyKind::kUnknownQuery && keyOf(reply.fields[0]) != "?";
}

// Length of a query echo at the start of \p text ("?Q500", "?Q600 5021", "Q104"), or 0 if none.
// An echo is the query letter and digits, optionally preceded by '?', optionally followed by one
// numeric argument; a reply key never starts with a letter directly followed by a digit.
size_t echoLength(const std::string& text)
{
  size_t i = 0;
  if (i < text.size() && text[i] == '?')
    ++i;
  if (i >= text.size() || (std::toupper(static_cast<unsigned char>(text[i])) != 'Q' &&
                           std::toupper(static_cast<unsigned char>(text[i])) != 'E'))
    return 0;
  ++i;
  const size_t digits = i;
  while (i < text.size() && isDigit(text[i]))
    ++i;
  if (i == digits)
    return 0;
  // Optional argument: spaces then a number, which must end at a space or the end of the text.
  size_t j = i;
  while (j < text.size() && isSpace(text[j]))
    ++j;
  if (j > i && j < text.size() && (isDigit(text[j]) || text[j] == '-' || text[j] == '+' || text[j] == '.'))
  {
    size_t k = j + 1;
    while (k < text.size() && (isDigit(text[k]) || text[k] == '.'))
      ++k;
    if (k == text.size() || isSpace(text[k]))
      i = k;
  }
  // An echo is followed by a space, a line end, or the reply key (a letter, '?', '!').
  if (i < text.size() && !isSpace(text[i]) && !std::isalpha(static_cast<unsigned char>(text[i])) && text[i] != '?' &&
      text[i] != '!')
    return 0;
  return i;
}

// "?Q105" -> the query it names (for "?, ?Q105").
std::optional<Query> queryNamed(const std::string& text)
{
  const std::string t = normalise(text);
  const size_t length = echoLength(t);
  if (length == 0 || length != t.size())
    return std::nullopt;
  size_t i = t[0] == '?' ? 1 : 0;
  Query query;
  query.letter = t[i++];
  int code = 0;
  while (i < t.size() && isDigit(t[i]) && code < 100000000)
    code = code * 10 + (t[i++] - '0');
  query.code = code;
  while (i < t.size() && isSpace(t[i]))
    ++i;
  if (i < t.size())
  {
    try
    {
      query.argument = parseNumber(t.substr(i));
    }
    catch (const ProtocolError&)
    {
      return std::nullopt;
    }
  }
  return query;
}

// The most a number on the wire carries: whole numbers below 1e15 (15 digits), fractions to 6
// decimals. A value outside that is refused (formatNumber), never cut to fit.
constexpr double kMaxWireMagnitude = 1e15;
constexpr int kWireDecimals = 6;

// A number as the control reads it: whole numbers without a point, others with up to 6 decimals and
// no trailing zeros. \throws ProtocolError if the text would not read back as exactly \p value.
std::string formatNumber(double value)
{
  const auto refuse = [&](const std::string& why) -> std::string
  {
    char shown[40];
    std::snprintf(shown, sizeof shown, "%.17g", value);
    throw ProtocolError(std::string("value ") + shown + " cannot be written exactly: " + why);
  };
  if (!std::isfinite(value))
    return refuse("MDC numbers are finite");
  if (!(std::fabs(value) < kMaxWireMagnitude))
    return refuse("MDC numbers carry at most 15 digits before the point (magnitude below 1e15)");
  char buffer[64];
  if (value == std::floor(value))
  {
    std::snprintf(buffer, sizeof buffer, "%.0f", value);
    return buffer;
  }
  std::snprintf(buffer, sizeof buffer, "%.*f", kWireDecimals, value);
  std::string text = buffer;
  while (!text.empty() && text.back() == '0')
    text.pop_back();
  if (std::strtod(text.c_str(), nullptr) != value)
    return refuse("MDC numbers carry at most 6 decimals (it would arrive as " + text + ")");
  return text;
}

// A Q500 status as sent, upper case, without the full stop the manual writes after "STATUS, BUSY.".
std::string statusText(const std::string& field)
{
  std::string text = normalise(field);
  if (!text.empty() && text.back() == '.')
    text = normalise(text.substr(0, text.size() - 1));
  return text;
}

void requireKind(const Reply& reply, ReplyKind kind)
{
  if (reply.kind != kind)
  {
    throw ProtocolError(std::string("expected a ") + toString(kind) + " reply, got \"" + reply.line + "\"");
  }
}
}  // namespace

std::string Query::text() const
{
  std::string out = "?";
  out.push_back(letter);
  char code_text[16];
  std::snprintf(code_text, sizeof code_text, letter == 'Q' ? "%03d" : "%d", code);
  out += code_text;
  if (argument)
  {
    out += " " + formatNumber(*argument);
  }
  return out;
}

bool Query::operator==(const Query& other) const
{
  return letter == other.letter && code == other.code && argument == other.argument;
}

Query writeQuery(int variable, double value)
{
  Query query;
  query.letter = 'E';
  query.code = variable;
  query.argument = value;
  formatNumber(value);  // refuses what the wire cannot carry before anything is sent
  return query;
}

Query q(int code)
{
  Query query;
  query.code = code;
  return query;
}

Query macroQuery(int variable)
{
  Query query = q(600);
  query.argument = variable;
  return query;
}

const char* toString(ReplyKind kind)
{
  switch (kind)
  {
    case ReplyKind::kSerialNumber:
      return "serial number";
    case ReplyKind::kSoftwareVersion:
      return "software version";
    case ReplyKind::kModel:
      return "model";
    case ReplyKind::kMode:
      return "mode";
    case ReplyKind::kToolChanges:
      return "tool changes";
    case ReplyKind::kToolInUse:
      return "tool in use";
    case ReplyKind::kPowerOnTime:
      return "power-on time";
    case ReplyKind::kMotionTime:
      return "motion time";
    case ReplyKind::kLastCycle:
      return "last cycle";
    case ReplyKind::kPreviousCycle:
      return "previous cycle";
    case ReplyKind::kPartsCounter1:
      return "M30 counter #1";
    case ReplyKind::kPartsCounter2:
      return "M30 counter #2";
    case ReplyKind::kProgramStatus:
      return "program status";
    case ReplyKind::kMacro:
      return "macro";
    case ReplyKind::kUnknownQuery:
      return "unknown query";
    case ReplyKind::kWriteAck:
      return "write acknowledge";
    case ReplyKind::kOther:
      return "unrecognised";
  }
  return "unrecognised";
}

std::optional<Reply> parseReply(const std::string& raw)
{
  // Drop framing: the '>' prompt, STX/ETB of the Classic serial port, CR/LF, other control bytes,
  // and the parity bit of a 7-bit line read as 8 bits.
  std::string line;
  line.reserve(std::min(raw.size(), kMaxLineLength));
  for (char c : raw)
  {
    const auto byte = static_cast<unsigned char>(c) & 0x7F;
    if (byte < 0x20 || byte == 0x7F)
    {
      if (byte == '\t')
        line.push_back(' ');
      continue;
    }
    line.push_back(static_cast<char>(byte));
  }
  line = trim(line);
  while (!line.empty() && line.front() == '>')
    line = trim(line.substr(1));
  while (!line.empty() && line.back() == '>')
    line = trim(line.substr(0, line.size() - 1));
  if (line.empty())
    return std::nullopt;

  Reply reply;
  const size_t echo = echoLength(line);
  if (echo > 0)
  {
    reply.echoed = normalise(line.substr(0, echo));
    line = trim(line.substr(echo));
    if (line.empty())
      return std::nullopt;  // the echo on a line of its own; the reply follows
  }
  reply.line = line;

  size_t start = 0;
  while (start <= line.size())
  {
    size_t comma = line.find(',', start);
    if (comma == std::string::npos)
      comma = line.size();
    reply.fields.push_back(trim(line.substr(start, comma - start)));
    start = comma + 1;
  }
  reply.fields[0] = normalise(reply.fields[0]);
  if (reply.fields.size() == 1 && reply.fields[0].rfind("STATUS ", 0) == 0)
  {
    // "STATUS BUSY" without its comma, as one MTConnect Haas adapter expects it.
    reply.fields = {"STATUS", reply.fields[0].substr(7)};
  }
  const std::string key = keyOf(reply.fields[0]);
  for (const auto& entry : kKeys)
  {
    if (key == entry.key)
    {
      reply.kind = entry.kind;
      break;
    }
  }
  return reply;
}

int queryCodeOf(ReplyKind kind)
{
  switch (kind)
  {
    case ReplyKind::kSerialNumber:
      return 100;
    case ReplyKind::kSoftwareVersion:
      return 101;
    case ReplyKind::kModel:
      return 102;
    case ReplyKind::kMode:
      return 104;
    case ReplyKind::kToolChanges:
      return 200;
    case ReplyKind::kToolInUse:
      return 201;
    case ReplyKind::kPowerOnTime:
      return 300;
    case ReplyKind::kMotionTime:
      return 301;
    case ReplyKind::kLastCycle:
      return 303;
    case ReplyKind::kPreviousCycle:
      return 304;
    case ReplyKind::kPartsCounter1:
      return 402;
    case ReplyKind::kPartsCounter2:
      return 403;
    case ReplyKind::kProgramStatus:
      return 500;
    case ReplyKind::kMacro:
      return 600;
    default:
      return 0;
  }
}

bool answers(const Query& query, const Reply& reply)
{
  if (reply.kind == ReplyKind::kUnknownQuery)
  {
    if (isUnnamedRejection(reply))
      return true;  // only a Classic serial port says this, and it has one peer: the query in flight
    if (reply.fields.size() < 2)
      return false;
    const auto named = queryNamed(reply.fields[1]);
    // The control names the query without its argument: "?, ?Q600" answers any Q600.
    return named && named->letter == query.letter && named->code == query.code &&
           (!named->argument || named->argument == query.argument);
  }
  if (query.letter == 'E')
  {
    return reply.kind == ReplyKind::kWriteAck;
  }
  if (queryCodeOf(reply.kind) != query.code)
  {
    return false;
  }
  if (reply.kind == ReplyKind::kMacro)
  {
    if (!query.argument || reply.fields.size() < 2)
      return false;
    if (reply.fields.size() == 2)
      return true;  // NGC: "MACRO, value" names no variable (see answers() in the header)
    try
    {
      return parseNumber(reply.fields[1]) == *query.argument;
    }
    catch (const ProtocolError&)
    {
      return false;
    }
  }
  return true;
}

double parseNumber(const std::string& text)
{
  std::string t = trim(text);
  if (!t.empty() && t.front() == '+')
    t.erase(0, 1);
  double value = 0.0;
  const auto result = std::from_chars(t.data(), t.data() + t.size(), value);
  if (t.empty() || result.ec != std::errc() || result.ptr != t.data() + t.size() || !std::isfinite(value))
  {
    throw ProtocolError("not a number: \"" + text + "\"");
  }
  return value;
}

std::string valueOf(const Reply& reply)
{
  if (reply.fields.size() < 2 || reply.fields[1].empty())
  {
    throw ProtocolError("reply without a value: \"" + reply.line + "\"");
  }
  return reply.fields[1];
}

int64_t integerOf(const Reply& reply)
{
  const double value = parseNumber(valueOf(reply));
  if (value != std::floor(value) || std::fabs(value) > 9.0e15)
  {
    throw ProtocolError("not an integer: \"" + reply.line + "\"");
  }
  return static_cast<int64_t>(value);
}

MacroReading macroOf(const Reply& reply)
{
  requireKind(reply, ReplyKind::kMacro);
  MacroReading reading;
  if (reply.fields.size() == 2)
  {
    // NGC: "MACRO, value"; the variable is the one the matched query asked for.
    reading.value = parseNumber(reply.fields[1]);
    if (reply.answered && reply.answered->code == 600 && reply.answered->argument)
      reading.variable = static_cast<int>(*reply.answered->argument);
    return reading;
  }
  if (reply.fields.size() != 3)
  {
    throw ProtocolError("macro reply without a value: \"" + reply.line + "\"");
  }
  const double number = parseNumber(reply.fields[1]);
  if (number != std::floor(number) || number < 0 || number > 1.0e6)
  {
    throw ProtocolError("bad macro number in \"" + reply.line + "\"");
  }
  reading.variable = static_cast<int>(number);
  reading.value = parseNumber(reply.fields[2]);
  return reading;
}

ProgramStatus toProgramStatus(const Reply& reply)
{
  requireKind(reply, ReplyKind::kProgramStatus);
  ProgramStatus status;
  const auto& f = reply.fields;
  if (f[0] == "STATUS")
  {
    // "STATUS, BUSY": a program runs; the control says nothing of program or parts.
    if (f.size() < 2 || f[1].empty())
      throw ProtocolError("status reply without a status: \"" + reply.line + "\"");
    status.status = statusText(f[1]);
    return status;
  }
  // "PROGRAM, O00110, IDLE, PARTS, 4523"
  if (f.size() < 3)
    throw ProtocolError("program reply too short: \"" + reply.line + "\"");
  status.program = f[1];
  status.status = statusText(f[2]);
  for (size_t i = 3; i + 1 < f.size(); ++i)
  {
    if (normalise(f[i]) == "PARTS")
    {
      const double parts = parseNumber(f[i + 1]);
      if (parts != std::floor(parts) || parts < 0 || parts > 9.0e15)
        throw ProtocolError("bad part count in \"" + reply.line + "\"");
      status.parts = static_cast<int64_t>(parts);
      break;
    }
  }
  return status;
}

double parseDuration(const std::string& text)
{
  const std::string t = trim(text);
  std::vector<double> parts;
  size_t start = 0;
  while (start <= t.size())
  {
    size_t colon = t.find(':', start);
    if (colon == std::string::npos)
      colon = t.size();
    const std::string part = t.substr(start, colon - start);
    if (part.empty() || !std::all_of(part.begin(), part.end(), [](char c) { return isDigit(c) || c == '.'; }))
      throw ProtocolError("not a duration: \"" + text + "\"");
    parts.push_back(parseNumber(part));
    start = colon + 1;
  }
  if (parts.size() < 2 || parts.size() > 3)
    throw ProtocolError("not a duration: \"" + text + "\"");
  double seconds = 0;
  for (double p : parts)
    seconds = seconds * 60.0 + p;
  return seconds;
}

Execution mapExecution(const std::string& raw)
{
  const std::string s = normalise(raw);
  if (s.find("ALARM") != std::string::npos || s.find("ESTOP") != std::string::npos ||
      s.find("E-STOP") != std::string::npos)
    return Execution::kAlarm;
  if (s.find("FEED HOLD") != std::string::npos || s == "FEEDHOLD" || s.find("SINGLE BLOCK") != std::string::npos ||
      s.find("HOLD") != std::string::npos)
    return Execution::kPaused;
  if (s == "BUSY" || s == "RUNNING" || s == "CYCLE")
    return Execution::kActive;
  if (s == "IDLE")
    return Execution::kReady;
  if (s.find("STOP") != std::string::npos || s.find("RESET") != std::string::npos)
    return Execution::kStopped;
  return Execution::kUnknown;
}

Mode mapMode(const std::string& raw)
{
  std::string s = normalise(raw);
  s.erase(std::remove(s.begin(), s.end(), '('), s.end());
  s.erase(std::remove(s.begin(), s.end(), ')'), s.end());
  s = normalise(s);
  if (s == "MEM" || s == "MEMORY" || s == "AUTO")
    return Mode::kAuto;
  if (s == "MDI")
    return Mode::kMdi;
  if (s == "JOG" || s == "HAND JOG" || s == "HANDLE" || s == "HANDLE JOG")
    return Mode::kManual;
  if (s == "ZERO RET" || s == "ZERO RETURN" || s == "ZERO" || s == "HOME")
    return Mode::kHoming;
  if (s == "EDIT" || s == "LIST PROG" || s == "LIST")
    return Mode::kEdit;
  if (s == "DNC")
    return Mode::kDnc;
  return Mode::kUnknown;
}

const char* toString(Execution execution)
{
  switch (execution)
  {
    case Execution::kUnknown:
      return "unknown";
    case Execution::kReady:
      return "ready";
    case Execution::kActive:
      return "active";
    case Execution::kPaused:
      return "paused";
    case Execution::kStopped:
      return "stopped";
    case Execution::kAlarm:
      return "alarm";
  }
  return "unknown";
}

const char* toString(Mode mode)
{
  switch (mode)
  {
    case Mode::kUnknown:
      return "unknown";
    case Mode::kAuto:
      return "auto";
    case Mode::kManual:
      return "manual";
    case Mode::kMdi:
      return "mdi";
    case Mode::kDnc:
      return "dnc";
    case Mode::kEdit:
      return "edit";
    case Mode::kHoming:
      return "homing";
  }
  return "unknown";
}

std::optional<Query> parseReadOnlyQuery(const std::string& text)
{
  if (text.size() > 32 || !std::all_of(text.begin(), text.end(), [](char c) { return c >= 0x20 && c < 0x7F; }))
    return std::nullopt;
  const auto query = queryNamed(text);
  if (!query || query->letter != 'Q' || query->code < 0 || query->code > 999)
    return std::nullopt;
  const std::string t = normalise(text);
  // Exactly three digits after Q, as the control's documentation writes them.
  const size_t q_at = t[0] == '?' ? 1 : 0;
  if (t.size() < q_at + 4 || !isDigit(t[q_at + 1]) || !isDigit(t[q_at + 2]) || !isDigit(t[q_at + 3]) ||
      (t.size() > q_at + 4 && isDigit(t[q_at + 4])))
    return std::nullopt;
  return query;
}
}  // namespace mdc
}  // namespace cnc_bridge
