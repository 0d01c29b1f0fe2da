// at_controller_node's parameters (at_controller_node.h; docs/at_controller_node.md, parameters).
#include "at_controller_node.h"

#include <cmath>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace at_controller
{
namespace ap = at_protocol;

namespace
{
/// ~period, ~max_speed_x/y/z (m/s; also the speed a feed value of 255 stands for), ~max_accel_x/y/z
/// (m/s^2), ~corner_share, ~profile (trapezoid, or scurve: jerk-limited by ~max_jerk_x/y/z, m/s^3).
/// The planner works in mm (the machinist's unit): m * 1000.
ap::PlannerLimits plannerLimits(const ros::NodeHandle& pnh)
{
  ap::PlannerLimits limits;
  limits.period = params::positive(pnh, "period", 0.001);  // s, the controller's time loop
  const char* axes[] = {"x", "y", "z"};
  const double speed[] = {0.05, 0.05, 0.025}, accel[] = {0.5, 0.5, 0.25}, jerk[] = {10.0, 10.0, 5.0};
  for (int i = 0; i < 3; ++i)
  {
    limits.max_speed[i] = params::positive(pnh, std::string("max_speed_") + axes[i], speed[i]) * 1000.0;
    limits.max_accel[i] = params::positive(pnh, std::string("max_accel_") + axes[i], accel[i]) * 1000.0;
  }
  pnh.param("corner_share", limits.corner_share, 0.2);
  const std::string profile = pnh.param<std::string>("profile", "trapezoid");
  if (profile != "trapezoid" && profile != "scurve")
  {
    throw ConfigError(pnh.resolveName("profile") + " must be trapezoid or scurve, not '" + profile + "'");
  }
  limits.profile = profile == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
  for (int i = 0; i < 3; ++i)
  {
    limits.max_jerk[i] = params::positive(pnh, std::string("max_jerk_") + axes[i], jerk[i]) * 1000.0;
  }
  // ~path_tolerance (m, default 0.00001): how far the scurve profile may pass from a corner
  // (LinuxCNC's G64 P); a corner it would cut further is taken slower, or stopped on; 0 stops on
  // every corner.
  const double tolerance = pnh.param("path_tolerance", limits.path_tolerance / 1000.0);
  if (!(tolerance >= 0.0) || !std::isfinite(tolerance) || tolerance > 0.01)
  {
    throw ConfigError(pnh.resolveName("path_tolerance") + " must be a distance from 0 to 0.01 m, not " +
                      std::to_string(tolerance));
  }
  limits.path_tolerance = tolerance * 1000.0;
  limits.validate();
  return limits;
}
}  // namespace

ap::TcpLinkSettings linkSettings(const ros::NodeHandle& pnh)
{
  ap::TcpLinkSettings link;
  // ~host (required): address of the controller (both sockets in client mode); ~tcp_port: the
  // controller's command server (the ESPRIT paper's server_recv, docs/protocols/at_protocol.md#source);
  // ~connect_timeout: s allowed for one TCP connect.
  params::TcpLinkDefaults defaults;
  defaults.tcp_port = 5000;
  defaults.connect_timeout = 2.0;
  link.command = params::tcpLink(pnh, defaults);
  // ~report_mode: "client" connects to the controller's report server (the ESPRIT paper's server_send,
  // like the add-in's ReceiveClient); "server" listens on ~listen_port for the controller.
  link.report_server = params::choice(pnh, "report_mode", "client", {"client", "server"}) == "server";
  // ~report_port: the controller's report server (client mode).
  link.report_port = params::tcpPort(pnh, "report_port", 5001);
  // ~listen_port: our report server (server mode); 0 picks a free port (logged).
  link.listen_port = params::tcpPort(pnh, "listen_port", 5001, params::PortZero::kMeansAny);
  return link;
}

ap::ControllerSession::Options sessionOptions(const ros::NodeHandle& pnh)
{
  ap::ControllerSession::Options options;
  // ~program_dir: directory G-code goals are read from; empty refuses G-code goals.
  options.program_dir = pnh.param<std::string>("program_dir", "");
  options.program_dir_setting = pnh.resolveName("program_dir");
  options.limits = plannerLimits(pnh);
  // ~default_feed_rate: m/s along the path when neither the goal nor the program gives one.
  options.default_feed = params::positive(pnh, "default_feed_rate", 0.01);
  // ~gcode_dialect (haas, fanuc or linuxcnc, docs/gcode.md); ~tool_table: diameters for G41/G42.
  params::gcodeOptions(pnh, options.gcode);
  // ~spindle_max_rpm: rev/min that the spindle value 255 stands for.
  options.spindle_max_rpm = params::positive(pnh, "spindle_max_rpm", 24000.0);
  // ~soft_limits ({x: [min, max], ...} m, machine frame): every point of a goal and every move of
  // a program is checked against them before anything is sent; not set: no soft limits.
  options.soft_limits = params::softLimits(pnh);
  // ~coolant: whether operations use coolant (P1@) unless a goal says otherwise; ~coolant service.
  options.coolant = pnh.param("coolant", false);
  // ~realtime_priority: SCHED_FIFO priority of the 1 ms sender thread (with locked memory), 50 by
  // default: the priority of the kernel's threaded interrupt handlers on PREEMPT_RT, so no
  // ordinary thread delays a setpoint while device interrupts still come first. 0 keeps the
  // normal scheduler; where real time is not permitted the sender falls back to it with one
  // warning naming what allows it.
  options.sender.realtime_priority = pnh.param("realtime_priority", 50);
  options.sender.write_timeout = params::seconds(pnh, "write_timeout", 0.2);
  // ~jog_timeout: s a jog moves after its last ~jog call (the deadman, as teleoperation commands
  // have one); a client renews it by calling ~jog again. 0 turns the deadman off.
  options.jog_timeout = pnh.param("jog_timeout", 0.5);
  if (!(options.jog_timeout >= 0.0))
  {
    throw ConfigError(pnh.resolveName("jog_timeout") + " must be 0 (no deadman) or a positive number of seconds");
  }
  return options;
}

ap::EndCheck endCheck(const ros::NodeHandle& pnh)
{
  ap::EndCheck check;
  // ~end_tolerance (m): an operation has ended when the controller reports its end point within
  // this distance; ~end_timeout (s): how long after the last setpoint it has to (the goal fails).
  const double tolerance = pnh.param("end_tolerance", check.tolerance / ap::kPulsesPerMetre);
  if (!(tolerance >= 0.0 && tolerance < 1.0))
  {
    throw ConfigError(pnh.resolveName("end_tolerance") + " must be a distance in metres from 0 (the end point to the " +
                      "pulse) to below 1, not " + std::to_string(tolerance));
  }
  check.tolerance = tolerance * ap::kPulsesPerMetre;
  check.timeout = pnh.param("end_timeout", check.timeout);
  if (!(check.timeout > 0.0 && check.timeout <= 3600.0))
  {
    throw ConfigError(pnh.resolveName("end_timeout") + " must be a positive number of seconds (at most 3600), not " +
                      std::to_string(check.timeout));
  }
  return check;
}
}  // namespace at_controller
}  // namespace cnc_bridge
