// SimController (sim_controller.h): the simulated '@' controller's sockets, console and time loop.
#include "sim/at_protocol/sim_controller.h"

#include <time.h>

#include <cmath>
#include <iostream>
#include <sstream>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "sim/sim_support.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
std::vector<SimFault> readFaultScript(const std::string& path)
{
  std::vector<SimFault> faults;
  if (path.empty())
  {
    return faults;
  }
  std::ifstream in(path);
  if (!in)
  {
    throw ConfigError("sim_at_controller: cannot read the fault script " + path);
  }
  std::string line;
  while (std::getline(in, line))
  {
    std::istringstream words(line);
    std::string trigger, action;
    SimFault fault;
    if (!(words >> trigger) || trigger[0] == '#')
    {
      continue;
    }
    // Format: "setpoint <n> estop-on|estop-off|drop-command-link"
    if (trigger != "setpoint" || !(words >> fault.after_setpoints >> action) ||
        (action != "estop-on" && action != "estop-off" && action != "drop-command-link"))
    {
      throw ConfigError("sim_at_controller: fault script line \"" + line +
                        "\" is not \"setpoint <n> estop-on|estop-off|drop-command-link\"");
    }
    fault.action = action == "estop-on"    ? SimFault::Action::kEStopOn
                   : action == "estop-off" ? SimFault::Action::kEStopOff
                                           : SimFault::Action::kDropCommandLink;
    faults.push_back(fault);
  }
  return faults;
}

int64_t monotonicNs()
{
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<int64_t>(now.tv_sec) * 1000000000LL + now.tv_nsec;
}
}  // namespace

SimController::SimController(SimControllerOptions options, StopSignal& stop) : options_(std::move(options)), stop_(stop)
{
  faults_ = readFaultScript(options_.fault_script);
  if (!options_.command_log.empty())
  {
    command_log_.open(options_.command_log, std::ios::app);
    if (!command_log_)
    {
      throw ConfigError("sim_at_controller: cannot open --command-log " + options_.command_log);
    }
  }
}

void SimController::run()
{
  TcpServer command_server(options_.command_port, options_.host);
  sim::onStop([&] { command_server.interrupt(); });
  sim::announce("sim_at_controller", "tcp " + options_.host + ":" + std::to_string(command_server.port()));
  std::unique_ptr<TcpServer> report_server;
  if (options_.report_mode == "server")
  {
    report_server = std::make_unique<TcpServer>(options_.report_port, options_.host);
    sim::onStop([&] { report_server->interrupt(); });
    std::cout << "report tcp " << options_.host << ":" << report_server->port() << std::endl;
  }
  else if (options_.report_mode != "client")
  {
    throw ConfigError("sim_at_controller: --report-mode must be server or client");
  }
  if (!options_.pid_file.empty())
  {
    sim::writePidFile(options_.pid_file);
  }
  std::thread commands([&] { commandLoop(command_server); });
  std::thread reports([&] { report_server ? reportServerLoop(*report_server) : reportClientLoop(); });
  std::thread console([&] { consoleLoop(); });
  console.detach();  // blocked in a read of stdin; ends with the process
  controlLoop();
  commands.join();
  reports.join();
  std::cerr << "sim_at_controller: " << setpoints_received_ << " setpoints received, " << ignored_
            << " messages ignored, arrival interval p50 " << arrivals_.percentile(0.5) * 1e3 << " ms p99 "
            << arrivals_.percentile(0.99) * 1e3 << " ms max " << arrivals_.max() * 1e3 << " ms" << std::endl;
}

void SimController::console(const std::string& line)
{
  std::lock_guard<std::mutex> lock(mutex_);
  console_.push_back(line);
}

void SimController::commandLoop(TcpServer& server)
{
  while (!stop_.stopped())
  {
    std::unique_ptr<TcpConnection> peer;
    try
    {
      peer = server.accept(Milliseconds(200));
    }
    catch (const Error&)
    {
      return;  // interrupted: stopping
    }
    if (!peer)
    {
      continue;
    }
    // Reads time out every 200 ms, so a stop request ends this loop without an interrupt.
    std::cerr << "sim_at_controller: command link from " << peer->describe() << std::endl;
    {
      // A new host connection starts a fresh sequence (M1@ ... M0@) in the control loop.
      std::lock_guard<std::mutex> lock(mutex_);
      queue_.clear();
      new_command_link_ = true;
    }
    drop_command_link_ = false;
    CommandReassembler reassembler;
    uint8_t buffer[4096];
    try
    {
      while (!stop_.stopped())
      {
        if (drop_command_link_.exchange(false))
        {
          std::cerr << "sim_at_controller: command link dropped (fault script)" << std::endl;
          break;  // the connection closes with peer
        }
        const size_t n = peer->read(buffer, sizeof(buffer), Milliseconds(200));
        if (n == 0)
        {
          continue;
        }
        const int64_t now = monotonicNs();
        auto result = reassembler.feed(buffer, n);
        for (const auto& error : result.errors)
        {
          std::cerr << "sim_at_controller: " << error << std::endl;
        }
        std::lock_guard<std::mutex> lock(mutex_);
        for (const auto& message : result.messages)
        {
          logCommand(message);
          try
          {
            Command command = decodeCommand(message);
            if (std::holds_alternative<Setpoint>(command))
            {
              if (last_arrival_ns_ != 0)
              {
                arrivals_.record(now - last_arrival_ns_);
              }
              last_arrival_ns_ = now;
            }
            queue_.push_back(std::move(command));
          }
          catch (const ProtocolError& e)
          {
            ++ignored_;
            std::cerr << "sim_at_controller: " << e.what() << std::endl;
          }
        }
      }
    }
    catch (const Error& e)
    {
      std::cerr << "sim_at_controller: command link closed: " << e.what() << std::endl;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    last_arrival_ns_ = 0;
  }
}

void SimController::logCommand(const std::string& message)
{
  if (command_log_.is_open())
  {
    command_log_ << message << std::endl;
  }
}

void SimController::setReportLink(std::shared_ptr<TcpConnection> link)
{
  {
    std::lock_guard<std::mutex> lock(report_mutex_);
    report_link_ = std::move(link);
  }
  greet_ = true;  // tell the new peer the whole state
}

bool SimController::reportLinkUp()
{
  std::lock_guard<std::mutex> lock(report_mutex_);
  return report_link_ != nullptr;
}

void SimController::reportServerLoop(TcpServer& server)
{
  while (!stop_.stopped())
  {
    try
    {
      dropReportLinkDuringOutage();
      if (reportLinkUp())
      {
        stop_.waitFor(Milliseconds(20));
        continue;
      }
      auto peer = server.accept(Milliseconds(200));
      if (peer && report_outage_)
      {
        continue;  // closed at once: no report gets through
      }
      if (peer)
      {
        std::cerr << "sim_at_controller: report link to " << peer->describe() << std::endl;
        setReportLink(std::shared_ptr<TcpConnection>(std::move(peer)));
      }
    }
    catch (const Error&)
    {
      return;
    }
  }
}

void SimController::reportClientLoop()
{
  while (!stop_.stopped())
  {
    dropReportLinkDuringOutage();
    if (!reportLinkUp() && !report_outage_)
    {
      try
      {
        auto link = TcpConnection::connect(options_.report_host, options_.report_port, Milliseconds(1000));
        std::cerr << "sim_at_controller: report link to " << link->describe() << std::endl;
        setReportLink(std::shared_ptr<TcpConnection>(std::move(link)));
      }
      catch (const Error&)
      {
        // The node is not listening yet: try again.
      }
    }
    stop_.waitFor(Milliseconds(200));
  }
}

void SimController::dropReportLinkDuringOutage()
{
  if (!report_outage_)
  {
    return;
  }
  std::shared_ptr<TcpConnection> link;
  {
    std::lock_guard<std::mutex> lock(report_mutex_);
    link.swap(report_link_);
  }
  if (link)
  {
    std::cerr << "sim_at_controller: report link outage (SIGHUP): connection closed" << std::endl;
  }
}

void SimController::report(const Report& report)
{
  std::shared_ptr<TcpConnection> link;
  {
    std::lock_guard<std::mutex> lock(report_mutex_);
    link = report_link_;
  }
  if (!link)
  {
    return;
  }
  try
  {
    link->write(encode(report), Milliseconds(100));
  }
  catch (const Error& e)
  {
    std::cerr << "sim_at_controller: report link lost: " << e.what() << std::endl;
    std::lock_guard<std::mutex> lock(report_mutex_);
    if (report_link_ == link)
    {
      report_link_.reset();
    }
  }
}

PositionReport SimController::positionReport() const
{
  PositionReport r;
  for (int i = 0; i < 3; ++i)
  {
    r.position[i] = static_cast<int32_t>(std::llround(position_[i]));
  }
  return r;
}

void SimController::reportMode()
{
  if (jog_axis_)
  {
    report(JogModeReport{*jog_axis_});
  }
  else
  {
    report(AutoModeReport{});
  }
}

void SimController::consoleLoop()
{
  std::string line;
  while (std::getline(std::cin, line))
  {
    console(line);
  }
}

void SimController::handleConsole(const std::string& line)
{
  std::istringstream words(line);
  std::string verb, argument;
  words >> verb >> argument;
  if (verb == "estop")
  {
    setEStop(argument != "off");
  }
  else if (verb == "auto")
  {
    apply(AutoMode{});
  }
  else if (verb == "jog" && !argument.empty())
  {
    apply(JogMode{axisFromChar(argument[0])});
  }
  else if (verb == "home")
  {
    apply(Home{});
  }
  else if (!verb.empty())
  {
    std::cerr << "sim_at_controller: stdin commands: estop on|off, auto, jog X|Y|Z, home" << std::endl;
  }
}

void SimController::apply(const Command& command)
{
  const std::string refusal = sequencer_.refusal(command);
  if (!refusal.empty())
  {
    // Step 2: "even if the jog mode is turned on from the mode selector, Linux will not go
    // to jog mode, it ignores the change". Other out-of-order messages are ignored the same way.
    ++ignored_;
    std::cerr << "sim_at_controller: ignored: " << refusal << std::endl;
    return;
  }
  sequencer_.apply(command);
  if (const auto* setpoint = std::get_if<Setpoint>(&command))
  {
    ++setpoints_received_;
    for (const auto& fault : faults_)
    {
      if (fault.after_setpoints != setpoints_received_)
      {
        continue;
      }
      if (fault.action == SimFault::Action::kDropCommandLink)
      {
        std::cerr << "sim_at_controller: fault script: dropping the command link after setpoint " << setpoints_received_
                  << std::endl;
        drop_command_link_ = true;
      }
      else
      {
        setEStop(fault.action == SimFault::Action::kEStopOn);
      }
    }
    if (!estop_)
    {
      for (int i = 0; i < 3; ++i)
      {
        target_[i] = setpoint->position[i];
      }
    }
    homing_ = false;
  }
  else if (std::holds_alternative<JogMode>(command) || std::holds_alternative<AutoMode>(command))
  {
    jog_axis_ = sequencer_.jogAxis();
    reportMode();
  }
  else if (std::holds_alternative<Home>(command))
  {
    if (!estop_)
    {
      homing_ = true;
      at_home_reported_ = false;
    }
  }
}

void SimController::controlLoop()
{
  const int64_t period = 1000000;  // 1 ms
  const double dt = 1e-3;
  const double alpha = 1.0 - std::exp(-dt / (options_.lag_ms * 1e-3));
  int64_t due = monotonicNs() + period;
  uint64_t tick = 0;
  ReportPacing pacing;
  while (!stop_.stopped())
  {
    timespec when{static_cast<time_t>(due / 1000000000LL), static_cast<long>(due % 1000000000LL)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &when, nullptr);
    due += period;
    if (monotonicNs() > due + 100 * period)
    {
      due = monotonicNs() + period;  // the process was stopped: do not race to catch up
    }
    ++tick;
    takeCommands();
    if (greet_.exchange(false))
    {
      greet(tick, pacing);
    }
    takeEStopRequest();
    moveAxes(dt, alpha);
    reportPosition(tick, pacing);
  }
}

void SimController::takeCommands()
{
  // Commands of this time loop: everything up to and including one setpoint.
  std::deque<Command> now;
  std::deque<std::string> console;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (new_command_link_)
    {
      new_command_link_ = false;
      sequencer_.reset();
    }
    while (!queue_.empty())
    {
      const bool setpoint = std::holds_alternative<Setpoint>(queue_.front());
      now.push_back(std::move(queue_.front()));
      queue_.pop_front();
      if (setpoint)
      {
        break;
      }
    }
    console.swap(console_);
  }
  for (const auto& line : console)
  {
    handleConsole(line);
  }
  for (const auto& command : now)
  {
    apply(command);
  }
}

void SimController::greet(uint64_t tick, ReportPacing& pacing)
{
  if (!options_.estop_unreported)
  {
    report(EStopReport{estop_});
  }
  reportMode();
  report(positionReport());
  pacing.last_tick = tick;
}

void SimController::takeEStopRequest()
{
  const int request = estop_request_.exchange(-1);
  if (request >= 0 && (request == 1) != estop_)
  {
    estop_ = request == 1;
    std::cerr << "sim_at_controller: emergency stop " << (estop_ ? "on" : "off") << std::endl;
    if (estop_)
    {
      target_ = position_;  // the axes stop where they are
      homing_ = false;
    }
    report(EStopReport{estop_});
  }
}

// Axes: first-order lag towards the target; homing moves the target at the homing speed, a jog
// at its feed.
void SimController::moveAxes(double dt, double alpha)
{
  if (jog_axis_ && sequencer_.jogFeed() > 0 && options_.jog_speed > 0.0 && !estop_)
  {
    target_[static_cast<int>(*jog_axis_)] +=
        sequencer_.jogFeed() / double(kMaxFeed) * options_.jog_speed * kPulsesPerMm * dt;
  }
  if (homing_)
  {
    homeStep(dt);
  }
  if (!estop_)
  {
    for (int i = 0; i < 3; ++i)
    {
      position_[i] += (target_[i] - position_[i]) * alpha;
      if (std::fabs(target_[i] - position_[i]) < 0.01)
      {
        position_[i] = target_[i];
      }
    }
  }
}

void SimController::homeStep(double dt)
{
  const double step = options_.home_speed * kPulsesPerMm * dt;
  bool arrived = true;
  for (int i = 0; i < 3; ++i)
  {
    const double error = options_.home[i] - target_[i];
    target_[i] += std::clamp(error, -step, step);
    arrived = arrived && std::fabs(options_.home[i] - position_[i]) < 0.5;
  }
  if (arrived && !at_home_reported_)
  {
    position_ = {double(options_.home[0]), double(options_.home[1]), double(options_.home[2])};
    report(positionReport());
    report(HomeReport{});
    at_home_reported_ = true;
    homing_ = false;
  }
}

// A position report every report period while moving, one when the axes come to rest, and a
// heartbeat while idle.
void SimController::reportPosition(uint64_t tick, ReportPacing& pacing)
{
  const PositionReport current = positionReport();
  bool moved = false;
  for (int i = 0; i < 3; ++i)
  {
    moved = moved || current.position[i] != pacing.last_reported[i];
  }
  const bool due_report = moved && tick - pacing.last_tick >= static_cast<uint64_t>(options_.report_period_ms);
  const bool stopped_now = !moved && pacing.was_moving;
  if (due_report || stopped_now || tick - pacing.last_tick >= static_cast<uint64_t>(options_.heartbeat_ms))
  {
    report(current);
    for (int i = 0; i < 3; ++i)
    {
      pacing.last_reported[i] = current.position[i];
    }
    pacing.last_tick = tick;
    pacing.was_moving = moved;
  }
}
}  // namespace at_protocol
}  // namespace cnc_bridge
