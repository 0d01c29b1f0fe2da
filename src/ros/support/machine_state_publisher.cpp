// MachineStatePublisher: the state/joint_states/tf/diagnostics every node shares.
#include "cnc_bridge/ros/machine_state_publisher.h"

#include <geometry_msgs/TransformStamped.h>

#include <cmath>
#include <limits>

#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace
{
// Two states differ for publishing purposes when anything but the stamp differs.
bool sameIgnoringStamp(MachineState a, MachineState b)
{
  a.header.stamp = b.header.stamp;
  a.header.seq = b.header.seq;
  // NaN never equals itself; treat "both unknown" as equal.
  if (std::isnan(a.feed_rate) && std::isnan(b.feed_rate))
    a.feed_rate = b.feed_rate = 0;
  if (std::isnan(a.spindle_speed) && std::isnan(b.spindle_speed))
    a.spindle_speed = b.spindle_speed = 0;
  return a == b;
}

}  // namespace

geometry_msgs::TransformStamped translationTransform(const ros::Time& stamp, const std::string& parent,
                                                     const std::string& child, const geometry_msgs::Point& p)
{
  geometry_msgs::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = parent;
  t.child_frame_id = child;
  t.transform.translation.x = p.x;
  t.transform.translation.y = p.y;
  t.transform.translation.z = p.z;
  t.transform.rotation.w = 1.0;
  return t;
}

MachineStatePublisher::MachineStatePublisher(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& hardware_id)
    : nh_(nh), updater_(nh, pnh)
{
  // ~machine: name of the machine in state messages and diagnostics.
  pnh.param<std::string>("machine", machine_, ros::this_node::getName());
  // ~tf_prefix: prepended to every frame this node publishes ("haas_vf2/" -> haas_vf2/tool).
  pnh.param<std::string>("tf_prefix", tf_prefix_, "");
  // ~state_rate: Hz at which state, joint_states and tf are republished.
  state_rate_ = params::positive(pnh, "state_rate", 10.0);

  state_.machine = machine_;
  state_.header.frame_id = frame("machine");
  state_.link = MachineState::LINK_DOWN;
  state_.feed_rate = std::numeric_limits<double>::quiet_NaN();
  state_.spindle_speed = std::numeric_limits<double>::quiet_NaN();
  state_.tool = -1;
  state_.part_count = -1;

  // Take the lock before anything can fire a callback into this object.
  std::lock_guard<std::mutex> lock(mutex_);
  state_pub_ = nh_.advertise<MachineState>("state", 10, true);
  joint_pub_ = nh_.advertise<sensor_msgs::JointState>("joint_states", 10);
  updater_.setHardwareID(hardware_id);
  updater_.add("link", this, &MachineStatePublisher::linkStatus);
  timer_ = nh_.createTimer(ros::Duration(1.0 / state_rate_), &MachineStatePublisher::onTimer, this);
  // diagnostic_updater publishes at its own ~diagnostic_period; force() keeps silence visible.
  diagnostics_timer_ = nh_.createTimer(ros::Duration(1.0),
                                       [this](const ros::TimerEvent&)
                                       {
                                         std::lock_guard<std::mutex> lock(diagnostics_mutex_);
                                         updater_.update();
                                       });
  state_.header.stamp = ros::Time::now();
  publishLocked(state_.header.stamp);
}

uint8_t MachineStatePublisher::toMessage(LinkState link)
{
  switch (link)
  {
    case LinkState::kDown:
      return MachineState::LINK_DOWN;
    case LinkState::kConnecting:
      return MachineState::LINK_CONNECTING;
    case LinkState::kUp:
      return MachineState::LINK_UP;
  }
  return MachineState::LINK_DOWN;
}

void MachineStatePublisher::update(const std::function<void(MachineState&)>& mutate)
{
  std::lock_guard<std::mutex> lock(mutex_);
  MachineState next = state_;
  next.header.stamp = ros::Time();
  mutate(next);
  const ros::Time now = ros::Time::now();
  if (next.header.stamp.isZero())
  {
    next.header.stamp = now;
  }
  const bool changed = !sameIgnoringStamp(next, state_);
  if (next.link != state_.link)
  {
    ++link_changes_;
  }
  state_ = next;
  if (changed)
  {
    publishLocked(now);
  }
}

void MachineStatePublisher::setLink(LinkState link, const std::string& message)
{
  const bool changed = snapshot().link != toMessage(link);
  update(
      [&](MachineState& s)
      {
        s.link = toMessage(link);
        // A link that comes up ends the error that took it down; otherwise keep the last words.
        if (!message.empty() || link == LinkState::kUp)
        {
          s.message = message;
        }
      });
  if (changed)
  {
    // A link lost or regained is news on /diagnostics at once, not at the next period (a restart
    // that takes a second could fall between two).
    std::lock_guard<std::mutex> lock(diagnostics_mutex_);
    updater_.force_update();
  }
}

void MachineStatePublisher::setPosition(double x, double y, double z)
{
  update(
      [&](MachineState& s)
      {
        s.position_valid = true;
        s.position.x = x;
        s.position.y = y;
        s.position.z = z;
      });
}

void MachineStatePublisher::setCommandedPosition(double x, double y, double z)
{
  update(
      [&](MachineState& s)
      {
        s.commanded_valid = true;
        s.commanded_position.x = x;
        s.commanded_position.y = y;
        s.commanded_position.z = z;
      });
}

CycleEvent MachineStatePublisher::cycleEvent(const ros::Time& stamp, uint8_t event, const std::string& program,
                                             int64_t part_count, double cycle_time, const std::string& text) const
{
  CycleEvent msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frame("machine");
  msg.machine = machine_;
  msg.event = event;
  msg.program = program;
  msg.part_count = part_count;
  msg.cycle_time = cycle_time >= 0 ? cycle_time : std::numeric_limits<double>::quiet_NaN();
  msg.text = text;
  return msg;
}

MachineState MachineStatePublisher::snapshot() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

void MachineStatePublisher::publishLocked(const ros::Time& now)
{
  state_pub_.publish(state_);
  if (!state_.position_valid)
  {
    return;
  }
  // Joints and tf are stamped "now": a machine standing still reports nothing new, yet its frames
  // must stay fresh for tf buffers (robot_state_publisher stamps the links with this stamp).
  sensor_msgs::JointState joints;
  joints.header.stamp = now;
  joints.name = {frame("x_axis"), frame("y_axis"), frame("z_axis")};
  joints.position = {state_.position.x, state_.position.y, state_.position.z};
  joint_pub_.publish(joints);

  tf_broadcaster_.sendTransform(translationTransform(now, frame("machine"), frame("tool"), state_.position));
  if (state_.work_offset_valid)
  {
    tf_broadcaster_.sendTransform(translationTransform(now, frame("machine"), frame("work"), state_.work_offset));
  }
}

void MachineStatePublisher::onTimer(const ros::TimerEvent&)
{
  std::lock_guard<std::mutex> lock(mutex_);
  publishLocked(ros::Time::now());
}

void MachineStatePublisher::linkStatus(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  std::lock_guard<std::mutex> lock(mutex_);
  switch (state_.link)
  {
    case MachineState::LINK_UP:
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, "link up");
      break;
    case MachineState::LINK_CONNECTING:
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "connecting");
      break;
    default:
      status.summary(diagnostic_msgs::DiagnosticStatus::ERROR,
                     state_.message.empty() ? "link down" : "link down: " + state_.message);
  }
  status.add("machine", machine_);
  status.add("link changes", link_changes_);
  status.add("last message", state_.message);
}
}  // namespace cnc_bridge
