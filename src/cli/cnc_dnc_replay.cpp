// cnc_dnc replay: plays the far side of a wire trace on a port (the table in cnc_dnc.cpp lists it).
//
//   cnc_dnc replay --port DEV [--baud B] [--parity P] [--data-bits N] [--stop-bits N]
//                  [--speed X] [--slack S] TRACE
//
// TRACE is a wire trace (a node's ~wire_trace, cnc_dnc's --wire-trace) or a serial sniffer's dump
// of the same layout. The replay sends what the traced side read, at the recorded pace, and checks
// that the program at the other end of DEV (a node, cnc_dnc, a control's stand-in) sends what the
// traced side wrote, byte for byte: a problem recorded in the field becomes a test. Exit status 0
// when everything matched, 1 at the first difference (printed: which entry, which byte), 2 for a
// bad command line or an unreadable trace.
#include <boost/program_options.hpp>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/transport/wire_trace.h"
#include "serial_options.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace cli
{
namespace
{
po::options_description replayOptions()
{
  po::options_description options = serialOptions();  // --port: where the program under test is
  options.add_options()("help,h", "this help")("speed", po::value<double>()->default_value(1.0),
                                               "time scale: 2 plays the trace twice as fast")(
      "slack", po::value<double>()->default_value(15.0),
      "s the program under test may take beyond the recorded time to send what the trace expects");
  return options;
}

std::vector<TraceEntry> readTrace(const std::string& path)
{
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error))
  {
    throw ConfigError("the trace " + path +
                      " is not a file: name a trace file (a node's ~wire_trace folder holds them)");
  }
  std::ifstream in(path);
  if (!in)
  {
    throw ConfigError("cannot read the trace " + path + ": check its permissions");
  }
  auto entries = parseWireTrace(in, path);
  if (entries.empty())
  {
    throw ConfigError("the trace " + path + " has no entries: nothing to replay");
  }
  return entries;
}
}  // namespace

int runReplay(const std::vector<std::string>& args)
{
  const po::options_description options = replayOptions();
  po::options_description all(options);
  all.add_options()("trace", po::value<std::string>()->required(), "the trace to play");
  po::positional_options_description positional;
  positional.add("trace", 1);
  po::variables_map vm;
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    if (vm.count("help") != 0)
    {
      std::cout << "usage: cnc_dnc replay [options] TRACE\n" << options;
      return 0;
    }
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc replay: " << e.what() << "\nusage: cnc_dnc replay [options] TRACE\n" << options;
    return 2;
  }
  std::unique_ptr<TraceReplay> player;
  TraceReplay::Options replay;
  try
  {
    replay.speed = vm["speed"].as<double>();
    const double slack = vm["slack"].as<double>();
    if (!(slack >= 0.0) || slack > 3600.0)
    {
      throw ConfigError("--slack must be from 0 to 3600 s");
    }
    replay.host_slack = Milliseconds(static_cast<long>(slack * 1000.0));
    // Everything checked before the port is opened: the program under test receives nothing.
    player = std::make_unique<TraceReplay>(readTrace(vm["trace"].as<std::string>()), replay);
  }
  catch (const ConfigError& e)
  {
    std::cerr << "cnc_dnc replay: " << e.what() << "\n";
    return 2;
  }
  const auto line = openSerialLine(serialSettingsFrom(vm), InputOnOpen::kKeep);
  const ReplayResult result = player->run(*line, [](const std::string& step) { std::cerr << step << "\n"; });
  std::cout << (result.matched ? "" : "cnc_dnc replay: ") << result.message << std::endl;
  return result.matched ? 0 : 1;
}
}  // namespace cli
}  // namespace cnc_bridge
