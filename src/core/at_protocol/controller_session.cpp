// The session with one '@' controller (controller_session.h).
#include "cnc_bridge/at_protocol/controller_session.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <future>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/tcp.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
constexpr int kCommandLink = 0;
constexpr int kReportLink = 1;

LinkState combine(LinkState command, LinkState report)
{
  if (command == LinkState::kUp && report == LinkState::kUp)
  {
    return LinkState::kUp;
  }
  return command == LinkState::kDown || report == LinkState::kDown ? LinkState::kDown : LinkState::kConnecting;
}

/// The command link as the reconnecting link holds it. The sender writes to the link itself;
/// the session waits on the sender, not on a read, so an interrupt (the reconnecting link's stop,
/// or its release of a failed link) must also end that wait.
class CommandLink : public ForwardingTransport
{
 public:
  CommandLink(std::shared_ptr<Transport> link, std::function<void()> on_interrupt)
      : ForwardingTransport(*link), link_(std::move(link)), on_interrupt_(std::move(on_interrupt))
  {
  }
  void interrupt() override
  {
    ForwardingTransport::interrupt();
    on_interrupt_();
  }

 private:
  std::shared_ptr<Transport> link_;
  std::function<void()> on_interrupt_;
};
}  // namespace

LinkSettings TcpLinkSettings::reportLink() const
{
  LinkSettings report = command;
  report.tcp_port = report_port;
  return report;
}

ControllerLinks tcpLinks(const TcpLinkSettings& settings, std::string* listening_on)
{
  ControllerLinks links;
  links.command_name = "at_controller command link " + settings.command.hardwareId();
  links.open_command = linkFactory(settings.command);
  if (!settings.report_server)
  {
    const LinkSettings report = settings.reportLink();
    links.report_name = "at_controller report link " + report.hardwareId();
    links.open_report = linkFactory(report);
    links.stop_opening = [] {};
    return links;
  }
  auto server = std::make_shared<TcpServer>(settings.listen_port);
  auto stopping = std::make_shared<std::atomic<bool>>(false);
  if (listening_on)
  {
    *listening_on = server->describe();
  }
  links.report_name = "at_controller report link " + server->describe();
  links.open_report = [server, stopping]() -> std::unique_ptr<Transport>
  {
    std::unique_ptr<TcpConnection> link;
    // Accepts in short waits so that a stop is seen even if the interrupt came between two.
    while (!link && !*stopping)
    {
      link = server->accept(Milliseconds(500));
    }
    if (!link)
    {
      throw CancelledError("stopping");
    }
    return link;
  };
  links.stop_opening = [server, stopping]
  {
    *stopping = true;
    server->interrupt();
  };
  return links;
}

ControllerSession::ControllerSession(ControllerLinks links, Options options, ControllerListener* listener)
    : options_(std::move(options)),
      listener_(listener),
      links_(std::move(links)),
      jog_deadman_(options_.jog_timeout),
      coolant_(options_.coolant),
      motion_(options_.motion ? options_.motion
                              : std::make_shared<SafetySwitch>(SafetySwitch::Names{}, options_.motion_enabled)),
      command_link_(links_.command_name, [this] { return openCommandLink(); }),
      report_link_(links_.report_name, links_.open_report),
      jog_timer_([this] { return checkJogDeadman(); })
{
  options_.limits.validate();
  if (!options_.disabled_refusal)
  {
    options_.disabled_refusal = [this](const std::string& what) { return motion_->refusal(what); };
  }
  motion_subscription_ =
      motion_->subscribe([this](bool enabled, const std::string& by) { onMotionSwitched(enabled, by); });
  if (!options_.program_dir.empty())
  {
    program_dir_ = std::make_unique<ProgramDirectory>(options_.program_dir);
  }
  SetpointSender::Options sender = options_.sender;
  sender.period = options_.limits.period;
  sender.on_link_error = [this](const std::string& why)
  {
    {
      std::lock_guard<std::mutex> lock(command_mutex_);
      command_failed_ = true;
      command_error_ = why;
    }
    command_cv_.notify_all();
  };
  sender_ = std::make_unique<SetpointSender>(sender);
}

ControllerSession::~ControllerSession()
{
  motion_->unsubscribe(motion_subscription_);  // the switch may outlive the session
  stop();
}

void ControllerSession::start()
{
  command_link_.start([this](Transport&) { commandSession(); },
                      [this](LinkState state, const std::string& why) { linkChanged(kCommandLink, state, why); });
  report_link_.start([this](Transport& link) { reportSession(link); },
                     [this](LinkState state, const std::string& why) { linkChanged(kReportLink, state, why); });
  if (jog_deadman_.enabled())
  {
    jog_timer_.start();
  }
}

void ControllerSession::stop()
{
  jog_timer_.stop();  // before the links: an expiry in progress still sends its F0@
  if (links_.stop_opening)
  {
    links_.stop_opening();
  }
  report_link_.stop();
  command_link_.stop();
  if (sender_)
  {
    sender_->setLink(nullptr);
  }
}

// ---- links ----------------------------------------------------------------------------------------

/// Opens the command link and gives it to the sender before the link is reported up, so that a
/// command sent as soon as the state says UP finds it.
std::unique_ptr<Transport> ControllerSession::openCommandLink()
{
  std::shared_ptr<Transport> link = links_.open_command();
  {
    std::lock_guard<std::mutex> lock(command_mutex_);
    command_failed_ = false;
    command_interrupted_ = false;
  }
  sender_->setLink(link);
  return std::make_unique<CommandLink>(link,
                                       [this]
                                       {
                                         {
                                           std::lock_guard<std::mutex> lock(command_mutex_);
                                           command_interrupted_ = true;
                                         }
                                         command_cv_.notify_all();
                                       });
}

/// The command link's session: the sender writes to it until a write fails (the sender reports
/// it) or the link is interrupted (stop). The protocol has no keep-alive, so a dead socket shows
/// on a write.
void ControllerSession::commandSession()
{
  std::unique_lock<std::mutex> lock(command_mutex_);
  command_cv_.wait(lock, [this] { return command_failed_ || command_interrupted_; });
  const bool failed = command_failed_;
  const std::string why = command_error_;
  lock.unlock();
  sender_->setLink(nullptr);  // the reconnecting link interrupts the link itself after this
  if (failed)
  {
    throw LinkError(why);
  }
}

void ControllerSession::reportSession(Transport& link)
{
  LineReassembler lines;
  uint8_t buffer[4096];
  // Ends when the link fails or is interrupted (stop): the read throws.
  for (;;)
  {
    const size_t n = link.read(buffer, sizeof(buffer), Milliseconds(500));
    if (n == 0)
    {
      continue;
    }
    const auto result = lines.feed(buffer, n);
    for (const auto& error : result.errors)
    {
      ++report_errors_;
      if (listener_)
      {
        listener_->onReportError(error);
      }
    }
    for (const auto& line : result.messages)
    {
      try
      {
        onReport(parseReport(line));
      }
      catch (const ProtocolError& e)
      {
        ++report_errors_;
        if (listener_)
        {
          listener_->onReportError(e.what());
        }
      }
    }
  }
}

void ControllerSession::linkChanged(int which, LinkState state, const std::string& why)
{
  // The two links' threads report at once when both come up; told out of order, a stale
  // CONNECTING could land after UP and stay: one change at a time, in order.
  std::lock_guard<std::mutex> order(link_change_mutex_);
  // Without reports the e-stop is not known any more: motion waits for the next E0.
  const bool reports_lost = which == kReportLink && state != LinkState::kUp;
  LinkState combined = LinkState::kDown;
  {
    std::lock_guard<std::mutex> lock(snapshot_mutex_);
    link_states_[which] = state;
    combined = combine(link_states_[kCommandLink], link_states_[kReportLink]);
    if (reports_lost)
    {
      snapshot_.estop = EStop::kUnknown;
    }
  }
  if (listener_)
  {
    const std::string link = which == kCommandLink ? "command link: " : "report link: ";
    listener_->onLink(combined, why.empty() ? "" : link + why, reports_lost);
  }
}

void ControllerSession::onReport(const Report& report)
{
  std::unique_lock<std::mutex> lock(snapshot_mutex_);
  snapshot_cv_.notify_all();  // waiters see the change once the lock is released
  if (const auto* estop = std::get_if<EStopReport>(&report))
  {
    snapshot_.estop = estop->active ? EStop::kOn : EStop::kOff;
    lock.unlock();
    if (estop->active)
    {
      sender_->abortRunning("emergency stop reported by the controller (E1)");
    }
    notifyReport(ReportEvent::Kind::kEStop, estop->active ? "emergency stop (E1)" : "emergency stop released (E0)");
  }
  else if (std::holds_alternative<AutoModeReport>(report))
  {
    snapshot_.jog_axis = -1;
    lock.unlock();
    jog_deadman_.disarm();  // the controller left jog mode (its mode selector)
    notifyReport(ReportEvent::Kind::kMode, "auto mode");
  }
  else if (const auto* jog = std::get_if<JogModeReport>(&report))
  {
    snapshot_.jog_axis = static_cast<int>(jog->axis);
    lock.unlock();
    notifyReport(ReportEvent::Kind::kMode, std::string("jog mode, axis ") + toChar(jog->axis));
  }
  else if (const auto* position = std::get_if<PositionReport>(&report))
  {
    if (snapshot_.position != position->position)
    {
      snapshot_.at_home = false;
    }
    snapshot_.position = position->position;
    snapshot_.position_valid = true;
    snapshot_.position_at = std::chrono::steady_clock::now();
    lock.unlock();
    notifyReport(ReportEvent::Kind::kPosition, "");
  }
  else if (std::holds_alternative<HomeReport>(report))
  {
    snapshot_.at_home = true;
    lock.unlock();
    notifyReport(ReportEvent::Kind::kHome, "at home");
  }
}

void ControllerSession::notifyReport(ReportEvent::Kind kind, const std::string& message)
{
  if (listener_)
  {
    listener_->onReport(ReportEvent{kind, message}, snapshot());
  }
}

ControllerSnapshot ControllerSession::snapshot() const
{
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  return snapshot_;
}

ControllerSnapshot ControllerSession::waitForReport(const std::function<bool(const ControllerSnapshot&)>& done,
                                                    std::chrono::steady_clock::time_point deadline,
                                                    const std::function<bool()>& cancelled) const
{
  std::unique_lock<std::mutex> lock(snapshot_mutex_);
  while (!done(snapshot_) && std::chrono::steady_clock::now() < deadline)
  {
    lock.unlock();
    if (cancelled && cancelled())
    {
      return snapshot();
    }
    lock.lock();
    // Woken by a report; at the latest after 100 ms to ask cancelled() again.
    const auto poll = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
    snapshot_cv_.wait_until(lock, std::min(poll, deadline), [&] { return done(snapshot_); });
  }
  return snapshot_;
}

// ---- the motion gate ------------------------------------------------------------------------------

void ControllerSession::setMotionEnabled(bool enabled, const std::string& by)
{
  motion_->set(enabled, by);
}

// The switch's listener, under its gate.
void ControllerSession::onMotionSwitched(bool enabled, const std::string& by)
{
  if (enabled)
  {
    return;
  }
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    if (running_job_ && !running_job_->done())
    {
      disabled_by_ = by;
      running_job_->cancel();  // decelerates along the path to a stop
    }
  }
  jog_deadman_.disarm();  // the jog gets feed 0 here
  if (snapshot().jog_axis >= 0)
  {
    try
    {
      sender_->send(JogFeed{0});  // jog feed 0: the axis stops
    }
    catch (const Error& e)
    {
      CNC_LOG_WARN("at_controller: jog stop on disable: " << e.what());
    }
  }
}

std::string ControllerSession::motionDisabledBy() const
{
  return motion_->disabledBy();
}

std::string ControllerSession::motionRefusal(const std::string& what) const
{
  if (!motion_->enabled())
  {
    return options_.disabled_refusal(what);
  }
  const EStop estop = snapshot().estop;
  if (estop == EStop::kOn)
  {
    return what + " refused: the controller reports an emergency stop (E1)";
  }
  if (estop != EStop::kOff)
  {
    // Unknown is not clear: the controller has not said E0 on this report connection.
    return what +
           " refused: the controller's emergency stop state is unknown (no E0/E1 report on the report link "
           "yet); motion starts once it reports E0";
  }
  return "";
}

// ---- commands -------------------------------------------------------------------------------------

Answer ControllerSession::send(const std::vector<Command>& commands)
{
  Answer answer;
  try
  {
    for (const auto& command : commands)
    {
      encode(command);  // a value out of range refuses the whole request before any of it is queued
    }
    std::vector<std::future<void>> written;
    written.reserve(commands.size());
    for (const auto& command : commands)
    {
      written.push_back(sender_->send(command));
    }
    std::string sent;
    for (size_t i = 0; i < written.size(); ++i)
    {
      if (written[i].wait_for(std::chrono::seconds(2)) != std::future_status::ready)
      {
        answer.message = "the command link did not take " + describe(commands[i]) + " within 2 s";
        return answer;
      }
      written[i].get();
      sent += encode(commands[i]);
    }
    answer.success = true;
    answer.message = "sent " + sent;
  }
  catch (const Error& e)
  {
    answer.message = e.what();
  }
  return answer;
}

Answer ControllerSession::setAuto()
{
  Answer answer = send({AutoMode{}});
  if (answer.success)
  {
    jog_deadman_.disarm();  // auto mode ends the jog
  }
  return answer;
}

Answer ControllerSession::jog(const std::string& axis_name, double feed_m_s)
{
  Answer answer{false, motionRefusal("jog")};
  if (!answer.message.empty())
  {
    return answer;
  }
  try
  {
    if (axis_name.size() != 1)
    {
      throw ProtocolError("axis must be x, y or z, not \"" + axis_name + "\"");
    }
    const Axis axis = axisFromChar(axis_name[0]);
    const double max_speed = options_.limits.max_speed[static_cast<int>(axis)];  // mm/s
    // m/s to the F value: a fraction of the axis' top speed, 0..255.
    const int feed = scaledValue(
        feed_m_s * 1000.0, max_speed,
        std::string("jog feed_rate (mm/s, ~max_speed_") + static_cast<char>(std::tolower(toChar(axis))) + ")");
    answer = send({JogMode{axis}, JogFeed{feed}});
    if (answer.success && feed > 0)
    {
      jog_deadman_.renew(Deadman::Clock::now());
      jog_timer_.poke();  // the deadline moved (or was set)
    }
    else if (answer.success)
    {
      jog_deadman_.disarm();
    }
  }
  catch (const Error& e)
  {
    answer.message = e.what();
  }
  return answer;
}

std::optional<JogStop> ControllerSession::expireJog(Deadman::Clock::time_point now, Deadman::Clock::duration* remaining)
{
  if (!jog_deadman_.expire(now, remaining))
  {
    return std::nullopt;
  }
  const Answer sent = send({JogFeed{0}});
  return JogStop{sent.success, "jog stopped: " + jog_deadman_.describe("jog command"),
                 sent.success ? "" : sent.message};
}

/// The deadman thread's check: stops an expired jog, records it and tells the listener.
Deadman::Clock::duration ControllerSession::checkJogDeadman()
{
  Deadman::Clock::duration remaining{};
  const std::optional<JogStop> stop = expireJog(Deadman::Clock::now(), &remaining);
  if (stop)
  {
    {
      std::lock_guard<std::mutex> lock(jog_stop_mutex_);
      last_jog_stop_ = stop->sent ? stop->why : stop->why + ", but feed 0 could not be sent: " + stop->failure;
    }
    if (listener_)
    {
      listener_->onJogStopped(*stop);
    }
  }
  return remaining;
}

std::string ControllerSession::lastJogStop() const
{
  std::lock_guard<std::mutex> lock(jog_stop_mutex_);
  return last_jog_stop_;
}

Answer ControllerSession::spindle(double rpm, double* sent_rpm)
{
  Answer answer;
  // rev/min to the S value 0..255 (clockwise only).
  int value = 0;
  try
  {
    value = scaledValue(rpm, options_.spindle_max_rpm, "spindle speed (rev/min, ~spindle_max_rpm; clockwise only)");
  }
  catch (const ProtocolError& e)
  {
    answer.message = e.what();
    return answer;
  }
  if (value > 0)  // stopping the spindle is always allowed
  {
    answer.message = motionRefusal("spindle start");
    if (!answer.message.empty())
    {
      return answer;
    }
  }
  answer = send({Spindle{value}});
  if (sent_rpm)
  {
    *sent_rpm = static_cast<double>(value) * options_.spindle_max_rpm / kMaxFeed;
  }
  return answer;
}

Answer ControllerSession::toolChange(int32_t tool, double length_m)
{
  Answer answer{false, motionRefusal("tool change")};
  if (!answer.message.empty())
  {
    return answer;
  }
  try
  {
    return send({toolChangeFor(tool, length_m)});  // refuses what the wire cannot carry exactly
  }
  catch (const ProtocolError& e)
  {
    return Answer{false, e.what()};
  }
}

Answer ControllerSession::home()
{
  Answer answer{false, motionRefusal("go home")};
  return answer.message.empty() ? send({Home{}}) : answer;
}

// ---- goals ----------------------------------------------------------------------------------------

std::vector<OperationPlan> ControllerSession::planGoal(const GoalRequest& goal, const std::array<int32_t, 3>& start,
                                                       bool program_commands,
                                                       const std::string& program_commands_setting) const
{
  const Vec3 start_pulses{double(start[0]), double(start[1]), double(start[2])};
  if (!std::isfinite(goal.feed_rate) || goal.feed_rate < 0.0 || !std::isfinite(goal.spindle_speed) ||
      goal.spindle_speed < 0.0)
  {
    throw ConfigError("goal refused before anything was sent: feed_rate (" + std::to_string(goal.feed_rate) +
                      " m/s) and spindle_speed (" + std::to_string(goal.spindle_speed) +
                      " rev/min) must be finite and not negative");
  }
  // Within the machine's limits, or refused naming them: a feed no axis can reach is a mistake in
  // the goal, not a request for the top speed.
  const Vec3& max_speed = options_.limits.max_speed;  // mm/s
  const double top_speed = *std::max_element(max_speed.begin(), max_speed.end());
  if (goal.feed_rate * 1000.0 > top_speed)
  {
    throw ConfigError("goal refused before anything was sent: feed_rate " + std::to_string(goal.feed_rate) +
                      " m/s is above the fastest axis' " + std::to_string(top_speed / 1000.0) +
                      " m/s (~max_speed_x, _y, _z)");
  }
  if (goal.spindle_speed > options_.spindle_max_rpm)
  {
    throw ConfigError("goal refused before anything was sent: spindle_speed " + std::to_string(goal.spindle_speed) +
                      " rev/min is above ~spindle_max_rpm (" + std::to_string(options_.spindle_max_rpm) + ")");
  }
  const bool coolant = goal.coolant == 1 || (goal.coolant == -1 && coolant_);
  const double goal_feed = goal.feed_rate * 1000.0;  // m/s to mm/s
  const double fallback_feed = goal_feed > 0.0 ? goal_feed : options_.default_feed * 1000.0;
  const bool has_file = !goal.gcode_file.empty();
  if (has_file == goal.has_path)
  {
    throw ConfigError("give exactly one of gcode_file and path");
  }
  std::vector<OperationPlan> plans;
  if (has_file)
  {
    if (!program_dir_)
    {
      throw ConfigError("G-code goals need the parameter " + options_.program_dir_setting);
    }
    const std::string file = program_dir_->resolveExisting(goal.gcode_file);
    std::ifstream in(file);
    if (!in)
    {
      throw ConfigError("cannot read " + file);
    }
    ProgramPlanOptions options;
    options.goal_feed = goal_feed;
    options.fallback_feed = fallback_feed;
    options.coolant = coolant;
    options.program_commands = program_commands;
    options.program_commands_setting = program_commands_setting;
    options.spindle_max_rpm = options_.spindle_max_rpm;
    options.soft_limits = options_.soft_limits;
    plans = planProgram(in, options_.gcode, options, start_pulses);
  }
  else
  {
    OperationPlan& plan = plans.emplace_back();
    plan.points.push_back(start_pulses);
    plan.coolant = coolant;
    for (const Vec3& p : goal.path_m)
    {
      // Every point is checked before anything is sent.
      const std::string outside = options_.soft_limits.violation({p[0], p[1], p[2]});
      if (!outside.empty())
      {
        throw ConfigError("goal refused before anything was sent: point " + std::to_string(plan.points.size() - 1) +
                          ": " + outside);
      }
      // Metres to pulses, rounded so that the end point is a whole pulse.
      plan.points.push_back(
          {std::round(p[0] * kPulsesPerMetre), std::round(p[1] * kPulsesPerMetre), std::round(p[2] * kPulsesPerMetre)});
      plan.feeds.push_back(fallback_feed);
    }
  }
  for (OperationPlan& each : plans)
  {
    roundToPulses(each);
    if (goal.spindle_speed > 0.0)
    {
      each.spindle_rpm = goal.spindle_speed;
    }
    if (goal.coolant != -1)
    {
      each.coolant = goal.coolant == 1;
    }
  }
  if (goal.tool >= 0)
  {
    plans.front().tool = goal.tool;
  }
  checkPlans(plans, goal.tool, goal.tool_length);
  return plans;
}

// The whole goal is checked before its first byte goes out: a value of a later operation the wire
// cannot carry would otherwise fail the goal after the earlier operations moved the machine.
void ControllerSession::checkPlans(const std::vector<OperationPlan>& plans, int32_t goal_tool,
                                   double goal_tool_length) const
{
  for (size_t i = 0; i < plans.size(); ++i)
  {
    try
    {
      operationCommands(plans[i], goal_tool, goal_tool_length);
    }
    catch (const ProtocolError& e)
    {
      throw ConfigError("goal refused before anything was sent: operation " + std::to_string(i + 1) + " of " +
                        std::to_string(plans.size()) + ": " + e.what());
    }
  }
}

void ControllerSession::operationCommands(const OperationPlan& plan, int32_t goal_tool, double goal_tool_length,
                                          Operation* operation) const
{
  Operation commands;
  if (plan.tool >= 0)
  {
    // The goal's tool length goes with its own tool; a program's tool change carries none.
    const double length = plan.tool == goal_tool ? goal_tool_length : 0.0;
    commands.tool = toolChangeFor(plan.tool, length);
  }
  if (plan.spindle_rpm > 0.0)
  {
    commands.spindle =
        scaledValue(plan.spindle_rpm, options_.spindle_max_rpm, "spindle speed (rev/min, ~spindle_max_rpm)");
  }
  if (operation)
  {
    operation->tool = commands.tool;
    operation->spindle = commands.spindle;
  }
}

Operation ControllerSession::operationFor(const OperationPlan& plan, int32_t goal_tool, double goal_tool_length) const
{
  Operation operation;
  operation.coolant = plan.coolant;
  operationCommands(plan, goal_tool, goal_tool_length, &operation);
  operation.trajectory = std::make_shared<Trajectory>(plan.points, plan.feeds, options_.limits);
  return operation;
}

OperationResult ControllerSession::runOperation(const OperationPlan& plan, const Operation& operation,
                                                const OperationWatch& watch)
{
  const uint64_t underruns_before = sender_->stats().underruns;
  jog_deadman_.disarm();  // the controller leaves jog mode for machining
  const std::shared_ptr<Job> job = sender_->start(operation);
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    running_job_ = job;
    disabled_by_.clear();
    if (!motion_->enabled())
    {
      // Disabled between the caller's check and the start: stop at once.
      disabled_by_ = motion_->disabledBy();
      job->cancel();
    }
  }
  if (watch.started)
  {
    watch.started(*job);
  }
  OperationResult result;
  while (!job->waitFor(Milliseconds(100)))
  {
    if (!result.cancelled && watch.cancel_requested && watch.cancel_requested())
    {
      job->cancel();
      result.cancelled = true;
    }
    if (watch.progress)
    {
      watch.progress(*job, result.cancelled);
    }
  }
  if (watch.progress)
  {
    watch.progress(*job, result.cancelled);
  }
  std::string disabled_by;
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    running_job_.reset();
    disabled_by.swap(disabled_by_);
  }
  result.job = job;
  result.underruns = sender_->stats().underruns - underruns_before;
  // A cancel of the goal wins over a disable that came at the same time.
  if (!disabled_by.empty() && !result.cancelled && job->state() == Job::State::kCancelled)
  {
    DisabledStop& stop = result.disabled.emplace();
    stop.by = disabled_by;
    const Setpoint last = job->current();
    stop.position = {double(last.position[0]), double(last.position[1]), double(last.position[2])};
    stop.distance = job->distance();
    if (job->sent() == 0)
    {
      stop.position = plan.points.front();  // stopped before its first setpoint: still at the start
      stop.distance = 0.0;
    }
    stop.sent = job->sent();
    stop.planned = operation.trajectory->steps();
  }
  return result;
}
}  // namespace at_protocol
}  // namespace cnc_bridge
