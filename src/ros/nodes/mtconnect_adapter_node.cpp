// mtconnect_adapter_node: the cell's machines out to the shop's MTConnect agent. Each machine's
// MachineState (whatever node drives it) is published as one device of an SHDR adapter
// (docs/mtconnect_adapter_node.md); the agent connects to ~port. The core (src/core/mtconnect/)
// does the protocol; this node converts messages and keeps time.
#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <cmath>
#include <mutex>

#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/ros/node_main.h"
#include "mtconnect_adapter_node.h"

namespace cnc_bridge
{
namespace
{
mtconnect::Mode modeOf(uint8_t mode)
{
  switch (mode)
  {
    case MachineState::MODE_AUTO:
    case MachineState::MODE_DNC:  // a program running, fed over the link: automatic to MTConnect
      return mtconnect::Mode::kAuto;
    case MachineState::MODE_MANUAL:
    case MachineState::MODE_HOMING:  // axes moved by the operator's command: manual
      return mtconnect::Mode::kManual;
    case MachineState::MODE_MDI:
      return mtconnect::Mode::kMdi;
    case MachineState::MODE_EDIT:
      return mtconnect::Mode::kEdit;
    default:
      return mtconnect::Mode::kUnknown;
  }
}

std::optional<double> known(double value)
{
  return std::isfinite(value) ? std::optional<double>(value) : std::nullopt;
}

/// The machine as the adapter publishes it.
mtconnect::MachineReport reportOf(const MachineState& m)
{
  mtconnect::MachineReport r;
  r.link_up = m.link == MachineState::LINK_UP;
  mtconnect::MachineView& v = r.view;
  v.estop =
      m.estop <= MachineState::ESTOP_ON ? static_cast<mtconnect::Tristate>(m.estop) : mtconnect::Tristate::kUnknown;
  v.mode = modeOf(m.mode);
  v.execution = m.execution <= MachineState::EXECUTION_ALARM ? static_cast<mtconnect::Execution>(m.execution)
                                                             : mtconnect::Execution::kUnknown;
  v.program = m.program;
  v.line = m.block;
  v.part_count = m.part_count;
  v.tool = m.tool;
  if (m.position_valid)
    v.position = {m.position.x, m.position.y, m.position.z};
  if (m.commanded_valid)
    v.commanded = {m.commanded_position.x, m.commanded_position.y, m.commanded_position.z};
  v.spindle_rpm = known(m.spindle_speed);
  v.feed_rate = known(m.feed_rate);
  v.door = m.door == MachineState::DOOR_OPEN        ? "OPEN"
           : m.door == MachineState::DOOR_CLOSED    ? "CLOSED"
           : m.door == MachineState::DOOR_UNLATCHED ? "UNLATCHED"
                                                    : "";
  r.message = m.message;
  return r;
}

void writeFile(const std::string& path, const std::string& text)
{
  AtomicFileWriter file(path);
  file.write(text);
  file.commit();
}
}  // namespace

class MtconnectAdapterNode
{
 public:
  MtconnectAdapterNode(ros::NodeHandle nh, ros::NodeHandle pnh) : settings_(readMtconnectAdapterSettings(pnh))
  {
    writeAgentFiles();
    std::vector<std::string> names;
    for (const auto& d : settings_.devices)
      names.push_back(d.name);
    adapter_ = std::make_unique<mtconnect::ShdrAdapter>(settings_.adapter, names);
    hardware_id_ = "shdr://" + settings_.adapter.address + ":" + std::to_string(adapter_->port());
    for (const auto& name : names)
    {
      const std::string topic = settings_.state_topics.at(name);
      subscribers_.push_back(
          nh.subscribe<MachineState>(topic, 10, [this, name](const MachineState::ConstPtr& m) { onState(name, *m); }));
      last_seen_[name] = ros::Time();
      ROS_INFO_STREAM("mtconnect_adapter_node: device " << name << " from " << nh.resolveName(topic));
    }
    stale_timer_ = nh.createTimer(ros::Duration(std::min(1.0, settings_.stale_after / 2)),
                                  [this](const ros::TimerEvent&) { checkStale(); });
    diagnostics_.setHardwareID(hardware_id_);
    diagnostics_.add("mtconnect adapter", this, &MtconnectAdapterNode::diagnose);
    diagnostics_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_.update(); });
    ROS_INFO_STREAM("mtconnect_adapter_node: SHDR adapter for " << names.size() << " machines on " << hardware_id_);
  }

 private:
  void writeAgentFiles()
  {
    if (!settings_.devices_file.empty())
    {
      writeFile(settings_.devices_file, mtconnect::devicesXml(settings_.devices));
      ROS_INFO_STREAM("mtconnect_adapter_node: wrote the agent's device file " << settings_.devices_file);
    }
    if (!settings_.agent_config_file.empty())
    {
      const std::string devices = settings_.devices_file.empty() ? "Devices.xml" : settings_.devices_file;
      writeFile(settings_.agent_config_file, mtconnect::agentConfig(settings_.devices, devices, settings_.adapter_host,
                                                                    settings_.adapter.port, settings_.agent_port));
      ROS_INFO_STREAM("mtconnect_adapter_node: wrote the agent's configuration " << settings_.agent_config_file);
    }
  }

  void onState(const std::string& name, const MachineState& m)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_seen_[name] = ros::Time::now();
    stale_.erase(name);
    const ros::Time stamp = m.header.stamp.isZero() ? ros::Time::now() : m.header.stamp;
    adapter_->publish(name, reportOf(m),
                      std::chrono::system_clock::time_point(std::chrono::nanoseconds(stamp.toNSec())));
  }

  /// A machine whose node has fallen silent counts as lost: its data items become UNAVAILABLE.
  void checkStale()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const ros::Time now = ros::Time::now();
    for (const auto& [name, seen] : last_seen_)
    {
      if (stale_.count(name) || (!seen.isZero() && (now - seen).toSec() < settings_.stale_after))
        continue;
      if (seen.isZero() && (now - started_).toSec() < settings_.stale_after)
        continue;  // its node may still be starting
      stale_.insert(name);
      ROS_WARN_STREAM("mtconnect_adapter_node: no state of " << name << " for " << settings_.stale_after
                                                             << " s; the agent is told it is unavailable");
      adapter_->publish(name, mtconnect::MachineReport{}, std::chrono::system_clock::now());
    }
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const auto s = adapter_->stats();
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stale_.empty())
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, std::to_string(stale_.size()) + " machines silent");
    else if (s.agents == 0)
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no agent connected");
    else
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, std::to_string(s.agents) + " agents connected");
    status.add("port", adapter_->port());
    status.add("agents connected now", s.agents);
    status.add("agent connections", s.agents_connected);
    status.add("agents dropped", s.agents_dropped);
    status.add("heartbeats answered", s.pings);
    status.add("lines sent", s.lines);
    std::string silent;
    for (const auto& name : stale_)
      silent += (silent.empty() ? "" : ", ") + name;
    status.add("machines silent", silent);
  }

  MtconnectAdapterSettings settings_;
  std::unique_ptr<mtconnect::ShdrAdapter> adapter_;
  std::string hardware_id_;
  std::vector<ros::Subscriber> subscribers_;
  std::mutex mutex_;  // last_seen_, stale_
  std::map<std::string, ros::Time> last_seen_;
  std::set<std::string> stale_;
  ros::Time started_ = ros::Time::now();
  ros::Timer stale_timer_;
  diagnostic_updater::Updater diagnostics_;
  ros::Timer diagnostics_timer_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::MtconnectAdapterNode>(argc, argv, "mtconnect_adapter_node");
}
