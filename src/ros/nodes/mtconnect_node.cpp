// mtconnect_node: any MTConnect agent's device (a Haas NGC's built-in agent, Mazak, Okuma, ...)
// into the suite's interface (docs/mtconnect_node.md). Parameters -> the core's follower and
// machine model (src/core/mtconnect/) -> state, joint_states, tf, events, conditions, diagnostics.
#include <ros/ros.h>

#include <cmath>
#include <limits>
#include <mutex>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/MachineConditions.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/transport/backoff.h"
#include "mtconnect_node.h"

namespace cnc_bridge
{
namespace
{
double orNaN(const std::optional<double>& v)
{
  return v ? *v : std::numeric_limits<double>::quiet_NaN();
}

uint8_t doorOf(const std::string& door)
{
  if (door == "OPEN")
    return MachineState::DOOR_OPEN;
  if (door == "CLOSED")
    return MachineState::DOOR_CLOSED;
  if (door == "UNLATCHED")
    return MachineState::DOOR_UNLATCHED;
  return MachineState::DOOR_UNKNOWN;
}

MachineCondition toMessage(const mtconnect::Condition& c)
{
  MachineCondition m;
  m.level = static_cast<uint8_t>(c.level);
  m.data_item = c.data_item_id;
  m.condition_type = c.condition_type;
  m.native_code = c.native_code;
  m.native_severity = c.native_severity;
  m.qualifier = c.qualifier;
  m.text = c.text;
  m.timestamp = c.timestamp;
  m.sequence = c.sequence;
  return m;
}

/// The newest active fault (else warning) in plain words, for MachineState.message.
std::string conditionMessage(const std::vector<mtconnect::Condition>& active)
{
  const mtconnect::Condition* worst = nullptr;
  for (const auto& c : active)
  {
    if (!worst || c.level >= worst->level)
      worst = &c;
  }
  if (!worst)
    return "";
  std::string text = worst->level == mtconnect::ConditionLevel::kFault ? "FAULT" : "WARNING";
  if (!worst->native_code.empty())
    text += " " + worst->native_code;
  return text + (worst->text.empty() ? "" : ": " + worst->text);
}
}  // namespace

class MtconnectNode : public mtconnect::FollowerListener
{
 public:
  MtconnectNode(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh)
  {
    link_ = readMtconnectLink(pnh);
    model_ = mtconnect::MachineModel(readMapping(pnh));
    hardware_id_ = "http://" + link_.agent.hardwareId();
    http_ = std::make_unique<mtconnect::HttpClient>(link_.agent.hardwareId(), linkFactory(link_.agent), link_.limits);
    follower_ = std::make_unique<mtconnect::Follower>(readFollowerSettings(pnh), *http_, *this);

    state_ = std::make_unique<MachineStatePublisher>(nh, pnh, hardware_id_);
    state_->diagnostics().add("mtconnect", this, &MtconnectNode::diagnose);
    events_pub_ = nh.advertise<CycleEvent>("events", 20);
    conditions_pub_ = nh.advertise<MachineConditions>("conditions", 10, true);

    Reconnector::Callbacks callbacks;
    callbacks.connect = [this] { follower_->probe(); };
    callbacks.session = [this] { follower_->follow(stop_); };
    callbacks.on_state = [this](LinkState link, const std::string& why) { onLinkState(link, why); };
    // Only a shutdown interrupts the client; after a failure the next request opens a new connection.
    callbacks.disconnect = [this]
    {
      if (stop_.stopped())
        http_->interrupt();
    };
    reconnector_ = std::make_unique<Reconnector>("mtconnect " + hardware_id_, callbacks);
    reconnector_->start();
    ROS_INFO_STREAM("mtconnect_node following " << hardware_id_);
  }

  ~MtconnectNode() override
  {
    stop_.stop();
    reconnector_->stop();
  }

  void onProbe(const mtconnect::Document& probe, const mtconnect::Device& device) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    model_.setDevice(device);
    device_ = device.name + (device.uuid.empty() ? "" : " (" + device.uuid + ")");
    const auto unmatched = model_.unmatched();
    unmatched_.clear();
    for (const auto& f : unmatched)
      unmatched_ += (unmatched_.empty() ? "" : ", ") + f;
    ROS_INFO_STREAM("mtconnect_node: agent " << probe.header.sender << " (MTConnect " << probe.header.version
                                             << ", instance " << probe.header.instance_id << "), device " << device_
                                             << (unmatched_.empty() ? "" : "; not reported: " + unmatched_));
  }

  void onObservations(const std::vector<mtconnect::Observation>& observations, bool snapshot) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto changes = model_.apply(observations, snapshot);
    const ros::Time now = ros::Time::now();
    if (changes.state)
      publishState(now);
    for (const auto& e : changes.events)
      publishEvent(e, now);
    if (snapshot || !changes.conditions.empty())
      publishConditions(changes.conditions, true, now);
  }

  void onDiscontinuity(const std::string& what) override
  {
    ROS_WARN_STREAM("mtconnect_node: " << what << "; reading the whole state again");
  }

 private:
  void onLinkState(LinkState link, const std::string& why)
  {
    if (link != LinkState::kUp)
    {
      std::lock_guard<std::mutex> lock(mutex_);
      // Nothing is known about a machine whose agent we cannot read.
      model_.forget();
      publishState(ros::Time::now());
      if (conditions_known_)
        publishConditions({}, false, ros::Time::now());
    }
    state_->setLink(link, why);
  }

  // Under mutex_.
  void publishState(const ros::Time& now)
  {
    const mtconnect::MachineView& v = model_.view();
    const std::string message = conditionMessage(model_.activeConditions());
    state_->update(
        [&](MachineState& m)
        {
          m.header.stamp = now;
          m.mode = static_cast<uint8_t>(v.mode);
          m.execution = v.estop == mtconnect::Tristate::kOn ? static_cast<uint8_t>(MachineState::EXECUTION_ALARM)
                                                            : static_cast<uint8_t>(v.execution);
          m.estop = static_cast<uint8_t>(v.estop);
          m.program = v.program;
          m.block = v.line;
          m.part_count = v.part_count;
          m.tool = v.tool;
          m.spindle_speed = orNaN(v.spindle_rpm);  // rev/min: the agent's REVOLUTION/MINUTE
          m.feed_rate = orNaN(v.feed_rate);        // m/s, from the probe's units
          m.door = doorOf(v.door);
          m.message = message;
          // Positions in the probe's units (POSITION: MILLIMETER), here in metres.
          m.position_valid = v.positionValid();
          if (m.position_valid)
          {
            m.position.x = *v.position[0];
            m.position.y = *v.position[1];
            m.position.z = *v.position[2];
          }
          m.commanded_valid = v.commandedValid();
          if (m.commanded_valid)
          {
            m.commanded_position.x = *v.commanded[0];
            m.commanded_position.y = *v.commanded[1];
            m.commanded_position.z = *v.commanded[2];
          }
        });
  }

  void publishEvent(const mtconnect::CycleEvent& e, const ros::Time& now)
  {
    events_pub_.publish(state_->cycleEvent(now, e.type, e.program, e.part_count, e.cycle_time, e.text));
    ROS_INFO_STREAM("mtconnect_node: " << e.text << " (program " << e.program << ", parts " << e.part_count << ")");
  }

  void publishConditions(const std::vector<mtconnect::Condition>& changes, bool known, const ros::Time& now)
  {
    MachineConditions msg;
    msg.header.stamp = now;
    msg.header.frame_id = state_->frame("machine");
    msg.machine = state_->machineName();
    msg.known = known;
    if (known)
    {
      for (const auto& c : model_.activeConditions())
        msg.active.push_back(toMessage(c));
    }
    for (const auto& c : changes)
      msg.changes.push_back(toMessage(c));
    conditions_known_ = known;
    conditions_pub_.publish(msg);
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const auto s = follower_->stats();
    const uint64_t new_gaps = s.gaps - reported_gaps_;
    const uint64_t new_restarts = s.restarts - reported_restarts_;
    reported_gaps_ = s.gaps;
    reported_restarts_ = s.restarts;
    if (state_->snapshot().link != MachineState::LINK_UP)
      status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "agent not reachable");
    else if (new_gaps > 0 || new_restarts > 0)
      status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN,
                      "%llu buffer overruns and %llu agent restarts since the last report: state read again",
                      static_cast<unsigned long long>(new_gaps), static_cast<unsigned long long>(new_restarts));
    else
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, s.streaming ? "streaming" : "polling");
    std::lock_guard<std::mutex> lock(mutex_);
    status.add("agent", hardware_id_);
    status.add("device", device_);
    status.add("instanceId", s.instance_id);
    status.add("MTConnect version", s.agent_version);
    status.add("next sequence", s.next_sequence);
    status.add("documents", s.documents);
    status.add("observations", s.observations);
    status.add("sequence gaps", s.gaps);
    status.add("observations lost in gaps", s.lost_observations);
    status.add("agent restarts", s.restarts);
    status.add("state read again", s.resyncs);
    status.add("streams opened", s.streams);
    status.add("polls", s.polls);
    status.add("last gap", s.last_gap);
    status.add("last restart", s.last_restart);
    status.add("fields the device does not report", unmatched_);
    status.add("reconnects", reconnector_ ? reconnector_->reconnects() : 0u);
    status.add("execution", model_.view().execution_text);
    status.add("controller mode", model_.view().mode_text);
    status.add("door", model_.view().door);
    status.add("active conditions", model_.activeConditions().size());
  }

  ros::NodeHandle nh_;
  MtconnectLinkSettings link_;
  std::string hardware_id_;
  std::mutex mutex_;  // guards model_, device_, unmatched_, conditions_known_
  mtconnect::MachineModel model_;
  std::string device_;
  std::string unmatched_;
  bool conditions_known_ = false;
  std::unique_ptr<mtconnect::HttpClient> http_;
  std::unique_ptr<mtconnect::Follower> follower_;
  std::unique_ptr<MachineStatePublisher> state_;
  ros::Publisher events_pub_;
  ros::Publisher conditions_pub_;
  uint64_t reported_gaps_ = 0;
  uint64_t reported_restarts_ = 0;
  StopSignal stop_;
  std::unique_ptr<Reconnector> reconnector_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::MtconnectNode>(argc, argv, "mtconnect_node");
}
