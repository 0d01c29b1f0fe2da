// ethernut_node (src/ros/nodes/ethernut_node.h): the client's events as state, and the
// services (pause, resume, clear, reset, sync_oled, board_command, kill, set_mode, and the motion
// switch's effect on a running job).
#include "ethernut_node.h"

#include <cmath>
#include <limits>

namespace cnc_bridge
{
namespace
{
uint8_t stateMode(ethernut::BoardMode mode)
{
  switch (mode)
  {
    case ethernut::BoardMode::kFile:
      return MachineState::MODE_DNC;  // the program is fed over the link while it runs
    case ethernut::BoardMode::kGuiControl:
      return MachineState::MODE_MANUAL;  // coordinates come from the host's controls
    case ethernut::BoardMode::kStandalone:
      return MachineState::MODE_AUTO;  // the board runs on its own
    default:
      return MachineState::MODE_UNKNOWN;
  }
}

uint8_t stateExecution(ethernut::SessionState st, bool job_active)
{
  switch (st)
  {
    case ethernut::SessionState::kSending:
    case ethernut::SessionState::kWaitingReady:
      return MachineState::EXECUTION_ACTIVE;
    case ethernut::SessionState::kReadyToSend:
      return job_active ? MachineState::EXECUTION_ACTIVE : MachineState::EXECUTION_READY;
    case ethernut::SessionState::kConnected:
      return MachineState::EXECUTION_READY;
    case ethernut::SessionState::kPaused:
      return MachineState::EXECUTION_PAUSED;
    case ethernut::SessionState::kKilled:
      return MachineState::EXECUTION_STOPPED;
    default:
      return MachineState::EXECUTION_UNKNOWN;
  }
}
}  // namespace

// ------------------------------------------------------------------------- listener (run() thread)
void EthernutNode::onState(ethernut::SessionState st, ethernut::SessionState /*previous*/)
{
  const std::shared_ptr<ethernut::Client> client = board_->latest();
  const ethernut::BoardMode mode = client ? client->mode() : ethernut::BoardMode::kUnknown;
  const bool job_active = client && client->jobActive();
  state_->update(
      [&](MachineState& m)
      {
        m.mode = stateMode(mode);
        m.execution = stateExecution(st, job_active);
        if (st == ethernut::SessionState::kKilled)
        {
          m.message = "killed";
        }
        if (st == ethernut::SessionState::kStandalone)
        {
          m.mode = MachineState::MODE_AUTO;
          m.message = "board in standalone mode (call ~set_mode to reconnect)";
        }
      });
}

void EthernutNode::onPosition(float x, float y, float z)
{
  // Status-4 messages are the machine's reported position, mm.
  state_->setPosition(x * kMetresPerMm, y * kMetresPerMm, z * kMetresPerMm);
}

void EthernutNode::onCoordinateDone(uint64_t index, const ethernut::Coordinate& c)
{
  jobs_->onCoordinateDone(index, c);
  // The set the board acknowledged (NEXT) is the commanded position; status-4 reports are where
  // the machine is.
  state_->setCommandedPosition(c.x * kMetresPerMm, c.y * kMetresPerMm, c.z * kMetresPerMm);
}

void EthernutNode::onResend(uint64_t /*index*/, unsigned /*count*/)
{
  jobs_->onResend();
}

void EthernutNode::onJobFinished(ethernut::JobOutcome outcome, const std::string& message)
{
  if (jobs_->onJobFinished(outcome, message))
  {
    return;  // the program goes on after one of its own steps: the job runs on
  }
  // A job cancelled by ~run_job's cancel leaves the board paused (the held move): say so.
  const std::shared_ptr<ethernut::Client> client = board_->latest();
  const bool paused = client && client->state() == ethernut::SessionState::kPaused;
  state_->update(
      [&](MachineState& m)
      {
        m.execution = paused ? MachineState::EXECUTION_PAUSED
                             : (outcome == ethernut::JobOutcome::kCompleted ? MachineState::EXECUTION_READY
                                                                            : MachineState::EXECUTION_STOPPED);
        m.message = message;
      });
}

void EthernutNode::onBoardError(float code)
{
  state_->update([&](MachineState& m) { m.message = "board error code " + std::to_string(static_cast<int>(code)); });
}

// ------------------------------------------------------------------------- services
template <typename Response, typename F>
bool EthernutNode::command(Response& res, const std::string& what, F f)
{
  std::string why;
  auto c = client(why);
  if (!c)
  {
    res.success = false;
    res.message = why;
    return true;
  }
  try
  {
    f(*c);
    res.success = true;
    res.message = what;
  }
  catch (const Error& e)
  {
    res.success = false;
    res.message = e.what();
  }
  return true;
}

template <typename Response>
bool EthernutNode::motionRefused(Response& res, const std::string& service) const
{
  if (motion_->enabled())
    return false;
  res.success = false;
  res.message = motion_->refusal(service);
  return true;
}

bool EthernutNode::onPause(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  return command(res, "paused", [](ethernut::Client& c) { c.pause(); });
}

// ~resume: lets a held move go on (the board paused by ~pause, a cancel or a disable), a job on
// after the program's M00/M01 or after a disable; refused while motion is disabled.
bool EthernutNode::onResume(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  const auto gate = motion_->core().gate();
  if (motionRefused(res, "resume"))
    return true;
  const std::string held = jobs_->releaseHolds();
  std::string why;
  const auto c = client(why);
  if (held.empty() || (c && c->state() == ethernut::SessionState::kPaused))
  {
    command(res, "resumed", [](ethernut::Client& board) { board.resume(); });
    if (!res.success)
    {
      return true;
    }
  }
  if (!held.empty())
  {
    res.success = true;
    res.message = "resumed after " + held;
  }
  return true;
}

// ~set_motion_enabled: disabling pauses a running job (the board holds the move in progress,
// as for a cancel) and holds the goal until motion is enabled again and ~resume is called.
void EthernutNode::onMotionSwitched(bool enabled, const std::string& caller)
{
  // Called under the switch's gate: a segment's start or a gated service comes wholly before or after.
  std::string what = std::string("motion ") + (enabled ? "enabled" : "disabled") + " by " + caller;
  bool running = false;
  if (!enabled)
  {
    running = jobs_->runner().holdOnDisable(what);
  }
  else if (!jobs_->runner().motionHold().empty())
  {
    what += "; the job stays held until " + pnh_.resolveName("resume");  // enabling alone moves nothing
  }
  jobs_->notify();  // the running job shows the hold
  state_->update([&](MachineState& m) { m.message = what; });
  if (enabled || !running)
  {
    return;
  }
  std::string why;
  const auto c = client(why);
  if (!c || !c->jobActive())
  {
    return;  // between two segments of the job, or not connected: nothing streams
  }
  try
  {
    c->pause();
  }
  catch (const Error& e)
  {
    // The board did not confirm the pause: stop streaming at least (the job then ends).
    ROS_ERROR_STREAM("run_job: pause on disable failed (" << e.what() << "): streaming stopped");
    c->cancelJob();
  }
}

// ~reset: the board's reset opcode (99, 0) also drives the axes to 0/0/0, so it is motion.
// ~clear and ~reset send the same opcode (row 8: the job cancelled, memory cleared, the axes to
// 0/0/0); "Reset also terminates all active connections" (qCNC): ~reset then closes the
// connection and the link reconnects. Both move the axes, so both are behind the motion switch.
bool EthernutNode::onClear(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  const auto gate = motion_->core().gate();
  if (motionRefused(res, "clear"))
    return true;
  return command(res, "clear: job cancelled, board cleared to 0/0/0; the connection kept",
                 [](ethernut::Client& c) { c.reset(); });
}

bool EthernutNode::onReset(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  const auto gate = motion_->core().gate();
  if (motionRefused(res, "reset"))
    return true;
  return command(res, "reset: job cancelled, board cleared to 0/0/0; the connection closed, reconnecting",
                 [this](ethernut::Client& c)
                 {
                   c.reset();
                   board_->closeAfterReset(c);  // the session ends and its connection closes
                 });
}

namespace
{
/// The three values of rows 2 and 3 as the board's float32, or a refusal naming the first that
/// does not fit (NaN, infinite, beyond float32): a value is sent exactly or not at all.
std::string floatRefusal(const char* service, const EthernutCoordinates::Request& req)
{
  const std::pair<const char*, double> values[] = {{"x", req.x}, {"y", req.y}, {"z", req.z}};
  for (const auto& [name, value] : values)
  {
    if (!std::isfinite(value) || std::fabs(value) > std::numeric_limits<float>::max())
      return std::string(service) + " refused: " + name + " = " + std::to_string(value) +
             " is not a finite number the board's float32 can carry";
  }
  return "";
}
}  // namespace

// ~sync_oled (row 2): coordinates for the board's display; nothing moves.
bool EthernutNode::onSyncOled(EthernutCoordinates::Request& req, EthernutCoordinates::Response& res)
{
  res.message = floatRefusal("sync_oled", req);
  if (!res.message.empty())
    return true;
  return command(res, "sync_oled: sent and acknowledged",
                 [&](ethernut::Client& c)
                 { c.syncOled(static_cast<float>(req.x), static_cast<float>(req.y), static_cast<float>(req.z)); });
}

// ~board_command (row 3): the board's own command, whose effect this node cannot know: behind the
// motion switch, as anything that may move the machine is.
bool EthernutNode::onBoardCommand(EthernutCoordinates::Request& req, EthernutCoordinates::Response& res)
{
  const auto gate = motion_->core().gate();
  if (motionRefused(res, "board_command"))
    return true;
  res.message = floatRefusal("board_command", req);
  if (!res.message.empty())
    return true;
  return command(res, "board_command: sent and acknowledged",
                 [&](ethernut::Client& c)
                 { c.sendCommand(static_cast<float>(req.x), static_cast<float>(req.y), static_cast<float>(req.z)); });
}

bool EthernutNode::onKill(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  if (!kill_->enabled())
  {
    res.success = false;
    res.message = kill_->refusal("kill") + " (or PROG_CNCkill|1 in ~settings_file)";
    return true;
  }
  return command(res, "killed: the board stopped and dropped the link", [](ethernut::Client& c) { c.kill(); });
}

bool EthernutNode::onSetMode(EthernutSetMode::Request& req, EthernutSetMode::Response& res)
{
  ethernut::BoardMode mode = ethernut::BoardMode::kUnknown;
  if (!ethernut::parseBoardMode(req.mode, mode))
  {
    res.success = false;
    res.message = "unknown mode '" + req.mode + "' (file, gui-control or standalone)";
    return true;
  }
  // A mode change changes what drives the machine (standalone: the board runs on its own), and the
  // mode is also the one selected on every reconnection: gated like motion, nothing changed if refused.
  const auto gate = motion_->core().gate();
  if (motionRefused(res, "set_mode"))
    return true;
  // The mode of every later connection; while the board is in standalone mode, the session
  // reconnects in it, which answers the request.
  if (const std::optional<std::string> answer = board_->selectMode(mode))
  {
    res.success = true;
    res.message = *answer;
    return true;
  }
  return command(res, std::string("mode ") + ethernut::toString(mode),
                 [&](ethernut::Client& c)
                 {
                   c.setMode(mode);
                   state_->update([&](MachineState& m) { m.mode = stateMode(mode); });
                 });
}

}  // namespace cnc_bridge
