// sim_slave_bus: a universal-CNC master board with its I2C slaves, on a pty. It runs the receive state machine of the
// universal-CNC paper (docs/protocols/slave_bus.md#source) on the serial link, forwards each payload to its slave as a
// WirePacker frame, and while idle polls the slaves and writes their answers up the link (the uplink format of
// include/cnc_bridge/slave_bus/array_protocol.h). First line: "sim_slave_bus pty <path>".

#include <boost/program_options.hpp>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/transport/serial_port.h"
#include "sim/sim_support.h"
#include "sim/slave_bus/sim_master.h"
#include "testing/paced_transport.h"
#include "testing/pty.h"

namespace
{
using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;

// The slaves of config/slave_bus_example.yaml: three axes, a tool, four generic boards.
const std::vector<std::string> kDefaultSlaves = {"1:axis:be16s",    "2:axis:be16s",    "3:axis:be16s",
                                                 "4:tool:bytes",    "5:generic:bytes", "6:generic:bytes",
                                                 "7:generic:bytes", "8:generic:bytes"};

/// "ADDR:ROLE[:ENCODING]", e.g. "1:axis:be16s".
SimSlave parseSlave(const std::string& text)
{
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string part; std::getline(in, part, ':');)
  {
    parts.push_back(part);
  }
  if (parts.size() < 2 || parts.size() > 3)
  {
    throw ConfigError("--slave '" + text + "' is not ADDR:ROLE[:ENCODING]");
  }
  int address = 0;
  try
  {
    address = std::stoi(parts[0]);
  }
  catch (const std::exception&)
  {
    throw ConfigError("--slave '" + text + "': address is not a number");
  }
  if (address < 1 || address > static_cast<int>(kMaxSlaves))
  {
    throw ConfigError("--slave '" + text + "': address out of range 1..127");
  }
  return SimSlave(static_cast<uint8_t>(address), parseSimRole(parts[1]),
                  parts.size() == 3 ? parseEncoding(parts[2]) : Encoding::kBytes);
}

/// --delivery-log: one line per payload handed to a slave, "ADDRESS HEX" (e.g. "1 04d2"), flushed
/// at once: a test reads the file from another process to see what the machine received. Appended
/// to, so a simulator started again adds to its predecessor's record.
std::function<void(uint8_t, const std::vector<uint8_t>&)> deliveryLogger(const std::string& path)
{
  auto out = std::make_shared<std::ofstream>(path, std::ios::app);
  if (!*out)
  {
    throw ConfigError("--delivery-log: cannot open " + path);
  }
  return [out](uint8_t address, const std::vector<uint8_t>& payload)
  {
    *out << static_cast<int>(address) << ' ';
    for (const uint8_t byte : payload)
    {
      char digits[3];
      std::snprintf(digits, sizeof digits, "%02x", byte);
      *out << digits;
    }
    *out << std::endl;
  };
}
/// The command line (--help lists it).
struct CommandLine
{
  std::string link, framing, wirepacker_crc, delivery_log, pid_file;
  std::vector<std::string> slave_specs;
  std::vector<unsigned> noisy_slaves;
  unsigned baud = 0, resync_gap_ms = 0, corrupt_every = 0, max_payload = 0;
  bool verbose = false;
};

boost::program_options::options_description describeOptions(CommandLine& args)
{
  namespace po = boost::program_options;
  po::options_description options("sim_slave_bus options");
  options.add_options()("help,h", "this help")("link", po::value(&args.link),
                                               "symbolic link to create to the pty device (default: none)")(
      "framing", po::value(&args.framing)->default_value("raw"),
      "raw (the universal-CNC paper's bytes) or framed (WirePacker + CRC-8)")(
      "slave", po::value(&args.slave_specs)->composing(),
      "ADDR:ROLE[:ENCODING], repeatable, addresses 1..N in order; ROLE axis|tool|generic, ENCODING "
      "bytes|hundreds|be16|be16s (default: 3 be16s axes, a tool, 4 generic slaves)")(
      "baud", po::value(&args.baud)->default_value(0),
      "time the uplink as a line of this rate, 8N1: each byte reaches the PC when a UART would have finished "
      "it (0: unpaced)")("resync-gap-ms", po::value(&args.resync_gap_ms)->default_value(0),
                         "silence after which a partial frame from the PC is dropped; raw: 0 = never (as the "
                         "universal-CNC paper's firmware); "
                         "framed: always resynchronises, 0 = 100 ms")(
      "wirepacker-crc", po::value(&args.wirepacker_crc)->default_value("spec"),
      "spec (CRC over length and data, as the packet format documents) or library (data only, as the "
      "ESP32_I2C_Slave library's released code computes it): I2C frames and the framed link")(
      "max-payload", po::value(&args.max_payload)->default_value(0),
      "most data bytes of one WirePacker frame (each slave's payload, a framed step); longer payloads are "
      "reported with status 4 (0: 251 for spec, 124 for library, the library's 128-byte buffers)")(
      "noisy-slave", po::value(&args.noisy_slaves)->composing(),
      "ADDR, repeatable: this slave's I2C answers fail the master's CRC check (status 3)")(
      "corrupt-uplink-every", po::value(&args.corrupt_every)->default_value(0),
      "corrupt one byte of every Nth uplink write (0: never)")(
      "delivery-log", po::value(&args.delivery_log),
      "append every payload handed to a slave to this file as 'ADDRESS HEX', one per line")(
      "pid-file", po::value(&args.pid_file), "write the process id here (a test that stops the simulator reads it)")(
      "verbose,v", "log every frame on stderr");
  return options;
}

/// Reads the command line into \p args. \returns the exit status when there is nothing to serve
/// (--help: 0; a wrong option: 2, with the options listed).
std::optional<int> parseCommandLine(int argc, char** argv, CommandLine& args)
{
  namespace po = boost::program_options;
  const po::options_description options = describeOptions(args);
  po::variables_map vm;
  try
  {
    // Unregistered arguments are allowed: roslaunch appends __name:= and __log:= to every node.
    po::store(po::command_line_parser(argc, argv).options(options).allow_unregistered().run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_slave_bus: " << e.what() << "\n" << options;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << options;
    return 0;
  }
  args.verbose = vm.count("verbose") > 0;
  return std::nullopt;
}

/// The slaves of --slave (or the default bus), with --noisy-slave's marked noisy.
std::vector<SimSlave> makeSlaves(const CommandLine& args)
{
  std::vector<SimSlave> slaves;
  for (const auto& spec : args.slave_specs.empty() ? kDefaultSlaves : args.slave_specs)
  {
    slaves.push_back(parseSlave(spec));
  }
  for (const unsigned address : args.noisy_slaves)
  {
    if (address < 1 || address > slaves.size())
    {
      throw ConfigError("--noisy-slave " + std::to_string(address) + " is not one of the slaves 1.." +
                        std::to_string(slaves.size()));
    }
    slaves[address - 1].setNoisy(true);
  }
  return slaves;
}

SimMaster::Options masterOptions(const CommandLine& args)
{
  SimMaster::Options options;
  options.framing = parseFraming(args.framing);
  options.resync_gap = Milliseconds(args.resync_gap_ms);
  options.corrupt_uplink_every = args.corrupt_every;
  options.wire = WireFormat::of(parseWireCrc(args.wirepacker_crc), args.max_payload);
  if (!args.delivery_log.empty())
  {
    options.on_delivery = deliveryLogger(args.delivery_log);
  }
  return options;
}

void printStats(const SimMaster::Stats& s)
{
  std::cerr << "sim_slave_bus: " << s.frames << " frames, " << s.deliveries << " payloads, " << s.bad_frames
            << " bad frames, " << s.unknown_slaves << " for unknown slaves, " << s.oversize_payloads << " too long, "
            << s.slave_errors << " failed slave reads, " << s.resyncs << " resyncs, " << s.uplink_records
            << " uplink records\n";
}

/// Serves the pty until stopped. \throws ConfigError for a wrong option, LinkError.
void serve(const CommandLine& args)
{
  auto& stop = sim::installStopHandler();
  std::vector<SimSlave> slaves = makeSlaves(args);
  const SimMaster::Options options = masterOptions(args);
  PtyMaster pty(args.link);
  sim::onStop([&pty] { pty.interrupt(); });
  // The uplink reaches the PC when a UART at --baud would have finished each byte, not before.
  std::unique_ptr<PacedTransport> timed;
  Transport* transport = &pty;
  if (args.baud > 0)
  {
    timed = std::make_unique<PacedTransport>(pty, args.baud / static_cast<double>(bitsPerCharacter(8, false, 1)),
                                             PacedTransport::Release::kWhenSent);
    transport = timed.get();
  }
  if (args.verbose)
  {
    setLogHandler([](LogLevel level, const std::string& line)
                  { std::cerr << toString(level) << ": " << line << "\n"; });
  }
  SimMaster master(*transport, std::move(slaves), options);
  if (!args.pid_file.empty())
  {
    sim::writePidFile(args.pid_file);
  }
  sim::announce("sim_slave_bus", "pty " + pty.slavePath());
  master.run(stop);
  printStats(master.stats());
}
}  // namespace

int main(int argc, char** argv)
{
  CommandLine args;
  if (const std::optional<int> status = parseCommandLine(argc, argv, args))
  {
    return *status;
  }
  try
  {
    serve(args);
    return 0;
  }
  catch (const std::exception& e)
  {
    std::cerr << "sim_slave_bus: " << e.what() << std::endl;
    return 1;
  }
}
