// sim_haas_serial xmodem: a Haas Classic Control's RS-232 port with setting 14 = XMODEM, as the
// OpenDNC's capture shows it (docs/protocols/xmodem.md#haas-specifics): checksum mode only; while
// waiting to receive it NAKs every --nak-interval, so several NAKs are queued before a host starts
// sending; it answers the host's EOT with CAN CAN CAN; programs it receives are stored in --dir
// under their O number. It sends --program (NAK start; a 'C' is ignored, as a checksum-only
// control does) when asked: with --send-on request (the default) whenever the host asks with NAK;
// with --send-on signal only after the operator presses SEND: SIGUSR1, or --send at start-up (the
// control then waits for the host's NAK, as a Haas does). Line-rate pacing (--pace-baud) and
// seeded faults (--faults).
//
//   sim_haas_serial xmodem [--link PATH] [--dir DIR] [--program FILE] [--send-on request|signal]
//                          [--send] [--nak-interval S] [--pace-baud N]
//                          [--faults flip=..,drop=..,dup=..,lose=..,seed=..] [--eob lf] [--eob-checksum wire]
//   kill -USR1 <pid>       the operator presses SEND (the program goes to the host's next NAK)
#include <pthread.h>

#include <atomic>
#include <boost/program_options.hpp>
#include <csignal>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <regex>
#include <thread>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "cnc_bridge/transport/pushback_transport.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "sim/haas_serial/modes.h"
#include "sim/sim_support.h"
#include "testing/faulty_transport.h"
#include "testing/paced_transport.h"
#include "testing/pty.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace sim
{
namespace
{
/// The name a Haas gives a received program: its O number ("O05555.nc"), else a counter.
std::string programName(const std::string& text, unsigned counter)
{
  std::smatch match;
  static const std::regex kONumber("(^|\\n)\\s*[Oo](\\d{1,5})");
  if (std::regex_search(text, match, kONumber))
    return "O" + std::string(5 - std::min<size_t>(5, match[2].length()), '0') + match[2].str() + ".nc";
  return "received_" + std::to_string(counter) + ".nc";
}

/// SIGUSR1 blocked in this thread and the threads it starts: call before any thread starts.
void blockSendSignal()
{
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGUSR1);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
}

/// The operator's SEND key: SIGUSR1 sets it, a send takes it. SIGUSR1 is taken by sigwait in a
/// thread of its own, started after installStopHandler() so that it keeps SIGINT/SIGTERM blocked
/// (blockSendSignal() must have run before either).
std::atomic<bool>& sendPressedOnSignal()
{
  static std::atomic<bool> pressed{false};
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGUSR1);
  std::thread(
      [set]
      {
        for (;;)
        {
          int signal_number = 0;
          if (sigwait(&set, &signal_number) == 0)
          {
            pressed = true;
            std::cerr << "sim_haas_serial: SEND pressed (SIGUSR1)" << std::endl;
          }
        }
      })
      .detach();  // lives as long as the process: sigwait has no timeout to end it by
  return pressed;
}

/// After SEND: waits up to \p wait for the host's NAK (a 'C' or anything else is not an answer a
/// checksum-only control knows), puts it back for the sender. \returns false if none came.
bool waitForHostNak(PushbackTransport& line, Milliseconds wait)
{
  const auto deadline = std::chrono::steady_clock::now() + wait;
  for (;;)
  {
    const auto left = std::chrono::duration_cast<Milliseconds>(deadline - std::chrono::steady_clock::now());
    const int c = left.count() > 0 ? line.readByte(left) : -1;
    if (c < 0)
      return false;
    if (c == xmodem::kNak)
    {
      line.unread(xmodem::kNak);
      return true;
    }
  }
}

/// The command line, roslaunch's __name:=/__log:= dropped. \returns an exit code if the run ends
/// here (--help, a bad option), else nothing and \p vm filled.
std::optional<int> parseXmodemArgs(const std::vector<std::string>& all_args, po::variables_map& vm)
{
  // roslaunch appends __name:= and __log:= when a test launches the simulator as a node.
  std::vector<std::string> args;
  std::copy_if(all_args.begin(), all_args.end(), std::back_inserter(args),
               [](const std::string& a) { return a.rfind("__", 0) != 0; });
  po::options_description options("sim_haas_serial xmodem options");
  options.add_options()("help,h", "this help")("link", po::value<std::string>()->default_value(""),
                                               "make this symbolic link to the pty (a stable device name)")(
      "dir", po::value<std::string>()->default_value("."), "where received programs are stored")(
      "program", po::value<std::string>()->default_value(""), "the program sent when the host asks for one")(
      "send-on", po::value<std::string>()->default_value("request"),
      "request: send --program whenever the host asks with NAK; signal: only after SEND is pressed "
      "(SIGUSR1 or --send), then to the host's next NAK")(
      "send", po::bool_switch(), "press SEND once at start-up (the program goes to the host's first NAK)")(
      "nak-interval", po::value<double>()->default_value(1.0), "seconds between NAKs while waiting to receive")(
      "pace-baud", po::value<unsigned>()->default_value(0), "pace output to this baud rate, 8N1 (0 = pty speed)")(
      "faults", po::value<std::string>()->default_value(""), "fault injection, e.g. flip=0.001,lose=0.01,seed=3")(
      "eob", po::value<std::string>()->default_value("lf"), "EOB pattern, Haas setting 25: lf|cr|crlf|crcr|lflf")(
      "eob-checksum", po::value<std::string>()->default_value("wire"),
      "how the control sums ends of block: wire (the bytes sent) or lf (each end of block as LF)")(
      "timeout-scale", po::value<double>()->default_value(1.0),
      "multiply the protocol timeouts (tests use 0.1 for fast recovery)");
  try
  {
    po::store(po::command_line_parser(args).options(options).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_haas_serial xmodem: " << e.what() << "\n" << options;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << options;
    return 0;
  }
  const std::string send_on = vm["send-on"].as<std::string>();
  if (send_on != "request" && send_on != "signal")
  {
    std::cerr << "sim_haas_serial xmodem: --send-on is request or signal, not '" << send_on << "'\n";
    return 2;
  }
  return std::nullopt;
}

/// What the serving loop needs: the protocol settings, scaled by --timeout-scale, and the options.
struct XmodemSession
{
  explicit XmodemSession(const po::variables_map& vm) : scale(vm["timeout-scale"].as<double>())
  {
    config.char_timeout = scaled(1000);
    config.purge_quiet = scaled(1000);
    config.block_timeout = scaled(10000);
    config.ack_timeout = scaled(10000);
    config.stale_nak_settle = scaled(1000);
    config.eot_quiet = scaled(250);
    config.start_wait = scaled(1000);
    config.skip_initial_request = true;
    config.answer_eot_with_can = true;
    text.control_eob = xmodem::parseEob(vm["eob"].as<std::string>());
    text.eob_checksum = xmodem::parseEobChecksum(vm["eob-checksum"].as<std::string>());
    dir = vm["dir"].as<std::string>();
    std::error_code ignored;
    std::filesystem::create_directories(dir, ignored);  // a failure shows when a program is stored
    program = vm["program"].as<std::string>();
    nak_interval = Milliseconds(static_cast<int64_t>(vm["nak-interval"].as<double>() * 1000));
    send_wait = scaled(60000);  // how long a pressed SEND waits for the host
    send_on_signal = vm["send-on"].as<std::string>() == "signal";
  }

  Milliseconds scaled(int ms) const { return Milliseconds(std::max<int64_t>(1, static_cast<int64_t>(ms * scale))); }

  double scale;
  xmodem::Config config;
  xmodem::TextOptions text;
  std::string dir;
  std::string program;
  Milliseconds nak_interval{0};
  Milliseconds send_wait{0};
  bool send_on_signal = false;
  unsigned received = 0;
};

/// SEND pressed: the control waits for the host's NAK and sends the program.
void sendOnPressedSend(PushbackTransport& line, const XmodemSession& session)
{
  if (session.program.empty())
    std::cerr << "sim_haas_serial: SEND pressed but --program is not set" << std::endl;
  else if (!waitForHostNak(line, session.send_wait))
    std::cerr << "sim_haas_serial: SEND pressed but the host did not ask (no NAK within "
              << session.send_wait.count() / 1000.0 << " s)" << std::endl;
  else
    std::cerr << "sim_haas_serial: "
              << xmodem::sendFile(line, session.program, xmodem::Mode::kChecksum, session.config, session.text).message
              << std::endl;
}

/// The host started sending (its first block header is put back): receive and store the program.
void receiveProgram(PushbackTransport& line, XmodemSession& session)
{
  xmodem::Receiver receiver(line, xmodem::Mode::kChecksum, xmodem::withEobReading(session.config, session.text));
  const std::string contents = xmodem::fromWire(receiver.receive(), session.text);
  const std::string path = session.dir + "/" + programName(contents, ++session.received);
  AtomicFileWriter writer(path);
  writer.write(contents);
  writer.commit();
  std::cerr << "sim_haas_serial: received " << path << " (" << contents.size() << " bytes, " << receiver.stats().retries
            << " retries)" << std::endl;
}

/// One turn of the control's loop: a pressed SEND, else a NAK and whatever the host answers.
void serveOneTransfer(PushbackTransport& line, XmodemSession& session, std::atomic<bool>& send_pressed)
{
  if (send_pressed.exchange(false))
  {
    sendOnPressedSend(line, session);
    return;
  }
  // Waiting in "receive" as the control does: a NAK now and then until something happens.
  line.writeByte(xmodem::kNak);
  const int c = line.readByte(session.nak_interval);
  if (c == xmodem::kSoh || c == xmodem::kStx)
  {
    line.unread(static_cast<uint8_t>(c));
    receiveProgram(line, session);
  }
  else if (c == xmodem::kNak && !session.send_on_signal)
  {
    // The host wants a program (it is a receiver asking in checksum mode).
    if (session.program.empty())
    {
      std::cerr << "sim_haas_serial: host asked for a program but --program is not set" << std::endl;
      xmodem::sendCancel(line);
      line.purge(session.scaled(1000));
      return;
    }
    line.unread(xmodem::kNak);
    const xmodem::FileResult result =
        xmodem::sendFile(line, session.program, xmodem::Mode::kChecksum, session.config, session.text);
    std::cerr << "sim_haas_serial: " << result.message << std::endl;
  }
  // Anything else ('C' from a host that wants CRC, noise, a NAK nobody pressed SEND for): a
  // checksum-only control ignores it.
}

int runXmodem(const std::vector<std::string>& all_args)
{
  po::variables_map vm;
  if (const std::optional<int> exit_code = parseXmodemArgs(all_args, vm))
    return *exit_code;

  blockSendSignal();  // before the stop handler's thread starts
  StopSignal& stop = installStopHandler();
  std::atomic<bool>& send_pressed = sendPressedOnSignal();
  send_pressed = vm["send"].as<bool>();
  try
  {
    PtyMaster pty(vm["link"].as<std::string>());
    onStop([&pty] { pty.interrupt(); });
    Transport* link = &pty;
    std::unique_ptr<PacedTransport> paced;
    if (vm["pace-baud"].as<unsigned>() > 0)
    {
      paced = std::make_unique<PacedTransport>(pty, vm["pace-baud"].as<unsigned>() / 10.0);  // 8N1: 10 bits
      link = paced.get();
    }
    std::unique_ptr<FaultyTransport> faulty;
    const FaultSettings faults = FaultSettings::parse(vm["faults"].as<std::string>());
    if (faults.any())
    {
      faulty = std::make_unique<FaultyTransport>(*link, faults);
      link = faulty.get();
    }
    PushbackTransport line(*link);

    XmodemSession session(vm);

    announce("sim_haas_serial", "pty " + pty.slavePath());
    while (!stop.stopped())
    {
      try
      {
        serveOneTransfer(line, session, send_pressed);
      }
      catch (const CancelledError&)
      {
        break;
      }
      catch (const Error& e)
      {
        std::cerr << "sim_haas_serial: transfer failed: " << e.what() << std::endl;
        try
        {
          line.purge(session.scaled(1000));
        }
        catch (const CancelledError&)
        {
          break;
        }
      }
    }
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial xmodem: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}

const SimMode kXmodemMode("xmodem", "XModem peer as the Haas in OpenDNC's capture (checksum, NAKs, CAN answer to EOT)",
                          &runXmodem);
}  // namespace
}  // namespace sim
}  // namespace cnc_bridge
