// sim_at_controller: the simulated '@' controller (src/sim/at_protocol/sim_controller.h) as a
// program: its options, the signals and stdin lines that drive it.
//
// Jog (with --jog-speed): in jog mode a feed F<n>@ above 0 moves the jog axis in the positive
// direction at n/255 of --jog-speed until the next feed or mode change, as if the operator held the
// joystick that way (the ESPRIT paper, docs/protocols/at_protocol.md#source, leaves the direction to the
// joystick); F0@ stops it.
//
// Emergency stop: stdin lines "estop on" / "estop off", SIGUSR1 (on) / SIGUSR2 (off), or a fault
// script. Also on stdin: "auto", "jog X|Y|Z" (the mode selector), "home".
//
// Link faults, for tests of the node's link handling: the fault script's "drop-command-link" closes
// the command connection after a given setpoint (the next connection starts a fresh sequence, as a
// controller whose host reconnected); SIGHUP starts a report link outage (the report connection is
// closed and every new one closed at once, so no report arrives) and the next SIGHUP ends it.
#include <signal.h>

#include <boost/program_options.hpp>
#include <iostream>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "sim/at_protocol/sim_controller.h"
#include "sim/sim_support.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
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
  SimControllerOptions options;
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
