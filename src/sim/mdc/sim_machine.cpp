// SimMachine: the scripted Haas control behind sim_haas_mdc (see sim_machine.h).
#include "sim/mdc/sim_machine.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_protocol.h"

namespace cnc_bridge
{
namespace mdc
{
namespace
{
std::string upper(std::string text)
{
  for (auto& c : text)
    c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return text;
}

std::string number(double value, int decimals)
{
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", decimals, value);
  return buffer;
}

std::string hms(double seconds, int hour_digits)
{
  const long long total = static_cast<long long>(seconds);
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%0*lld:%02lld:%02lld", hour_digits, total / 3600, (total / 60) % 60,
                total % 60);
  return buffer;
}

// The printable characters of a line from a client, without leading and trailing spaces.
std::string printableTrimmed(const std::string& raw)
{
  std::string line;
  for (char c : raw)
    if (c >= 0x20 && c < 0x7F)
      line.push_back(c);
  while (!line.empty() && line.back() == ' ')
    line.pop_back();
  while (!line.empty() && line.front() == ' ')
    line.erase(0, 1);
  return line;
}
}  // namespace

// A line of the script being read: where it is, for the errors that name it.
struct SimMachine::ScriptLine
{
  std::string name;
  size_t number = 0;
  std::string text;

  [[noreturn]] void fail(const std::string& why) const
  {
    throw ConfigError(name + ":" + std::to_string(number) + ": " + why + ": \"" + text + "\"");
  }
  double toDouble(const std::string& value) const
  {
    try
    {
      return parseNumber(value);
    }
    catch (const ProtocolError&)
    {
      fail("not a number");
    }
  }
};

SimMachine SimMachine::fromScript(std::istream& in, const std::string& name)
{
  SimMachine machine;
  ScriptLine script;
  script.name = name;
  while (std::getline(in, script.text))
  {
    ++script.number;
    std::string line = script.text.substr(0, script.text.find('#'));
    std::istringstream words(line);
    std::string keyword;
    if (!(words >> keyword))
      continue;
    machine.readStatement(keyword, words, script);
  }
  if (machine.phases_.empty())
  {
    script.number = 0;
    script.text.clear();
    script.fail("no phase");
  }
  return machine;
}

void SimMachine::readStatement(const std::string& keyword, std::istream& words, const ScriptLine& script)
{
  if (keyword == "serial")
    words >> serial_;
  else if (keyword == "software")
    words >> software_;
  else if (keyword == "model")
    words >> model_;
  else if (keyword == "units")
  {
    std::string units;
    words >> units;
    if (units != "inch" && units != "mm")
      script.fail("units must be inch or mm");
    inch_ = units == "inch";
  }
  else if (keyword == "work")
  {
    std::string x, y, z;
    if (!(words >> x >> y >> z))
      script.fail("work needs X Y Z");
    work_[0] = script.toDouble(x);
    work_[1] = script.toDouble(y);
    work_[2] = script.toDouble(z);
  }
  else if (keyword == "var")
  {
    std::string n, value;
    if (!(words >> n >> value))
      script.fail("var needs N VALUE");
    variables_[static_cast<int>(script.toDouble(n))] = script.toDouble(value);
  }
  else if (keyword == "phase")
    phases_.push_back(readPhase(words, script));
  else
    script.fail("unknown statement " + keyword);
}

SimMachine::Phase SimMachine::readPhase(std::istream& words, const ScriptLine& script)
{
  Phase phase;
  phase.line = script.number;
  std::string seconds;
  if (!(words >> seconds))
    script.fail("phase needs SECONDS");
  phase.seconds = script.toDouble(seconds);
  if (!(phase.seconds > 0) || phase.seconds > 1e6)
    script.fail("phase length must be positive");
  std::string item;
  while (words >> item)
  {
    if (item == "drop")
    {
      phase.drop = true;
      continue;
    }
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0)
      script.fail("expected key=value, not " + item);
    std::string value = item.substr(eq + 1);
    for (auto& c : value)
      if (c == '_')
        c = ' ';
    setPhaseKey(phase, item.substr(0, eq), value, script);
  }
  return phase;
}

void SimMachine::setPhaseKey(Phase& phase, const std::string& key, const std::string& value, const ScriptLine& script)
{
  if (key == "parts+")
    phase.parts_increment = static_cast<long long>(script.toDouble(value));
  else if (key == "x")
    phase.x = script.toDouble(value);
  else if (key == "y")
    phase.y = script.toDouble(value);
  else if (key == "z")
    phase.z = script.toDouble(value);
  else if (key == "mode" || key == "status" || key == "program")
    phase.set[key] = upper(value);
  else if (key == "tool" || key == "spindle" || key == "parts")
  {
    script.toDouble(value);
    phase.set[key] = value;
  }
  else if (key.size() > 3 && key.compare(0, 3, "var") == 0)
  {
    const double n = script.toDouble(key.substr(3));
    if (n != std::floor(n) || n < 1 || n > 99999)
      script.fail("varN needs a variable number N, not " + key);
    phase.variables[static_cast<int>(n)] = script.toDouble(value);
  }
  else
    script.fail("unknown key " + key);
}

double SimMachine::timelineSeconds() const
{
  double total = 0;
  for (const auto& phase : phases_)
    total += phase.seconds;
  return total;
}

SimMachine::State SimMachine::stateAt(Clock::time_point now) const
{
  const double total = timelineSeconds();
  const double elapsed = std::max(0.0, std::chrono::duration<double>(now - start_).count());
  State state;
  state.loop = static_cast<long long>(std::floor(elapsed / total));
  double t = elapsed - static_cast<double>(state.loop) * total;
  size_t index = 0;
  while (index + 1 < phases_.size() && t >= phases_[index].seconds)
  {
    t -= phases_[index].seconds;
    ++index;
  }
  state.phase = index;
  const double fraction = std::min(1.0, t / phases_[index].seconds);

  long long increments_per_loop = 0, base_parts = 0;
  for (const auto& phase : phases_)
  {
    increments_per_loop += phase.parts_increment;
    if (phase.set.count("parts"))
      base_parts = std::stoll(phase.set.at("parts"));
  }
  // Settings carry over from the previous loop's end, so apply the whole timeline first when
  // this is not the first loop, then the phases up to the current one.
  double axis_end[3] = {0, 0, 0};
  auto apply_phase = [&](const Phase& phase, double began)
  {
    for (const auto& [n, value] : phase.variables)
      state.variables[n] = {value, began};
    for (const auto& [key, value] : phase.set)
    {
      if (key == "mode")
        state.mode = value;
      else if (key == "status")
        state.status = value;
      else if (key == "program")
        state.program = value;
      else if (key == "tool")
        state.tool = std::stoi(value);
      else if (key == "spindle")
        state.spindle = std::stod(value);
    }
    if (phase.x)
      axis_end[0] = *phase.x;
    if (phase.y)
      axis_end[1] = *phase.y;
    if (phase.z)
      axis_end[2] = *phase.z;
  };
  // When each phase of this loop began (s since start).
  double began = static_cast<double>(state.loop) * total;
  if (state.loop > 0)
  {
    double previous = began - total;
    for (const auto& phase : phases_)
    {
      apply_phase(phase, previous);
      previous += phase.seconds;
    }
  }
  long long parts = 0;
  for (size_t i = 0; i < index; ++i)
  {
    apply_phase(phases_[i], began);
    began += phases_[i].seconds;
    parts += phases_[i].parts_increment;
  }
  const double from[3] = {axis_end[0], axis_end[1], axis_end[2]};
  apply_phase(phases_[index], began);
  parts += phases_[index].parts_increment;
  state.parts = base_parts + state.loop * increments_per_loop + parts;
  state.x = from[0] + (axis_end[0] - from[0]) * fraction;
  state.y = from[1] + (axis_end[1] - from[1]) * fraction;
  state.z = from[2] + (axis_end[2] - from[2]) * fraction;
  return state;
}

std::pair<double, double> SimMachine::lastCycles(Clock::time_point now) const
{
  // Cycles of one loop as (end, length), the end an offset into the loop. A cycle running across
  // the loop's end is not counted.
  std::vector<std::pair<double, double>> cycles;
  std::string status = State().status;
  double offset = 0;
  std::optional<double> started;
  for (const auto& phase : phases_)
  {
    if (phase.set.count("status"))
      status = phase.set.at("status");
    const bool running = status == "BUSY" || status == "FEED HOLD";
    if (running && !started)
      started = offset;
    else if (!running && started)
    {
      cycles.emplace_back(offset, offset - *started);
      started.reset();
    }
    offset += phase.seconds;
  }
  const double total = timelineSeconds();
  const double elapsed = std::max(0.0, std::chrono::duration<double>(now - start_).count());
  const long long loop = static_cast<long long>(std::floor(elapsed / total));
  const double t = elapsed - static_cast<double>(loop) * total;
  // Every cycle ended so far, newest last: those of earlier loops, then this loop's up to t.
  std::vector<double> ended;
  for (long long l = std::max(0LL, loop - 2); l < loop; ++l)
    for (const auto& cycle : cycles)
      ended.push_back(cycle.second);
  for (const auto& cycle : cycles)
    if (cycle.first <= t)
      ended.push_back(cycle.second);
  const double last = ended.empty() ? 0 : ended.back();
  const double previous = ended.size() < 2 ? 0 : ended[ended.size() - 2];
  return {last, previous};
}

bool SimMachine::dropDue(Clock::time_point now)
{
  const State state = stateAt(now);
  if (!phases_[state.phase].drop)
    return false;
  const auto key = std::make_pair(state.loop, state.phase);
  if (last_drop_ == key)
    return false;
  last_drop_ = key;
  return true;
}

std::string SimMachine::answer(const std::string& raw, Clock::time_point now)
{
  const std::string command = upper(printableTrimmed(raw));
  if (command.empty())
    return "";
  if (query_log_)
    *query_log_ << command << std::endl;
  const State s = stateAt(now);

  // A write: ?E<var> <value>.
  if (command.size() > 2 && command[0] == '?' && command[1] == 'E')
    return answerWrite(command, now);
  std::string unknown = classic_ ? "UNKNOWN" : "?, " + command;
  const auto query = parseReadOnlyQuery(command);
  if (!query)
    return unknown;
  switch (query->code)
  {
    case 100:
      return "SERIAL NUMBER, " + serial_;
    case 101:
      return "SOFTWARE VERSION, " + software_;
    case 102:
      return "MODEL, " + model_;
    case 104:
      return "MODE, (" + s.mode + ")";
    case 200:
      return "TOOL CHANGES, " + std::to_string(s.loop * 2);
    case 201:
      return "USING TOOL, " + std::to_string(s.tool);
    case 300:
      return "P.O. TIME, " + hms(std::chrono::duration<double>(now - start_).count() + 100000.0, 5);
    case 301:
      return "C.S. TIME, " + hms(std::chrono::duration<double>(now - start_).count(), 5);
    case 303:
      return "LAST CYCLE, " + hms(lastCycles(now).first, 3);
    case 304:
      return "PREV CYCLE, " + hms(lastCycles(now).second, 3);
    case 402:
    case 403:
      return std::string(query->code == 402 ? "M30 #1, " : "M30 #2, ") + std::to_string(s.parts);
    case 500:
      if (s.status == "BUSY")
        return "STATUS, BUSY";
      return "PROGRAM, " + s.program + ", " + s.status + ", PARTS, " + std::to_string(s.parts);
    case 600:
      return answerMacro(query->argument, s, unknown);
    default:
      return unknown;
  }
}

std::string SimMachine::answerWrite(const std::string& command, Clock::time_point now)
{
  std::istringstream words(command.substr(2));
  std::string var, value;
  if (words >> var >> value)
  {
    try
    {
      const double n = parseNumber(var), v = parseNumber(value);
      // The G54 work offset (#5221-#5223) is the `work` of the script: writing it moves the work
      // zero, as probing software does on a control.
      if (n == std::floor(n) && n >= 5221 && n <= 5223)
      {
        work_[static_cast<int>(n) - 5221] = v;
        return "!";
      }
      // Other system variables (#1000 and up here) are read-only on the control.
      if (n == std::floor(n) && n >= 1 && n < 1000)
      {
        variables_[static_cast<int>(n)] = v;
        written_at_[static_cast<int>(n)] = std::chrono::duration<double>(now - start_).count();
        return "!";
      }
    }
    catch (const ProtocolError&)
    {
    }
  }
  return "?, " + command;
}

std::string SimMachine::answerMacro(const std::optional<double>& argument, const State& s,
                                    const std::string& unknown) const
{
  if (!argument || *argument != std::floor(*argument) || *argument < 0)
    return unknown;
  const int n = static_cast<int>(*argument);
  double value = 0;
  const double work[3] = {s.x - work_[0], s.y - work_[1], s.z - work_[2]};
  if (n >= 5021 && n <= 5023)
    value = n == 5021 ? s.x : n == 5022 ? s.y : s.z;
  else if (n >= 5041 && n <= 5043)
    value = work[n - 5041];
  else if (n >= 5221 && n <= 5223)
    value = work_[n - 5221];
  else if (n == 4006)
    value = inch_ ? 20 : 21;
  else if (n == 3027)
    value = s.spindle;
  else if (n == 3901)
    value = static_cast<double>(s.parts);
  else if (s.variables.count(n) && (!written_at_.count(n) || written_at_.at(n) < s.variables.at(n).second))
    value = s.variables.at(n).first;  // set by the script's phase, after any write
  else if (variables_.count(n))
    value = variables_.at(n);
  if (classic_)
    return "MACRO, " + std::to_string(n) + ", " + number(value, 6);
  return "MACRO, " + number(value, 6);
}
}  // namespace mdc
}  // namespace cnc_bridge
