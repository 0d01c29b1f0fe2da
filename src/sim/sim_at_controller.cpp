// sim_at_controller: the real-time Linux controller of docs/protocols/at_protocol.md (its paper's
// sections 5 and 6), without the machine. It serves the command socket ('@'-terminated messages,
// the paper's server_recv) and sends reports one per line (server_send), either as a server the
// node connects to or as a client of the node's report server. Every 1 ms time loop it takes one
// setpoint and the axes follow it with a first-order lag; it reports position, mode, home and
// emergency stop, and ignores jog requests while machining as the original controller does.
//
// Jog (with --jog-speed): in jog mode a feed F<n>@ above 0 moves the jog axis in the positive
// direction at n/255 of --jog-speed until the next feed or mode change, as if the operator held the
// joystick that way (the paper leaves the direction to the joystick); F0@ stops it.
//
// Emergency stop: stdin lines "estop on" / "estop off", SIGUSR1 (on) / SIGUSR2 (off), or a fault
// script. Also on stdin: "auto", "jog X|Y|Z" (the mode selector), "home".
//
// Link faults, for tests of the node's link handling: the fault script's "drop-command-link" closes
// the command connection after a given setpoint (the next connection starts a fresh sequence, as a
// controller whose host reconnected); SIGHUP starts a report link outage (the report connection is
// closed and every new one closed at once, so no report arrives) and the next SIGHUP ends it.
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <boost/program_options.hpp>
#include <cmath>
#include <deque>
#include <fstream>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/at_protocol/sequencer.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/testing/sim_support.h"
#include "cnc_bridge/transport/tcp.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
struct Options
{
  std::string host = "127.0.0.1";
  uint16_t command_port = 0;
  std::string report_mode = "server";
  std::string report_host = "127.0.0.1";
  uint16_t report_port = 0;
  double lag_ms = 5.0;        // first-order time constant of the axes
  int report_period_ms = 10;  // position reports while moving
  int heartbeat_ms = 1000;    // position report while idle
  double home_speed = 20.0;   // mm/s towards home
  double jog_speed = 0.0;     // mm/s that the jog feed F255 stands for; 0: jog mode moves nothing
  std::array<int32_t, 3> home{0, 0, 0};
  std::string fault_script;
  std::string pid_file;
  std::string command_log;        // every command message received, one per line, for tests to inspect
  bool estop_unreported = false;  // no E report on connection: a controller that reports only changes
};

/// One fault-script line: after the n-th setpoint received, switch the emergency stop or drop the
/// command connection.
struct Fault
{
  enum class Action
  {
    kEStopOn,
    kEStopOff,
    kDropCommandLink
  };
  uint64_t after_setpoints = 0;
  Action action = Action::kEStopOn;
};

std::vector<Fault> readFaultScript(const std::string& path)
{
  std::vector<Fault> faults;
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
    Fault fault;
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
    fault.action = action == "estop-on"    ? Fault::Action::kEStopOn
                   : action == "estop-off" ? Fault::Action::kEStopOff
                                           : Fault::Action::kDropCommandLink;
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

class SimController
{
 public:
  SimController(Options options, StopSignal& stop) : options_(std::move(options)), stop_(stop)
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

  void run()
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
      std::ofstream(options_.pid_file) << getpid() << "\n";
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

  /// Emergency stop from a signal, stdin or the fault script. Thread-safe.
  void setEStop(bool on) { estop_request_ = on ? 1 : 0; }
  /// Starts or ends a report link outage (SIGHUP). Async-signal-safe: one lock-free atomic.
  void toggleReportOutage() { report_outage_.fetch_xor(1); }
  void console(const std::string& line)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    console_.push_back(line);
  }

 private:
  // ---- command socket ----
  void commandLoop(TcpServer& server)
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

  /// Appends a received message (as it arrived, without its '@') to --command-log; flushed at once
  /// so a test reads what the controller has received so far.
  void logCommand(const std::string& message)
  {
    if (command_log_.is_open())
    {
      command_log_ << message << std::endl;
    }
  }

  // ---- report socket ----
  void setReportLink(std::shared_ptr<TcpConnection> link)
  {
    {
      std::lock_guard<std::mutex> lock(report_mutex_);
      report_link_ = std::move(link);
    }
    greet_ = true;  // tell the new peer the whole state
  }

  bool reportLinkUp()
  {
    std::lock_guard<std::mutex> lock(report_mutex_);
    return report_link_ != nullptr;
  }

  void reportServerLoop(TcpServer& server)
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

  void reportClientLoop()
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

  /// Closes the report connection while an outage (SIGHUP) lasts.
  void dropReportLinkDuringOutage()
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

  /// Writes one report; a failed write drops the link (the report loop connects or accepts again).
  void report(const Report& report)
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

  PositionReport positionReport() const
  {
    PositionReport r;
    for (int i = 0; i < 3; ++i)
    {
      r.position[i] = static_cast<int32_t>(std::llround(position_[i]));
    }
    return r;
  }

  void reportMode()
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

  // ---- stdin ----
  void consoleLoop()
  {
    std::string line;
    while (std::getline(std::cin, line))
    {
      console(line);
    }
  }

  void handleConsole(const std::string& line)
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

  // ---- the 1 ms time loop ----
  void apply(const Command& command)
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
        if (fault.action == Fault::Action::kDropCommandLink)
        {
          std::cerr << "sim_at_controller: fault script: dropping the command link after setpoint "
                    << setpoints_received_ << std::endl;
          drop_command_link_ = true;
        }
        else
        {
          setEStop(fault.action == Fault::Action::kEStopOn);
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

  void controlLoop()
  {
    const int64_t period = 1000000;  // 1 ms
    const double dt = 1e-3;
    const double alpha = 1.0 - std::exp(-dt / (options_.lag_ms * 1e-3));
    int64_t due = monotonicNs() + period;
    uint64_t tick = 0;
    std::array<double, 3> last_reported{NAN, NAN, NAN};
    uint64_t last_report_tick = 0;
    bool was_moving = false;
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

      if (greet_.exchange(false))
      {
        if (!options_.estop_unreported)
        {
          report(EStopReport{estop_});
        }
        reportMode();
        report(positionReport());
        last_report_tick = tick;
      }
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

      // Axes: first-order lag towards the target; homing moves the target at the homing speed,
      // a jog at its feed.
      if (jog_axis_ && sequencer_.jogFeed() > 0 && options_.jog_speed > 0.0 && !estop_)
      {
        target_[static_cast<int>(*jog_axis_)] +=
            sequencer_.jogFeed() / double(kMaxFeed) * options_.jog_speed * kPulsesPerMm * dt;
      }
      if (homing_)
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
      const PositionReport current = positionReport();
      bool moved = false;
      for (int i = 0; i < 3; ++i)
      {
        moved = moved || current.position[i] != last_reported[i];
      }
      const bool due_report = moved && tick - last_report_tick >= static_cast<uint64_t>(options_.report_period_ms);
      const bool stopped_now = !moved && was_moving;
      if (due_report || stopped_now || tick - last_report_tick >= static_cast<uint64_t>(options_.heartbeat_ms))
      {
        report(current);
        for (int i = 0; i < 3; ++i)
        {
          last_reported[i] = current.position[i];
        }
        last_report_tick = tick;
        was_moving = moved;
      }
    }
  }

  Options options_;
  StopSignal& stop_;
  std::vector<Fault> faults_;

  std::mutex mutex_;  // guards queue_, console_, arrivals bookkeeping
  std::deque<Command> queue_;
  std::deque<std::string> console_;
  bool new_command_link_ = false;  // the control loop resets the sequencer; guarded by mutex_
  std::ofstream command_log_;      // guarded by mutex_
  int64_t last_arrival_ns_ = 0;
  IntervalHistogram arrivals_;
  std::atomic<uint64_t> ignored_{0};

  std::mutex report_mutex_;
  std::shared_ptr<TcpConnection> report_link_;
  std::atomic<bool> greet_{false};
  std::atomic<int> estop_request_{-1};
  std::atomic<bool> drop_command_link_{false};  // set by the fault script, taken by the command loop
  std::atomic<int> report_outage_{0};           // SIGHUP toggles it (int: fetch_xor)

  // Owned by the control loop.
  Sequencer sequencer_;
  std::optional<Axis> jog_axis_;
  bool estop_ = false;
  bool homing_ = false;
  bool at_home_reported_ = false;
  uint64_t setpoints_received_ = 0;
  std::array<double, 3> position_{0, 0, 0};
  std::array<double, 3> target_{0, 0, 0};
};

SimController* the_sim = nullptr;

void onEStopSignal(int signal)
{
  if (the_sim)
  {
    the_sim->setEStop(signal == SIGUSR1);  // only an atomic store: async-signal-safe
  }
}

void onReportOutageSignal(int)
{
  if (the_sim)
  {
    the_sim->toggleReportOutage();
  }
}
}  // namespace

int main(int argc, char** argv)
{
  StopSignal& stop = sim::installStopHandler();
  namespace po = boost::program_options;
  Options options;
  std::string home;
  po::options_description description("sim_at_controller options");
  description.add_options()("help,h", "this help")("host", po::value(&options.host)->default_value(options.host),
                                                   "address to listen on (and of the node in report client mode)")(
      "command-port", po::value(&options.command_port)->default_value(0), "command server port (0: a free one)")(
      "report-mode", po::value(&options.report_mode)->default_value("server"),
      "server: the node connects for reports; client: connect to the node's report server")(
      "report-host", po::value(&options.report_host)->default_value(options.report_host), "node's report server host")(
      "report-port", po::value(&options.report_port)->default_value(0),
      "report server port (server mode, 0: a free one) or the node's (client mode)")(
      "lag-ms", po::value(&options.lag_ms)->default_value(options.lag_ms), "time constant of the axes (ms)")(
      "report-period-ms", po::value(&options.report_period_ms)->default_value(options.report_period_ms),
      "position report interval while moving (ms)")(
      "heartbeat-ms", po::value(&options.heartbeat_ms)->default_value(options.heartbeat_ms),
      "position report interval while idle (ms)")("home", po::value(&home)->default_value("0,0,0"),
                                                  "home position, pulses \"x,y,z\"")(
      "home-speed", po::value(&options.home_speed)->default_value(options.home_speed), "homing speed (mm/s)")(
      "jog-speed", po::value(&options.jog_speed)->default_value(options.jog_speed),
      "speed (mm/s) of the jog feed F255: a jog feed moves the jog axis (positive direction); 0: jog moves nothing")(
      "fault-script", po::value(&options.fault_script),
      "file of \"setpoint <n> estop-on|estop-off|drop-command-link\" lines")(
      "pid-file", po::value(&options.pid_file), "write the process id here (for SIGUSR1/SIGUSR2 e-stop)")(
      "command-log", po::value(&options.command_log), "append every command message received to this file")(
      "estop-unreported", po::bool_switch(&options.estop_unreported),
      "send no E0/E1 on connection (the e-stop state is reported only when it changes)");
  try
  {
    po::variables_map vm;
    po::store(po::parse_command_line(argc, argv, description), vm);
    po::notify(vm);
    if (vm.count("help"))
    {
      std::cout << description
                << "\nstdin: estop on|off, auto, jog X|Y|Z, home; SIGUSR1 e-stop on, SIGUSR2 off; SIGHUP report link "
                   "outage on/off\n";
      return 0;
    }
    char comma1 = 0, comma2 = 0;
    std::istringstream in(home);
    if (!(in >> options.home[0] >> comma1 >> options.home[1] >> comma2 >> options.home[2]) || comma1 != ',' ||
        comma2 != ',')
    {
      throw ConfigError("--home must be \"x,y,z\" in pulses");
    }
    if (!(options.lag_ms > 0.0) || options.report_period_ms < 1 || options.heartbeat_ms < 1)
    {
      throw ConfigError("--lag-ms, --report-period-ms and --heartbeat-ms must be positive");
    }
    if (!(options.jog_speed >= 0.0))
    {
      throw ConfigError("--jog-speed must be 0 or a positive number of mm/s");
    }
    SimController sim(options, stop);
    the_sim = &sim;
    struct sigaction action
    {
    };
    action.sa_handler = onEStopSignal;
    sigemptyset(&action.sa_mask);
    sigaction(SIGUSR1, &action, nullptr);
    sigaction(SIGUSR2, &action, nullptr);
    struct sigaction outage
    {
    };
    outage.sa_handler = onReportOutageSignal;
    sigemptyset(&outage.sa_mask);
    sigaction(SIGHUP, &outage, nullptr);
    sim.run();
    the_sim = nullptr;
  }
  catch (const std::exception& e)
  {
    std::cerr << "sim_at_controller: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
