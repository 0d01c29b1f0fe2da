#include "cnc_bridge/cell/cell_rules.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace cnc_bridge
{
namespace cell
{
namespace
{
Verdict no(const std::string& reason)
{
  return Verdict{false, reason};
}

std::string seconds(double value)
{
  std::ostringstream text;
  text.precision(3);
  text << value << " s";
  return text.str();
}

// Each check returns the reason the field is not safe, or empty.
std::string linkProblem(Link link)
{
  switch (link)
  {
    case Link::Up:
      return "";
    case Link::Connecting:
      return "link connecting";
    case Link::Down:
      return "link down";
  }
  return "link unknown";
}

std::string estopProblem(Estop estop)
{
  switch (estop)
  {
    case Estop::Off:
      return "";
    case Estop::On:
      return "emergency stop on";
    case Estop::Unknown:
      return "emergency stop unknown";
  }
  return "emergency stop unknown";
}

std::string executionProblem(Execution execution)
{
  switch (execution)
  {
    case Execution::Ready:
    case Execution::Stopped:
      return "";
    case Execution::Active:
      return "execution ACTIVE";
    case Execution::Paused:
      return "execution PAUSED (in a cycle)";
    case Execution::Alarm:
      return "execution ALARM";
    case Execution::Unknown:
      return "execution unknown";
  }
  return "execution unknown";
}

std::string spindleProblem(double rpm, double stopped_below)
{
  if (std::isnan(rpm))
    return "spindle speed unknown";
  if (!(std::fabs(rpm) < stopped_below))
    return "spindle turning";
  return "";
}

std::string doorProblem(Door door, bool reports_door)
{
  if (!reports_door)
    return "";
  switch (door)
  {
    case Door::Open:
      return "";
    case Door::Closed:
      return "door closed";
    case Door::Unlatched:
      return "door unlatched, not open";
    case Door::Unknown:
      return "door unknown";
  }
  return "door unknown";
}

double staleLimit(const MachineRules& rules)
{
  return rules.state_period_s * rules.stale_factor;
}
}  // namespace

std::string MachineRules::problem() const
{
  if (!(state_period_s > 0.0) || !std::isfinite(state_period_s))
    return "state_period must be a positive number of seconds";
  if (!(stale_factor >= 1.0) || !std::isfinite(stale_factor))
    return "stale_factor must be at least 1";
  if (!(settle_s >= 0.0) || !std::isfinite(settle_s))
    return "settle_time must be zero or more seconds";
  if (!(spindle_stopped_rpm > 0.0) || !std::isfinite(spindle_stopped_rpm))
    return "spindle_stopped_rpm must be a positive speed";
  return "";
}

Verdict judgeReport(const MachineReport& report, double age_s, const MachineRules& rules)
{
  if (std::isnan(age_s) || age_s < 0.0)
    return no("clock jumped backwards since the last state");
  if (age_s > staleLimit(rules))
    return no("state is stale (" + seconds(age_s) + " old, limit " + seconds(staleLimit(rules)) + ")");
  for (const std::string& problem :
       {linkProblem(report.link), estopProblem(report.estop), executionProblem(report.execution),
        spindleProblem(report.spindle_rpm, rules.spindle_stopped_rpm), doorProblem(report.door, rules.reports_door)})
  {
    if (!problem.empty())
      return no(problem);
  }
  return Verdict{true, ""};
}

void CellRules::addMachine(const std::string& name, const MachineRules& rules)
{
  if (name.empty())
    throw std::invalid_argument("a cell machine needs a name");
  if (has(name))
    throw std::invalid_argument("machine '" + name + "' is listed twice");
  const std::string problem = rules.problem();
  if (!problem.empty())
    throw std::invalid_argument("machine '" + name + "': " + problem);
  machines_[name].rules = rules;
}

std::vector<std::string> CellRules::machines() const
{
  std::vector<std::string> names;
  for (const auto& entry : machines_)
    names.push_back(entry.first);
  return names;
}

CellRules::Machine& CellRules::machine(const std::string& name)
{
  auto found = machines_.find(name);
  if (found == machines_.end())
    throw std::invalid_argument("no machine '" + name + "' in the cell");
  return found->second;
}

void CellRules::noteTime(double now)
{
  if (latest_time_ && now < *latest_time_)
  {
    // The clock ran backwards: no age can be trusted, so every machine is unknown until it reports
    // again (and settles anew).
    for (auto& entry : machines_)
    {
      entry.second.last.reset();
      entry.second.safe_since.reset();
    }
  }
  latest_time_ = now;
}

void CellRules::report(const std::string& name, const MachineReport& report, double now)
{
  Machine& target = machine(name);
  noteTime(now);
  // A gap longer than the stale limit is a time the machine was unknown: settling starts again.
  if (target.last && now - target.received_at > staleLimit(target.rules))
    target.safe_since.reset();
  target.last = report;
  target.received_at = now;
  if (!judgeReport(report, 0.0, target.rules).safe)
  {
    target.safe_since.reset();
  }
  else if (!target.safe_since)
  {
    target.safe_since = now;
  }
}

Verdict CellRules::verdict(const std::string& name, double now)
{
  Machine& target = machine(name);
  noteTime(now);
  if (!target.last)
    return no("no state received");
  Verdict judged = judgeReport(*target.last, now - target.received_at, target.rules);
  if (!judged.safe)
  {
    target.safe_since.reset();
    return judged;
  }
  if (!target.safe_since)
    return no("conditions not yet settled");
  const double settled = now - *target.safe_since;
  if (settled < target.rules.settle_s)
    return no("settling (" + seconds(settled) + " of " + seconds(target.rules.settle_s) + ")");
  return judged;
}

Verdict CellRules::requestEntry(const std::string& name, const std::string& robot, double now)
{
  if (robot.empty())
    return no("a robot id is needed");
  Verdict answer = verdict(name, now);
  Machine& target = machine(name);
  if (target.lease && *target.lease != robot)
    return no("entry held by robot '" + *target.lease + "'");
  if (!answer.safe)
    return answer;
  target.lease = robot;
  return answer;
}

bool CellRules::release(const std::string& name, const std::string& robot)
{
  Machine& target = machine(name);
  if (!target.lease || *target.lease != robot)
    return false;
  target.lease.reset();
  return true;
}

std::optional<std::string> CellRules::leaseHolder(const std::string& name) const
{
  auto found = machines_.find(name);
  if (found == machines_.end())
    return std::nullopt;
  return found->second.lease;
}

std::vector<Withdrawal> CellRules::withdrawBroken(double now)
{
  std::vector<Withdrawal> withdrawn;
  noteTime(now);  // a clock jump is seen here too, even with no lease to judge
  for (auto& entry : machines_)
  {
    if (!entry.second.lease)
      continue;
    const Verdict answer = verdict(entry.first, now);
    if (answer.safe)
      continue;
    withdrawn.push_back(Withdrawal{entry.first, *entry.second.lease, answer.reason});
    entry.second.lease.reset();
  }
  return withdrawn;
}

}  // namespace cell
}  // namespace cnc_bridge
