// haas_mdc_node: live status of a Haas machine from Machine Data Collection (?Q queries over TCP to
// an NGC control, or over the RS-232 port of a Classic control) for robot cells: is the machine
// idle, running, in alarm; which program; how many parts; where the axes are. Publishes `state`,
// `joint_states`, tf and diagnostics through MachineStatePublisher, cycle events on `events`, and
// offers ~read_variable, ~write_variable (allow-list) and ~query (read-only raw queries).
#include <ros/ros.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <sstream>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/DprntLine.h"
#include "cnc_bridge/MacroVariables.h"
#include "cnc_bridge/MdcQuery.h"
#include "cnc_bridge/MdcReadVariable.h"
#include "cnc_bridge/MdcWriteVariable.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_monitor.h"
#include "cnc_bridge/mdc/mdc_readings.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "haas_mdc_node.h"

namespace cnc_bridge
{
namespace
{
uint8_t estopState(mdc::Estop estop)
{
  switch (estop)
  {
    case mdc::Estop::kOn:
      return MachineState::ESTOP_ON;
    case mdc::Estop::kOff:
      return MachineState::ESTOP_OFF;
    default:
      return MachineState::ESTOP_UNKNOWN;
  }
}
}  // namespace

class HaasMdcNode
{
 public:
  HaasMdcNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : nh_(nh), pnh_(pnh), settings_(haasMdcSettings(pnh)), session_(settings_), poller_(&session_.poller())
  {
    vars_ = settings_.vars;
    reply_timeout_ = settings_.reply_timeout;
    watch_ = std::make_unique<mdc::VariableWatch>(vars_.watched);
    policy_ = std::make_unique<mdc::WritePolicy>(settings_.writable_variables, pnh.resolveName("writable_variables"));
    advertise(nh, pnh);
    session_.start([this](LinkState link, const std::string& why) { onLinkState(link, why); });
    ROS_INFO_STREAM("haas_mdc_node polling " << session_.hardwareId() << " (Q500 every "
                                             << settings_.plan.status_period.count() << " ms; writes "
                                             << (policy_->allowed().empty() ? "disabled" : "allow-listed") << ")");
  }

  ~HaasMdcNode() { session_.stop(); }

 private:
  // Publishers, services and the poller's listeners: all there before the session starts.
  void advertise(ros::NodeHandle& nh, ros::NodeHandle& pnh)
  {
    state_ = std::make_unique<MachineStatePublisher>(nh, pnh, session_.hardwareId());
    state_->diagnostics().add("mdc", this, &HaasMdcNode::diagnose);
    events_pub_ = nh.advertise<CycleEvent>("events", 20);
    if (!watch_->numbers().empty())
    {
      variables_pub_ = nh.advertise<MacroVariables>("variables", 1, true);
    }
    poller_->setListener([this](const mdc::MachineStatus& s, const std::vector<mdc::CycleEventData>& events)
                         { onStatus(s, events); });
    if (settings_.forward_dprnt)
    {
      dprnt_pub_ = nh.advertise<DprntLine>("dprnt/port_lines", 1000);
      poller_->setTextListener([this](const std::string& line) { forwardLine(line); });
    }
    // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): a macro variable write
    // changes what the machine does (offsets, the program's flow), so it is gated like motion on the
    // other nodes, on top of the ~writable_variables allow-list.
    motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled");
    read_srv_ = advertiseGuardedService(pnh, "read_variable", &HaasMdcNode::readVariable, this);
    write_srv_ = advertiseGuardedService(pnh, "write_variable", &HaasMdcNode::writeVariable, this);
    query_srv_ = advertiseGuardedService(pnh, "query", &HaasMdcNode::query, this);
  }

  void onLinkState(LinkState link, const std::string& why)
  {
    if (link != LinkState::kUp)
    {
      std::lock_guard<std::mutex> lock(watch_mutex_);
      publishVariables(watch_->linkLost(), ros::Time::now());
      state_->update(
          [](MachineState& m)
          {
            // Nothing is known about a machine we cannot reach (MTConnect: UNAVAILABLE).
            m.mode = MachineState::MODE_UNKNOWN;
            m.execution = MachineState::EXECUTION_UNKNOWN;
            m.position_valid = false;
            m.estop = MachineState::ESTOP_UNKNOWN;
          });
    }
    state_->setLink(link, why);
  }

  // Called by the poller after each reply, under its lock.
  void onStatus(const mdc::MachineStatus& s, const std::vector<mdc::CycleEventData>& events)
  {
    const ros::Time now = ros::Time::now();
    const mdc::Readings readings = mdc::readingsFrom(s, vars_);
    if (s.units != mdc::Units::kUnknown)
      units_ = s.units;
    state_->update(
        [&](MachineState& m)
        {
          m.header.stamp = now;
          m.link = MachineState::LINK_UP;
          m.mode = static_cast<uint8_t>(s.mode);
          m.execution = static_cast<uint8_t>(s.execution);
          m.program = s.program;
          m.part_count = s.parts.value_or(-1);
          m.tool = s.tool ? static_cast<int32_t>(*s.tool) : -1;
          m.message = s.execution == mdc::Execution::kAlarm ? "Haas status " + s.status_text : "";
          m.estop = estopState(mdc::estopFrom(s));
          if (readings.spindle_rpm)
            m.spindle_speed = *readings.spindle_rpm;  // rev/min, the unit of MachineState.spindle_speed
          // Positions arrive in the control's unit (inch under G20, mm under G21), here in metres.
          m.position_valid = readings.position_valid;
          if (readings.position_valid)
          {
            m.position.x = readings.position[0];
            m.position.y = readings.position[1];
            m.position.z = readings.position[2];
          }
          if (readings.work_offset_valid)
          {
            m.work_offset_valid = true;
            m.work_offset.x = readings.work_offset[0];
            m.work_offset.y = readings.work_offset[1];
            m.work_offset.z = readings.work_offset[2];
          }
        });
    {
      std::lock_guard<std::mutex> lock(watch_mutex_);
      publishVariables(watch_->update(s), now);
    }
    if (const std::string errors = watch_->errors(s); !errors.empty())
    {
      ROS_WARN_STREAM_THROTTLE(10.0, "haas_mdc_node: watched variables without a value: " << errors);
    }
    for (const auto& e : events)
    {
      events_pub_.publish(state_->cycleEvent(now, e.type, e.program, e.part_count, e.cycle_time, e.text));
      ROS_INFO_STREAM("haas_mdc_node: " << e.text << " (program " << e.program << ", parts " << e.part_count << ")");
    }
  }

  // Called by the poller for each line of the port that is no MDC reply, in the order read.
  void forwardLine(const std::string& text)
  {
    DprntLine line;
    line.header.stamp = ros::Time::now();
    line.machine = state_->machineName();
    line.line_number = ++forwarded_lines_;
    line.text = text;
    dprnt_pub_.publish(line);
  }

  // Publishes the watched variables' values, if VariableWatch says they are due.
  void publishVariables(const std::optional<std::vector<double>>& values, const ros::Time& stamp)
  {
    if (!values)
      return;
    MacroVariables msg;
    msg.header.stamp = stamp;
    msg.machine = state_->machineName();
    msg.numbers.assign(watch_->numbers().begin(), watch_->numbers().end());
    msg.values = *values;
    variables_pub_.publish(msg);
  }

  bool readVariable(MdcReadVariable::Request& req, MdcReadVariable::Response& res)
  {
    try
    {
      if (req.variable < 0)
        throw ConfigError("variable numbers are not negative");
      poller_->withClient([&](mdc::MdcClient& c) { res.value = c.readVariable(req.variable, reply_timeout_); });
      res.success = true;
      std::ostringstream answer;
      answer << "#" << req.variable << " = " << res.value << ", " << mdc::unitNote(vars_.units, units_.load());
      res.message = answer.str();
    }
    catch (const Error& e)
    {
      res.success = false;
      res.message = e.what();
    }
    return true;
  }

  bool writeVariable(MdcWriteVariable::Request& req, MdcWriteVariable::Response& res)
  {
    try
    {
      policy_->check(req.variable);
      if (!motion_->enabled())
        throw ConfigError(motion_->refusal("write_variable"));
      mdc::writeQuery(req.variable, req.value);  // refuses a value the wire cannot carry exactly
      poller_->withClient([&](mdc::MdcClient& c) { c.writeVariable(req.variable, req.value, reply_timeout_); });
      res.success = true;
      res.message = "#" + std::to_string(req.variable) + " set";
      ROS_INFO_STREAM("haas_mdc_node: wrote #" << req.variable << " = " << req.value);
    }
    catch (const Error& e)
    {
      res.success = false;
      res.message = e.what();
      ROS_WARN_STREAM("haas_mdc_node: write of #" << req.variable << " refused: " << e.what());
    }
    return true;
  }

  bool query(MdcQuery::Request& req, MdcQuery::Response& res)
  {
    const auto parsed = mdc::parseReadOnlyQuery(req.query);
    if (!parsed)
    {
      res.success = false;
      res.message = "only read-only queries (?Qnnn, optionally one number) are sent; use " +
                    pnh_.resolveName("write_variable") + " to write";
      return true;
    }
    try
    {
      poller_->withClient([&](mdc::MdcClient& c) { res.reply = c.request(*parsed, reply_timeout_).line; });
      res.success = true;
    }
    catch (const Error& e)
    {
      res.success = false;
      res.message = e.what();
    }
    return true;
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const auto stats = poller_->stats();
    const auto s = poller_->status();
    const uint64_t new_unanswered = stats.unanswered - last_unanswered_;
    last_unanswered_ = stats.unanswered;
    if (state_->snapshot().link != MachineState::LINK_UP)
      status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "not connected");
    else if (new_unanswered > 0)
      status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%llu queries unanswered since the last report",
                      static_cast<unsigned long long>(new_unanswered));
    else
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, "polling");
    status.add("serial number", s.serial_number);
    status.add("model", s.model);
    status.add("software version", s.software_version);
    status.add("mode", s.mode_text);
    status.add("status", s.status_text);
    status.add("queries sent", stats.sent);
    status.add("answered", stats.answered);
    status.add("unanswered", stats.unanswered);
    status.add("rejected by the control", stats.rejected);
    status.add("other clients' replies", stats.foreign);
    status.add("oversize lines dropped", stats.dropped_lines);
    status.add("latency last (ms)", stats.last_latency_ms);
    status.add("latency mean (ms)", stats.answered ? stats.total_latency_ms / stats.answered : 0.0);
    status.add("latency max (ms)", stats.max_latency_ms);
    status.add("polls skipped for a DNC transfer", poller_->skippedForPortLock());
    status.add("port regained after a DNC transfer", poller_->portRegained());
    status.add("reconnects", session_.reconnects());
    motion_->addTo(status);
    if (settings_.forward_dprnt)
    {
      status.add("DPRNT lines forwarded", stats.text_lines);
      status.add("DPRNT readers", dprnt_pub_.getNumSubscribers());
      if (dprnt_pub_.getNumSubscribers() == 0)
        status.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN,
                            "nobody reads dprnt/port_lines: DPRNT lines of this port are lost (start dprnt_node "
                            "with input:=topic)");
    }
    if (s.last_cycle_s)
      status.add("last cycle (s)", *s.last_cycle_s);
    if (s.m30_counter1)
      status.add("M30 counter #1", *s.m30_counter1);
    for (const auto& [variable, value] : s.variables)
      status.add("#" + std::to_string(variable), value);
    for (const auto& [variable, why] : s.variable_errors)
      status.add("#" + std::to_string(variable) + " error", why);
    if (const std::string errors = watch_->errors(s); !errors.empty())
      status.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "watched variables without a value: " + errors);
  }

  ros::NodeHandle nh_, pnh_;
  mdc::MdcSettings settings_;
  mdc::MdcSession session_;
  mdc::MdcPoller* poller_;  // session_'s
  Milliseconds reply_timeout_{1000};
  mdc::PollVariables vars_;
  std::atomic<mdc::Units> units_{mdc::Units::kUnknown};  ///< the control's G20/G21 as last polled (#4006)
  std::unique_ptr<mdc::WritePolicy> policy_;
  std::unique_ptr<RuntimeSwitch> motion_;      // gates ~write_variable
  std::unique_ptr<mdc::VariableWatch> watch_;  // update() and linkLost() under watch_mutex_
  std::mutex watch_mutex_;
  std::unique_ptr<MachineStatePublisher> state_;
  ros::Publisher events_pub_;
  ros::Publisher variables_pub_;
  ros::Publisher dprnt_pub_;      // dprnt/port_lines, with ~forward_dprnt
  uint64_t forwarded_lines_ = 0;  // poller thread only
  ros::ServiceServer read_srv_, write_srv_, query_srv_;
  uint64_t last_unanswered_ = 0;
};
}  // namespace cnc_bridge

// Two threads: a service call waiting for its reply must not hold up the state timer.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::HaasMdcNode>(argc, argv, "haas_mdc_node", {2});
}
