// cell_monitor: the cell's own view (docs/cell_monitor.md). Reads the cell's machines from
// ~cell_file (config/cell.yaml), follows each machine's `state` (/<cell>/<machine>/state), judges
// it with the ROS-free rules (cnc_bridge/cell/cell_rules.h) and publishes `cell_state` (latched),
// `entry_events` and, when an entry is withdrawn, an ERROR on /diagnostics. Serves ~request_entry,
// ~release_entry and the ~hold_entry action. Advisory only: not a safety PLC. For each machine with
// a `cycle_time` profile in the cell file, publishes the predicted time to its cycle end on
// `cycle_countdown` (cnc_bridge/cell/cycle_time.h: its program from ~program_dir, planned).
#include <actionlib/server/action_server.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>
#include <yaml-cpp/yaml.h>
#include <cmath>

#include <chrono>
#include <list>
#include <map>

#include "cnc_bridge/CellEntryEvent.h"
#include "cnc_bridge/CellState.h"
#include "cnc_bridge/CycleCountdown.h"
#include "cnc_bridge/HoldEntryAction.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/RequestEntry.h"
#include "cnc_bridge/cell/cell_rules.h"
#include "cnc_bridge/cell/cycle_time.h"
#include "cnc_bridge/ros/node_main.h"

namespace cnc_bridge
{
namespace
{
// The rules run on the steady clock: a wall-clock (or sim-time) jump cannot make an old state fresh.
double steadyNow()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

cell::MachineReport toReport(const MachineState& state)
{
  cell::MachineReport report;
  report.link = static_cast<cell::Link>(std::min<int>(state.link, MachineState::LINK_UP));
  report.execution = state.execution <= MachineState::EXECUTION_ALARM ? static_cast<cell::Execution>(state.execution)
                                                                      : cell::Execution::Unknown;
  report.estop = state.estop <= MachineState::ESTOP_ON ? static_cast<cell::Estop>(state.estop) : cell::Estop::Unknown;
  report.spindle_rpm = state.spindle_speed;
  report.door = state.door <= MachineState::DOOR_UNLATCHED ? static_cast<cell::Door>(state.door) : cell::Door::Unknown;
  return report;
}

// The machines of the cell file, in its order, the namespace of the cell (`cell:`) and the cycle
// profiles of the machines that have one.
struct CellFile
{
  std::string cell;
  std::vector<std::string> machines;
  std::map<std::string, cell::CycleProfile> cycle_profiles;
};

// A machine's `cycle_time:` entry: metres, seconds, as every parameter of the suite.
cell::CycleProfile readCycleProfile(const YAML::Node& node, const std::string& where)
{
  const auto number = [&](const char* key, bool required) -> double
  {
    if (!node[key])
    {
      if (required)
        throw std::runtime_error(where + ": cycle_time needs " + key);
      return 0.0;
    }
    try
    {
      return node[key].as<double>();
    }
    catch (const YAML::Exception&)
    {
      throw std::runtime_error(where + ": cycle_time " + key + " must be a number");
    }
  };
  cell::CycleProfile profile;
  profile.max_feed = number("max_feed", true) * 1000.0;  // m/s to mm/s
  profile.rapid_rate = number("rapid_rate", true) * 1000.0;
  profile.acceleration = number("acceleration", true) * 1000.0;
  profile.tool_change_time = number("tool_change_time", false);
  if (node["dialect"])
    profile.dialect = gcode::parseDialect(node["dialect"].as<std::string>());
  try
  {
    profile.validate();
  }
  catch (const ConfigError& e)
  {
    throw std::runtime_error(where + ": " + e.what());
  }
  return profile;
}

CellFile readCellFile(const std::string& path)
{
  YAML::Node root;
  try
  {
    root = YAML::LoadFile(path);
  }
  catch (const YAML::Exception& e)
  {
    throw std::runtime_error("cannot read ~cell_file " + path + ": " + e.what());
  }
  CellFile file;
  file.cell = root["cell"] ? root["cell"].as<std::string>() : "cell";
  if (!root["machines"] || !root["machines"].IsSequence() || root["machines"].size() == 0)
    throw std::runtime_error("~cell_file " + path + " lists no machines (a `machines:` list with a name each)");
  for (const auto& machine : root["machines"])
  {
    if (!machine["name"])
      throw std::runtime_error("~cell_file " + path + ": a machine has no name");
    file.machines.push_back(machine["name"].as<std::string>());
    if (machine["cycle_time"])
      file.cycle_profiles[file.machines.back()] =
          readCycleProfile(machine["cycle_time"], "~cell_file " + path + ", machine " + file.machines.back());
  }
  return file;
}
}  // namespace

class CellMonitorNode
{
  using Server = actionlib::ActionServer<HoldEntryAction>;

 public:
  CellMonitorNode(ros::NodeHandle nh, ros::NodeHandle pnh) : server_(pnh, "hold_entry", false)
  {
    const CellFile file = readCellFile(params::required<std::string>(pnh, "cell_file"));
    cell::MachineRules rules;
    // ~state_period: s between two states of a machine's node (its ~state_rate is 10 Hz by default).
    rules.state_period_s = params::positive(pnh, "state_period", 0.1);
    // ~stale_factor: a state older than state_period * stale_factor is stale (not safe).
    rules.stale_factor = pnh.param("stale_factor", 10.0);
    // ~settle_time: s every condition must have held before a machine is safe to enter.
    rules.settle_s = pnh.param("settle_time", 1.0);
    // ~door_machines: machines that report a door; theirs must be known and open.
    std::vector<std::string> door_machines;
    pnh.param("door_machines", door_machines, {});
    // ~program_dir: the folder of the programs the machines run (for those with a cycle_time profile).
    const std::string program_dir = pnh.param<std::string>("program_dir", "");
    for (const auto& [name, profile] : file.cycle_profiles)
    {
      if (program_dir.empty())
        throw std::runtime_error("~program_dir is needed: machine " + name + " has a cycle_time profile");
      watches_.emplace(name, cell::CycleWatch(profile, program_dir));
    }
    for (const std::string& name : file.machines)
    {
      cell::MachineRules machine_rules = rules;
      machine_rules.reports_door = std::find(door_machines.begin(), door_machines.end(), name) != door_machines.end();
      rules_.addMachine(name, machine_rules);  // throws on a bad value or a duplicate name
      order_.push_back(name);
      subscribers_.push_back(nh.subscribe<MachineState>("/" + file.cell + "/" + name + "/state", 10,
                                                        [this, name](const MachineState::ConstPtr& state)
                                                        { onState(name, *state); }));
    }
    state_pub_ = nh.advertise<CellState>("cell_state", 1, true);
    event_pub_ = nh.advertise<CellEntryEvent>("entry_events", 20);
    countdown_pub_ = nh.advertise<CycleCountdown>("cycle_countdown", 20);
    diagnostics_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 10);
    request_srv_ = pnh.advertiseService("request_entry", &CellMonitorNode::onRequest, this);
    release_srv_ = pnh.advertiseService("release_entry", &CellMonitorNode::onRelease, this);
    server_.registerGoalCallback([this](const Server::GoalHandle& goal) { onHoldGoal(goal); });
    server_.registerCancelCallback([this](const Server::GoalHandle& goal) { onHoldCancel(goal); });
    server_.start();
    // ~check_rate: Hz at which staleness is judged without a state (leases, held goals, cell_state).
    timer_ = nh.createTimer(ros::Duration(1.0 / params::positive(pnh, "check_rate", 10.0)),
                            [this](const ros::TimerEvent&)
                            {
                              update();
                              publishCountdowns();
                            });
    publishState();
  }

 private:
  struct HeldGoal
  {
    Server::GoalHandle handle;
    double deadline;  // steady seconds; infinity: until cancelled
    std::string last_reason;
  };

  void onState(const std::string& name, const MachineState& state)
  {
    states_[name] = state;
    rules_.report(name, toReport(state), steadyNow());
    const auto watch = watches_.find(name);
    if (watch != watches_.end())
      watch->second.observe(toObservation(state), steadyNow());
    update();
  }

  static cell::CycleObservation toObservation(const MachineState& state)
  {
    const cell::MachineReport report = toReport(state);
    cell::CycleObservation observation;
    observation.link = report.link;
    observation.execution = report.execution;
    observation.program = state.program;
    observation.block = state.block;
    return observation;
  }

  // Every machine with a cycle profile, at ~check_rate: the time to its cycle end or NaN and why.
  void publishCountdowns()
  {
    const double now = steadyNow();
    for (const std::string& name : order_)
    {
      const auto watch = watches_.find(name);
      if (watch == watches_.end())
        continue;
      const cell::CyclePrediction prediction = watch->second.predict(now);
      CycleCountdown countdown;
      countdown.header.stamp = ros::Time::now();
      countdown.machine = name;
      countdown.program = prediction.program;
      countdown.planned_cycle_time = prediction.planned;
      countdown.time_to_cycle_end = prediction.remaining;
      countdown.block = prediction.block;
      countdown.reason = states_.count(name) ? prediction.reason : "no state received";
      countdown_pub_.publish(countdown);
    }
  }

  // Withdraws broken leases, serves held goals, publishes the view when it changed.
  void update()
  {
    const double now = steadyNow();
    for (const cell::Withdrawal& withdrawal : rules_.withdrawBroken(now))
      withdraw(withdrawal);
    serveHeldGoals(now);
    publishState();
  }

  void withdraw(const cell::Withdrawal& withdrawal)
  {
    ROS_ERROR("cell_monitor: entry of robot '%s' into %s withdrawn: %s", withdrawal.robot.c_str(),
              withdrawal.machine.c_str(), withdrawal.reason.c_str());
    publishEvent(withdrawal.machine, withdrawal.robot, CellEntryEvent::WITHDRAWN, withdrawal.reason);
    diagnostic_msgs::DiagnosticArray array;
    array.header.stamp = ros::Time::now();
    diagnostic_msgs::DiagnosticStatus status;
    status.level = diagnostic_msgs::DiagnosticStatus::ERROR;
    status.name = "cell_monitor: " + withdrawal.machine + " entry";
    status.hardware_id = withdrawal.machine;
    status.message = "entry of robot '" + withdrawal.robot + "' withdrawn: " + withdrawal.reason;
    array.status.push_back(status);
    diagnostics_pub_.publish(array);
  }

  void publishEvent(const std::string& machine, const std::string& robot, uint8_t kind, const std::string& reason)
  {
    CellEntryEvent event;
    event.header.stamp = ros::Time::now();
    event.machine = machine;
    event.robot = robot;
    event.event = kind;
    event.reason = reason;
    event_pub_.publish(event);
  }

  cell::Verdict request(const std::string& machine, const std::string& robot)
  {
    if (!rules_.has(machine))
      return cell::Verdict{false, "no machine '" + machine + "' in the cell"};
    const bool held = rules_.leaseHolder(machine).value_or("") == robot;
    cell::Verdict answer = rules_.requestEntry(machine, robot, steadyNow());
    if (answer.safe && !held)
      publishEvent(machine, robot, CellEntryEvent::GRANTED, "");
    return answer;
  }

  bool onRequest(RequestEntry::Request& req, RequestEntry::Response& res)
  {
    const cell::Verdict answer = request(req.machine, req.robot);
    res.granted = answer.safe;
    res.reason = answer.reason;
    publishState();
    return true;
  }

  bool onRelease(RequestEntry::Request& req, RequestEntry::Response& res)
  {
    res.granted = rules_.has(req.machine) && rules_.release(req.machine, req.robot);
    if (res.granted)
      publishEvent(req.machine, req.robot, CellEntryEvent::RELEASED, "");
    else
      res.reason = "robot '" + req.robot + "' holds no entry into '" + req.machine + "'";
    publishState();
    return true;
  }

  void onHoldGoal(Server::GoalHandle goal)
  {
    const auto& wanted = *goal.getGoal();
    if (!rules_.has(wanted.machine) || wanted.robot.empty() || std::isnan(wanted.timeout))
    {
      HoldEntryResult result;
      result.reason = wanted.robot.empty() ? "a robot id is needed"
                      : std::isnan(wanted.timeout)
                          ? "the timeout is not a number: give seconds, or 0 to wait until cancelled"
                          : "no machine '" + wanted.machine + "' in the cell";
      goal.setRejected(result, result.reason);
      return;
    }
    goal.setAccepted();
    const double deadline =
        wanted.timeout > 0.0 ? steadyNow() + wanted.timeout : std::numeric_limits<double>::infinity();
    held_.push_back(HeldGoal{goal, deadline, ""});
    serveHeldGoals(steadyNow());
  }

  void onHoldCancel(Server::GoalHandle goal)
  {
    for (auto it = held_.begin(); it != held_.end(); ++it)
    {
      if (it->handle == goal)
      {
        HoldEntryResult result;
        result.reason = "cancelled";
        goal.setCanceled(result);
        held_.erase(it);
        return;
      }
    }
  }

  void serveHeldGoals(double now)
  {
    for (auto it = held_.begin(); it != held_.end();)
    {
      const auto& wanted = *it->handle.getGoal();
      const cell::Verdict answer = request(wanted.machine, wanted.robot);
      HoldEntryResult result;
      result.granted = answer.safe;
      result.reason = answer.safe ? "" : answer.reason;
      if (answer.safe)
      {
        it->handle.setSucceeded(result);
      }
      else if (now >= it->deadline)
      {
        result.reason = "timed out: " + answer.reason;
        it->handle.setAborted(result, result.reason);
      }
      else
      {
        if (answer.reason != it->last_reason)
        {
          it->last_reason = answer.reason;
          HoldEntryFeedback feedback;
          feedback.reason = answer.reason;
          it->handle.publishFeedback(feedback);
        }
        ++it;
        continue;
      }
      it = held_.erase(it);
    }
  }

  void publishState()
  {
    CellState view;
    const double now = steadyNow();
    for (const std::string& name : order_)
    {
      CellMachine machine;
      machine.machine = name;
      const auto state = states_.find(name);
      machine.state_known = state != states_.end();
      if (machine.state_known)
        machine.state = state->second;
      const cell::Verdict verdict = rules_.verdict(name, now);
      machine.safe_to_enter = verdict.safe;
      machine.reason = verdict.reason;
      machine.lease_holder = rules_.leaseHolder(name).value_or("");
      view.machines.push_back(machine);
    }
    // Latched and published on change only: the verdicts, reasons and leases, not every state.
    if (published_ && sameVerdicts(view, last_view_))
      return;
    view.header.stamp = ros::Time::now();
    state_pub_.publish(view);
    last_view_ = view;
    published_ = true;
  }

  // A reason without its numbers ("state is stale (1.2 s old, ...)"): a changing age is no change.
  static std::string reasonKind(const std::string& reason) { return reason.substr(0, reason.find('(')); }

  static bool sameVerdicts(const CellState& a, const CellState& b)
  {
    if (a.machines.size() != b.machines.size())
      return false;
    for (size_t i = 0; i < a.machines.size(); ++i)
    {
      const auto& x = a.machines[i];
      const auto& y = b.machines[i];
      if (x.state_known != y.state_known || x.safe_to_enter != y.safe_to_enter ||
          reasonKind(x.reason) != reasonKind(y.reason) || x.lease_holder != y.lease_holder ||
          x.state.execution != y.state.execution || x.state.link != y.state.link)
        return false;
    }
    return true;
  }

  cell::CellRules rules_;  // every callback and the timer run on the one spinner thread
  std::vector<std::string> order_;
  std::map<std::string, MachineState> states_;
  std::vector<ros::Subscriber> subscribers_;
  ros::Publisher state_pub_, event_pub_, diagnostics_pub_, countdown_pub_;
  std::map<std::string, cell::CycleWatch> watches_;  // machines with a cycle profile
  ros::ServiceServer request_srv_, release_srv_;
  Server server_;
  std::list<HeldGoal> held_;
  ros::Timer timer_;
  CellState last_view_;
  bool published_ = false;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::CellMonitorNode>(argc, argv, "cell_monitor");
}
