// cnc_dnc: NC program transfer on a bare serial port, without ROS. One subcommand per transfer
// kind, each an entry in kCommands (name, summary, function), so drip-feed and backup are added
// with one function and one table line. Exit status 0 only for a verified complete transfer;
// anything else prints one line saying what went wrong.
//
//   cnc_dnc send    --port DEV [serial options] [--mode checksum|crc|1k] [--turnaround MS]
//                   [--ack-turnaround MS] FILE
//   cnc_dnc receive --port DEV [serial options] [--mode checksum|crc] [--timeout S]
//                   [--block-timeout S] FILE
//   (both: [--retries N] [--wait-chars N] [--wait-floor MS])
//   cnc_dnc drip    --port DEV [serial options] [--start-line N] FILE   (cnc_dnc_drip.cpp)
//   cnc_dnc backup  --port DEV [serial options] FILE                    (cnc_dnc_drip.cpp)
//   cnc_dnc send    --share URL [--credentials FILE] [--allow-protected] FILE (cnc_dnc_share.cpp)
//   cnc_dnc receive --share URL [--credentials FILE] NAME OUT
//   cnc_dnc list    --share URL [--credentials FILE]
//   cnc_dnc doctor  --port DEV [serial options] [--listen S]            (cnc_dnc_doctor.cpp)
//   cnc_dnc replay  --port DEV [serial options] [--speed X] [--slack S] TRACE (cnc_dnc_replay.cpp)
//   (send, receive, drip, backup: [--wire-trace DIR] traces the line)
//   cnc_dnc history (--archive DIR | --program-dir DIR) NAME
//   cnc_dnc diff    (--archive DIR | --program-dir DIR) NAME [V1 [V2]]
// DEV is a serial device, tcp://host:port (a device server's raw TCP port) or rfc2217://host:port
// (a device server's RFC 2217 port): serial_line.h.
#include <unistd.h>

#include <algorithm>
#include <boost/program_options.hpp>
#include <chrono>
#include <cstdio>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/stop_handler.h"
#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/network_waits.h"
#include "progress_line.h"
#include "protected_options.h"
#include "serial_options.h"

namespace po = boost::program_options;
using namespace cnc_bridge;

namespace cnc_bridge
{
namespace cli
{
int runDrip(const std::vector<std::string>& args);          // cnc_dnc_drip.cpp
int runBackup(const std::vector<std::string>& args);        // cnc_dnc_drip.cpp
int runShareSend(const std::vector<std::string>& args);     // cnc_dnc_share.cpp
int runShareReceive(const std::vector<std::string>& args);  // cnc_dnc_share.cpp
int runList(const std::vector<std::string>& args);          // cnc_dnc_share.cpp
int runHistory(const std::vector<std::string>& args);       // cnc_dnc_share.cpp
int runDiff(const std::vector<std::string>& args);          // cnc_dnc_share.cpp
bool namesShare(const std::vector<std::string>& args);      // cnc_dnc_share.cpp
int runDrip(const std::vector<std::string>& args);          // cnc_dnc_drip.cpp
int runBackup(const std::vector<std::string>& args);        // cnc_dnc_drip.cpp
int runDoctor(const std::vector<std::string>& args);        // cnc_dnc_doctor.cpp
int runReplay(const std::vector<std::string>& args);        // cnc_dnc_replay.cpp
}  // namespace cli
}  // namespace cnc_bridge

namespace
{
/// Thrown for a bad command line: printed with the usage, exit status 2.
struct UsageError : std::runtime_error
{
  using std::runtime_error::runtime_error;
};

SerialSettings serialSettings(const po::variables_map& vm)
{
  SerialSettings s = cli::serialSettingsFrom(vm);
  s.validate();
  return s;
}

/// Parses a subcommand's arguments; FILE is the one positional argument.
po::variables_map parse(const std::string& command, const std::vector<std::string>& args,
                        const po::options_description& options)
{
  po::options_description all(options);
  all.add_options()("file", po::value<std::string>()->required(), "program file");
  po::positional_options_description positional;
  positional.add("file", 1);
  po::variables_map vm;
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    if (vm.count("help"))
    {
      std::cout << "usage: cnc_dnc " << command << " [options] FILE\n" << options;
      std::exit(0);
    }
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::ostringstream usage;
    usage << e.what() << "\nusage: cnc_dnc " << command << " [options] FILE\n" << options;
    throw UsageError(usage.str());
  }
  return vm;
}

/// The progress of an XModem transfer on a ProgressLine. Called after every block (thousands a
/// second on a fast link), so between redraws it only reads the clock: no text is built.
std::function<void(const xmodem::Progress&)> showOn(cli::ProgressLine& line)
{
  constexpr auto kRedrawInterval = std::chrono::milliseconds(100);  // ProgressLine's fastest
  auto last = std::chrono::steady_clock::time_point();
  return [&line, last, kRedrawInterval](const xmodem::Progress& p) mutable
  {
    const bool done = p.total > 0 && p.bytes >= p.total;
    const auto now = std::chrono::steady_clock::now();
    if (!done && now - last < kRedrawInterval)
      return;
    last = now;
    line.show(p.bytes, p.total, "block " + std::to_string(p.block) + ", " + std::to_string(p.retries) + " retries",
              done);
  };
}

/// "; data blocks 0.84 s, 1248000 B/s": how fast the blocks went, without the start handshake and
/// the EOT exchange (a receiver waits for silence after EOT), so that rates can be compared.
std::string blockRate(const xmodem::Stats& stats)
{
  const double seconds = std::chrono::duration<double>(stats.block_time).count();
  if (seconds <= 0)
    return "";
  char text[80];
  std::snprintf(text, sizeof(text), "; data blocks %.3f s, %.0f B/s", seconds, stats.bytes / seconds);
  return text;
}

/// A value of the command line the core refuses (a mode or EOB name): a usage error, exit status 2.
template <typename T>
T parsed(const po::variables_map& vm, const std::string& option, T (*parse)(const std::string&))
{
  try
  {
    return parse(vm[option].as<std::string>());
  }
  catch (const ConfigError& e)
  {
    throw UsageError("--" + option + ": " + e.what());
  }
}

/// Options shared by send and receive: mode, EOB, binary, timing.
void addTransferOptions(po::options_description& options, const std::string& default_mode)
{
  options.add_options()("help,h", "this help")("mode,m", po::value<std::string>()->default_value(default_mode),
                                               "checksum (NAK start, what a Haas speaks), crc, or 1k (send only)")(
      "eob", po::value<std::string>()->default_value("lf"),
      "the control's end-of-block pattern, Haas setting 25: lf|cr|crlf|crcr|lflf")(
      "eob-checksum", po::value<std::string>()->default_value("wire"),
      "how the control sums ends of block in a checksum: wire (the bytes sent) or lf (each as LF)")(
      "binary", po::bool_switch(), "move bytes exactly: no EOB conversion, received padding kept")(
      "timeout,t", po::value<double>()->default_value(60.0), "seconds to wait for the other side to start")(
      "retries", po::value<unsigned>()->default_value(10), "errors in a row on one block before giving up")(
      "wait-chars", po::value<unsigned>()->default_value(30),
      "gap inside a packet, and silence before a NAK, in character times of the line (140 at a device server)")(
      "wait-floor", po::value<unsigned>()->default_value(30),
      "milliseconds: the least of those two waits (200 at a device server)")(
      "max-bytes", po::value<uint64_t>()->default_value(xmodem::kDefaultMaxProgramBytes),
      "the longest program moved: a sender that goes past it is cancelled and nothing is stored; a larger "
      "file is not sent (XModem has no length field)");
}

xmodem::Config transferConfig(const po::variables_map& vm)
{
  xmodem::Config config;
  const double timeout = vm["timeout"].as<double>();
  if (timeout <= 0)
    throw UsageError("--timeout must be positive");
  config.start_timeout = config.start_wait = Milliseconds(static_cast<int64_t>(timeout * 1000));
  config.max_retries = config.eot_retries = vm["retries"].as<unsigned>();
  config.wait_characters = vm["wait-chars"].as<unsigned>();
  config.wait_floor = Milliseconds(vm["wait-floor"].as<unsigned>());
  if (parseSerialAddress(vm["port"].as<std::string>()).networked())
  {
    // A device server sends in chunks and the network adds its delays (xmodem/network_waits.h).
    if (vm["wait-chars"].defaulted())
      config.wait_characters = xmodem::kNetworkWaitCharacters;
    if (vm["wait-floor"].defaulted())
      config.wait_floor = xmodem::kNetworkWaitFloor;
  }
  config.max_bytes = vm["max-bytes"].as<uint64_t>();
  if (config.max_bytes == 0)
    throw UsageError("--max-bytes must be at least 1");
  config.max_bytes_name = "--max-bytes";
  config.eob_checksum_name = "--eob-checksum";
  xmodem::fitToLine(config, serialSettings(vm).charactersPerSecond());
  return config;
}

/// Runs \p transfer on the port with Ctrl-C turned into a clean cancel (CANs to the peer).
int withPort(const po::variables_map& vm, const std::function<std::string(Transport&, std::atomic<bool>&)>& transfer)
{
  static std::atomic<bool> cancel{false};
  installStopHandler();
  // A start request the receiver sent before this program opened the port is kept: it is the one
  // the transfer needs (a receiver repeats it only after its NAK interval, 10 s for lrzsz rx).
  const auto port = openSerialLine(serialSettings(vm), InputOnOpen::kKeep);
  onStop(
      [&port]
      {
        cancel = true;
        port->interrupt();
      });
  std::cout << transfer(*port, cancel) << std::endl;
  return 0;
}

int runSend(const std::vector<std::string>& args)
{
  if (cli::namesShare(args))
    return cli::runShareSend(args);
  po::options_description options = cli::serialOptions();
  addTransferOptions(options, "checksum");
  options.add_options()("turnaround", po::value<unsigned>()->default_value(10),
                        "milliseconds of quiet after the start request or a NAK before a block (lrzsz rx "
                        "flushes its input right after it writes them)")(
      "ack-turnaround", po::value<unsigned>()->default_value(0),
      "milliseconds of quiet after each ACK before the next block (rx flushes after ACKs too; 0 is "
      "what sx does)");
  cli::addProtectedOptions(options);
  const po::variables_map vm = parse("send", args, options);
  const xmodem::Mode mode = parsed(vm, "mode", &xmodem::parseMode);
  xmodem::TextOptions text;
  text.binary = vm["binary"].as<bool>();
  text.control_eob = parsed(vm, "eob", &xmodem::parseEob);
  text.eob_checksum = parsed(vm, "eob-checksum", &xmodem::parseEobChecksum);
  xmodem::Config config = transferConfig(vm);
  config.turnaround = Milliseconds(vm["turnaround"].as<unsigned>());
  config.ack_turnaround = Milliseconds(vm["ack-turnaround"].as<unsigned>());
  // EOT: lrzsz rx answers after 1 s of silence, this tool's receiver after 30 ms. An answer lost
  // as the receiver exits (rx flushes its tty then) is not sent again, so waiting longer or asking
  // more often only keeps the user waiting: 2 s, three times at most.
  config.eot_timeout = Milliseconds(2000);
  config.eot_retries = std::min(config.eot_retries, 3u);
  const std::string file = vm["file"].as<std::string>();
  cli::checkProtected(vm, file);  // before the port is opened: the control receives nothing
  // ...and again on the bytes read for sending (the file is opened once): a file saved over since
  // is not sent.
  const xmodem::ContentCheck check = [&vm, &file](const std::string& contents)
  { cli::checkProtectedContents(vm, file, contents); };
  return withPort(vm,
                  [&](Transport& port, std::atomic<bool>& cancel)
                  {
                    cli::ProgressLine progress("send " + file);
                    const xmodem::FileResult result =
                        xmodem::sendFile(port, file, mode, config, text, showOn(progress), &cancel, nullptr, check);
                    progress.finish();
                    return result.message + blockRate(result.stats);
                  });
}

int runReceive(const std::vector<std::string>& args)
{
  if (cli::namesShare(args))
    return cli::runShareReceive(args);
  po::options_description options = cli::serialOptions();
  addTransferOptions(options, "crc");
  options.add_options()("file-eob", po::value<std::string>()->default_value("lf"),
                        "line ends of the stored file: lf|cr|crlf|crcr|lflf")(
      "block-timeout", po::value<double>()->default_value(1.0),
      "seconds without the next packet before a NAK (a lost ACK or NAK costs this long; the "
      "protocol's 10 s suits 300 baud)");
  const po::variables_map vm = parse("receive", args, options);
  const xmodem::Mode mode = parsed(vm, "mode", &xmodem::parseMode);
  if (mode == xmodem::Mode::k1K)
    throw UsageError("receive --mode is checksum or crc (1K blocks are accepted in either)");
  xmodem::TextOptions text;
  text.binary = vm["binary"].as<bool>();
  text.control_eob = parsed(vm, "eob", &xmodem::parseEob);
  text.eob_checksum = parsed(vm, "eob-checksum", &xmodem::parseEobChecksum);
  text.file_eob = parsed(vm, "file-eob", &xmodem::parseEob);
  xmodem::Config config = transferConfig(vm);
  // Waiting for the other side: the start request is repeated every 3 s (more often when the whole
  // wait is short), so that one damaged on the line costs 3 s, not the protocol's 10; 'C' for 30 s
  // (at least three times) before falling back to checksum, as with 10 s and three tries.
  config.nak_interval = std::min(Milliseconds(3000), config.start_timeout / 6);
  config.crc_attempts =
      std::max<unsigned>(3, static_cast<unsigned>(30000 / std::max<int64_t>(1, config.nak_interval.count())));
  const double block_timeout = vm["block-timeout"].as<double>();
  if (block_timeout <= 0)
    throw UsageError("--block-timeout must be positive");
  config.block_timeout = Milliseconds(static_cast<int64_t>(block_timeout * 1000));
  const std::string file = vm["file"].as<std::string>();
  return withPort(vm,
                  [&](Transport& port, std::atomic<bool>& cancel)
                  {
                    cli::ProgressLine progress("receive " + file);
                    const xmodem::FileResult result =
                        xmodem::receiveFile(port, file, mode, config, text, showOn(progress), &cancel);
                    progress.finish();
                    return result.message + blockRate(result.stats);
                  });
}

/// The subcommands. A new transfer kind (drip, backup) is one function and one line here.
struct Command
{
  const char* name;
  const char* summary;
  int (*run)(const std::vector<std::string>& args);
};
const Command kCommands[] = {
    {"send", "send a program by XModem (the control receives)", &runSend},
    {"receive", "receive a program by XModem (the control sends)", &runReceive},
    {"drip", "drip-feed a program while the control runs it (DNC, XON/XOFF)", &cli::runDrip},
    {"backup", "store a program the control punches (from '%' to '%')", &cli::runBackup},
    {"history", "the kept versions of a program in the program archive", &cli::runHistory},
    {"diff", "unified diff of two kept versions of a program, or of one and the current file", &cli::runDiff},
    {"list", "list the programs of a share (--share URL): name, O number, size, time, first comment", &cli::runList},
    {"doctor", "check a port: opens? why not, in words; with --listen S, what the control sends", &cli::runDoctor},
    {"replay", "play the far side of a wire trace on a port, checking that the program there answers as recorded",
     &cli::runReplay},
};

void usage(std::ostream& out)
{
  out << "usage: cnc_dnc COMMAND [options] FILE   (COMMAND --help for its options)\ncommands:\n";
  for (const Command& c : kCommands)
    out << "  " << c.name << "\t" << c.summary << "\n";
}
}  // namespace

int main(int argc, char** argv)
{
  const std::string name = argc > 1 ? argv[1] : "";
  for (const Command& command : kCommands)
  {
    if (name != command.name)
      continue;
    try
    {
      return command.run(std::vector<std::string>(argv + 2, argv + argc));
    }
    catch (const UsageError& e)
    {
      std::cerr << "cnc_dnc " << name << ": " << e.what() << "\n";
      return 2;
    }
    catch (const std::exception& e)
    {
      std::cerr << "cnc_dnc " << name << ": error: " << e.what() << std::endl;
      return 1;
    }
  }
  usage(name == "--help" || name == "-h" ? std::cout : std::cerr);
  return name == "--help" || name == "-h" ? 0 : 2;
}
