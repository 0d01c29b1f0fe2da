// sim_haas_serial drip: a control in DNC mode executing a drip-fed program from a finite buffer.
// It sends XOFF above a high mark and XON below a low mark, executes at a set rate, and reports on
// exit how many characters arrived after its XOFFs (the host may send at most 10). With --baud its
// UART takes characters no faster than the line, so what the host queued counts after an XOFF.
#include <boost/program_options.hpp>
#include <fstream>
#include <iostream>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/sim/haas_serial_modes.h"
#include "cnc_bridge/testing/paced_transport.h"
#include "cnc_bridge/testing/pty.h"
#include "cnc_bridge/testing/sim_support.h"
#include "cnc_bridge/transport/serial_port.h"
#include "dnc_sim.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace sim
{
namespace
{
int runDripMode(const std::vector<std::string>& args)
{
  DripControlOptions control;
  std::string link_path;
  std::string output_path;
  std::string stats_path;
  unsigned baud = 0;
  bool repeat = false;
  po::options_description options("sim_haas_serial drip [options]");
  options.add_options()("help,h", "this help")("link", po::value(&link_path),
                                               "also reachable as this path (a symbolic link to the pty)")(
      "baud", po::value(&baud),
      "line rate: the control's UART takes characters no faster, and what it sends is paced to it (0 = no line model)")(
      "7e1", po::bool_switch(&control.seven_e1), "7 data bits + even parity: DC1/DC3 sent as 0x11/0x93")(
      "buffer", po::value(&control.buffer_size)->default_value(control.buffer_size), "receive buffer, characters")(
      "high", po::value(&control.high_mark)->default_value(control.high_mark), "XOFF at this many buffered")(
      "low", po::value(&control.low_mark)->default_value(control.low_mark), "XON at this many buffered")(
      "exec-rate", po::value(&control.execution_cps)->default_value(control.execution_cps),
      "characters executed per second (0 = instantly)")("allowance",
                                                        po::value(&control.allowance)->default_value(control.allowance),
                                                        "characters accepted after XOFF before they count as overruns")(
      "dc1-at-start", po::bool_switch(&control.send_dc1_at_start), "send DC1 (reader start) when ready")(
      "realtime", po::bool_switch(&control.realtime), "receive at real-time priority when permitted")(
      "output", po::value(&output_path), "write every character received (parity masked) to this file")(
      "stats", po::value(&stats_path), "write the exit report to this file (atomically) after each program")(
      "repeat", po::bool_switch(&repeat), "take program after program instead of exiting after the first");
  po::variables_map vm;
  try
  {
    po::store(po::command_line_parser(args).options(options).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << e.what() << "\n" << options;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << options;
    return 0;
  }
  if (control.low_mark >= control.high_mark || control.high_mark > control.buffer_size)
  {
    std::cerr << "need low < high <= buffer\n";
    return 2;
  }
  StopSignal& stop = installStopHandler();
  try
  {
    PtyMaster pty(link_path);
    onStop([&pty] { pty.interrupt(); });
    const unsigned bits = bitsPerCharacter(control.seven_e1 ? 7 : 8, control.seven_e1, 1);
    PacedTransport paced(pty, baud > 0 ? static_cast<double>(baud) / bits : 1e9);
    control.line_cps = baud > 0 ? static_cast<double>(baud) / bits : 0;
    Transport& link = baud > 0 ? static_cast<Transport&>(paced) : pty;
    announce("sim_haas_serial", "pty " + pty.slavePath());
    std::ofstream output;
    if (!output_path.empty())
    {
      output.open(output_path, std::ios::binary | std::ios::trunc);
    }
    bool bad = false;
    UartModel uart(control.line_cps);  // one line across programs: writing the report takes time
    do
    {
      const auto stats = runDripControl(
          link, control, stop,
          [&](const uint8_t* data, size_t size)
          {
            if (output.is_open())
            {
              output.write(reinterpret_cast<const char*>(data), size);
            }
          },
          &uart);
      if (output.is_open())
      {
        output.flush();
      }
      std::cout << "sim_haas_serial drip: " << stats.summary() << std::endl;
      bad = bad || stats.overruns > 0 || stats.overflow_beyond_late > 0;  // its own lateness is not the host's
      if (!stats_path.empty())
      {
        AtomicFileWriter file(stats_path);
        file.write(stats.summary() + "\n");
        file.commit();
      }
    } while (repeat && !stop.stopped());
    return bad ? 3 : 0;
  }
  catch (const CancelledError&)
  {
    return 0;
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial drip: " << e.what() << std::endl;
    return 1;
  }
}

const SimMode kDripMode("drip", "DNC drip-feed receiver: finite buffer, XON/XOFF, execution rate, overrun count",
                        &runDripMode);
}  // namespace
}  // namespace sim
}  // namespace cnc_bridge
