// cnc_dnc's drip-feed and backup subcommands (the table in cnc_dnc.cpp lists them):
//
//   cnc_dnc drip   --port DEV [serial options] [--start-line N | --start-block N1234]
//                  [--show-preamble | --preamble-file F] [drip options] FILE
//   cnc_dnc backup --port DEV [serial options] [--timeout S] [--quiet S] FILE
//
// Ctrl-C cancels cleanly; drip then says which line it stopped at, for a restart. A running drip
// pauses on SIGUSR1 and resumes on SIGUSR2 (kill -USR1 PID; the PID is printed at the start).
// --baud defaults to 115200, as for send/receive and dnc_node: set it to the control's setting.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <boost/program_options.hpp>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/stop_handler.h"
#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/transport/serial_line.h"
#include "progress_line.h"
#include "protected_options.h"
#include "serial_options.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace cli
{
namespace
{
/// The serial options of drip and backup: --port is checked by parse(), so that --help needs none.
po::options_description dripSerialOptions()
{
  po::options_description options("serial port");
  options.add_options()("help,h", "this help")(
      "port,p", po::value<std::string>(),
      "serial device (/dev/ttyUSB0) or device server port (tcp://host:port, rfc2217://host:port)")(
      "baud,b", po::value<unsigned>()->default_value(115200), "baud rate: the control's (as send/receive)")(
      "parity", po::value<std::string>()->default_value("none"), "none|even|odd (ISO tape code: even with 7 bits)")(
      "data-bits", po::value<unsigned>()->default_value(8), "7|8")("stop-bits", po::value<unsigned>()->default_value(1),
                                                                   "1|2")(
      "wire-trace", po::value<std::string>(),
      "write every byte of the line, both ways, to a trace file in this folder (cnc_dnc replay plays it back)");
  return options;
}

// Parses; prints usage and returns false on --help or an error (status in \p status).
bool parse(const std::string& command, const std::vector<std::string>& args, const po::options_description& options,
           po::variables_map& vm, int& status)
{
  po::options_description all(options);
  all.add_options()("file", po::value<std::string>(), "program file");
  po::positional_options_description positional;
  positional.add("file", 1);
  const std::string usage = "usage: cnc_dnc " + command + " --port DEV [options] FILE\n";
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc " << command << ": " << e.what() << "\n" << usage << options;
    status = 2;
    return false;
  }
  if (vm.count("help"))
  {
    std::cout << usage << options;
    status = 0;
    return false;
  }
  if (!vm.count("port") || !vm.count("file"))
  {
    std::cerr << "cnc_dnc " << command << ": --port and FILE are required\n" << usage << options;
    status = 2;
    return false;
  }
  return true;
}

SerialSettings serialSettings(const po::variables_map& vm)
{
  SerialSettings s = cli::serialSettingsFrom(vm);
  // Drip-feed reads DC1/DC3 itself (kernel IXON would swallow them); RTS/CTS is the kernel's. With
  // --line-flow xonxoff the line obeys DC3/DC1 below the feed instead: the driver, or a device
  // server's UART over rfc2217:// (which stops at once, where the feed stops only what it has not
  // yet handed to the network).
  s.flow_control =
      vm.count("flow") && vm["flow"].as<std::string>() == "rtscts" ? FlowControl::kRtsCts : FlowControl::kNone;
  if (vm.count("line-flow") && vm["line-flow"].as<std::string>() != "none")
  {
    if (vm["line-flow"].as<std::string>() != "xonxoff")
      throw ConfigError("--line-flow is none or xonxoff, not '" + vm["line-flow"].as<std::string>() + "'");
    if (s.flow_control != FlowControl::kNone || vm["flow"].as<std::string>() != "none")
      throw ConfigError("--line-flow xonxoff needs --flow none: the line takes DC3/DC1, the feed would not see them");
    s.flow_control = FlowControl::kXonXoff;
  }
  s.validate();
  return s;
}

Milliseconds seconds(double value)
{
  return Milliseconds(static_cast<int64_t>(value * 1000.0));
}

/// Drip-feed and backup detail: the line being moved, its N number, whether the control holds us
/// or the operator paused.
std::string dripDetail(uint64_t line, const std::string& block, bool held, bool paused = false)
{
  std::string detail = "line " + std::to_string(line);
  if (!block.empty())
    detail += " " + block;
  if (paused)
    detail += " PAUSED (SIGUSR2 resumes)";
  else if (held)
    detail += " HELD (XOFF)";
  return detail;
}

/// The feed SIGUSR1 pauses and SIGUSR2 resumes (DripSender::pause()/resume() only store an atomic
/// flag, which a signal handler may do).
std::atomic<dnc::DripSender*> signalled_sender{nullptr};

void onPauseSignal(int signal)
{
  dnc::DripSender* sender = signalled_sender.load();
  if (sender == nullptr)
    return;
  if (signal == SIGUSR1)
    sender->pause();
  else
    sender->resume();
}

/// SIGUSR1/SIGUSR2 reach \p sender while this lives.
class PauseSignals
{
 public:
  explicit PauseSignals(dnc::DripSender& sender)
  {
    signalled_sender = &sender;
    struct sigaction action
    {
    };
    action.sa_handler = &onPauseSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    ::sigaction(SIGUSR1, &action, nullptr);
    ::sigaction(SIGUSR2, &action, nullptr);
  }
  ~PauseSignals()
  {
    ::signal(SIGUSR1, SIG_DFL);
    ::signal(SIGUSR2, SIG_DFL);
    signalled_sender = nullptr;
  }
  PauseSignals(const PauseSignals&) = delete;
  PauseSignals& operator=(const PauseSignals&) = delete;
};
}  // namespace

namespace
{
/// --preamble-file's blocks, or "" (the restart's own preamble) without it.
std::string preambleFrom(const po::variables_map& vm)
{
  if (vm.count("preamble-file") == 0)
    return "";
  std::ifstream in(vm["preamble-file"].as<std::string>());
  if (!in)
    throw ConfigError("cannot read " + vm["preamble-file"].as<std::string>());
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}
}  // namespace

int runDrip(const std::vector<std::string>& args)
{
  po::options_description options = dripSerialOptions();
  options.add_options()("eob", po::value<std::string>()->default_value("lf"),
                        "end of block sent: lf (ISO, Fanuc)|cr|crlf (Haas)|lfcr|lfcrcr")(
      "flow", po::value<std::string>()->default_value("xonxoff"), "xonxoff (DC3/DC1, parity masked)|rtscts|none")(
      "line-flow", po::value<std::string>()->default_value("none"),
      "none|xonxoff: the line itself obeys DC3/DC1 (the port's driver, or a device server's UART over "
      "rfc2217://), with --flow none")("no-pace", po::bool_switch(),
                                       "do not pace writes to the line rate (drain after each instead)")(
      "chunk", po::value<size_t>()->default_value(4), "characters per write")(
      "dc-codes", po::bool_switch(), "DC2 before and DC4 after the program (Haas setting 14)")(
      "leader", po::value<size_t>()->default_value(0), "NUL characters before and after the program")(
      "no-percent", po::bool_switch(), "do not add '%' framing when the file lacks it")(
      "allow-lowercase", po::bool_switch(), "let lowercase pass the pre-send check (8N1 controls)")(
      "start-line", po::value<uint64_t>()->default_value(0), "restart at this line of the file (1-based)")(
      "start-block", po::value<std::string>()->default_value(""), "restart at this sequence number, e.g. N1234")(
      "show-preamble", po::bool_switch(), "print the modal blocks a restart would send first, and stop")(
      "preamble-file", po::value<std::string>(), "send these blocks before the restart point instead")(
      "wait-dc1", po::bool_switch(), "send nothing until the control asks with DC1")(
      "hold-timeout", po::value<double>()->default_value(0), "seconds held by XOFF before --hold-action (0: forever)")(
      "hold-action", po::value<std::string>()->default_value("fail"), "fail|resume (assume the XON was lost)")(
      "realtime", po::value<int>()->default_value(0),
      "SCHED_FIFO priority while feeding (0: normal; keeps the pacing on time on a loaded machine)");
  addProtectedOptions(options);
  po::variables_map vm;
  int status = 0;
  if (!parse("drip", args, options, vm, status))
    return status;
  checkProtected(vm, vm["file"].as<std::string>());  // before the port is opened
  const SerialSettings settings = serialSettings(vm);
  dnc::DripOptions drip;
  drip.eob = dnc::parseEob(vm["eob"].as<std::string>());
  drip.flow = dnc::parseDripFlow(vm["flow"].as<std::string>());
  if (!vm["no-pace"].as<bool>())
    drip.pace_cps = settings.charactersPerSecond();
  drip.chunk = vm["chunk"].as<size_t>();
  drip.dc_codes = vm["dc-codes"].as<bool>();
  drip.leader_length = drip.trailer_length = vm["leader"].as<size_t>();
  drip.add_percent = !vm["no-percent"].as<bool>();
  drip.rules.reject_lowercase = !vm["allow-lowercase"].as<bool>();
  drip.wait_for_dc1 = vm["wait-dc1"].as<bool>();
  drip.realtime_priority = std::max(0, vm["realtime"].as<int>());
  drip.hold_timeout = seconds(vm["hold-timeout"].as<double>());
  const std::string hold_action = vm["hold-action"].as<std::string>();
  if (hold_action != "fail" && hold_action != "resume")
    throw ConfigError("--hold-action must be fail or resume");
  drip.on_hold_timeout = hold_action == "resume" ? dnc::HoldTimeoutAction::kResume : dnc::HoldTimeoutAction::kFail;
  // Checked again on the head the feed reads to send (one open file): a protected program saved
  // over the file since the check above is not sent.
  const std::string file = vm["file"].as<std::string>();
  drip.check_head = [&vm, file](const std::string& head) { checkProtectedContents(vm, file, head); };

  dnc::RestartPoint restart;
  restart.line = vm["start-line"].as<uint64_t>();
  restart.block = vm["start-block"].as<std::string>();
  const dnc::DripPlan plan = dnc::planDrip(file, drip, restart, preambleFrom(vm));
  for (const auto& warning : plan.scan.warnings)
    std::cerr << "cnc_dnc drip: warning: " << warning << "\n";
  if (vm["show-preamble"].as<bool>())
  {
    std::cout << plan.preamble;
    return 0;
  }

  static std::atomic<bool> cancel{false};
  installStopHandler();
  onStop([] { cancel = true; });
  drip.cancel = &cancel;
  const auto port = openSerialLine(settings);
  dnc::DripSender sender(*port, drip);
  const PauseSignals pause_signals(sender);
  std::cerr << "cnc_dnc drip: pause with kill -USR1 " << ::getpid() << ", resume with kill -USR2 " << ::getpid()
            << "\n";
  cli::ProgressLine bar("drip " + file);
  const auto result = sender.send(plan, [&](const dnc::DripProgress& p)
                                  { bar.show(p.bytes, p.total, dripDetail(p.line, p.block, p.held, p.paused)); });
  bar.finish();
  if (result.xoff_events > 0)
    std::cout << "cnc_dnc drip: " << result.xoff_events << " XOFF, largest output queue at an XOFF "
              << result.max_queued_at_xoff << " characters (with one write: at most " << drip.xoff_allowance
              << " may follow an XOFF)" << std::endl;
  if (result.completed())
  {
    std::cout << result.message << std::endl;
    return 0;
  }
  std::cerr << "cnc_dnc drip: " << result.message << "\n";
  if (result.stopped_at_line > 0)
    std::cerr << "cnc_dnc drip: to restart: --start-line " << result.stopped_at_line + 1 << "\n";
  return 1;
}

int runBackup(const std::vector<std::string>& args)
{
  po::options_description options = dripSerialOptions();
  options.add_options()("timeout,t", po::value<double>()->default_value(120),
                        "seconds to wait for the control to start punching (0: forever)")(
      "quiet", po::value<double>()->default_value(5),
      "seconds of silence that end a program punched without its closing '%'")("no-dc1", po::bool_switch(),
                                                                               "do not send DC1 when ready");
  po::variables_map vm;
  int status = 0;
  if (!parse("backup", args, options, vm, status))
    return status;
  dnc::BackupOptions backup;
  backup.start_timeout = seconds(vm["timeout"].as<double>());
  backup.quiet_timeout = seconds(vm["quiet"].as<double>());
  backup.send_dc1 = !vm["no-dc1"].as<bool>();
  static std::atomic<bool> cancel{false};
  installStopHandler();
  onStop([] { cancel = true; });
  backup.cancel = &cancel;
  const auto port = openSerialLine(serialSettings(vm));
  const std::string file = vm["file"].as<std::string>();
  dnc::BackupReceiver receiver(*port, backup);
  cli::ProgressLine bar("backup " + file);
  std::cerr << "waiting for the control to punch (PUNCH / SEND RS-232 on the control)...\n";
  const auto result = receiver.receive(
      file, [&](const dnc::BackupProgress& p) { bar.show(p.bytes, 0, dripDetail(p.line, "", false)); });
  bar.finish();
  std::cout << result.message << std::endl;
  return 0;
}
}  // namespace cli
}  // namespace cnc_bridge
