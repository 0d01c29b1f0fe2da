// sim_haas_serial punch: a control punching a program out of its memory for backup (Fanuc PUNCH,
// Haas SEND RS-232), at line rate, with leader, DC codes and the EOB and parity of the control.
#include <boost/program_options.hpp>
#include <iostream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/transport/serial_port.h"
#include "dnc_sim.h"
#include "sim/haas_serial/modes.h"
#include "sim/sim_support.h"
#include "testing/paced_transport.h"
#include "testing/pty.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace sim
{
namespace
{
int runPunchMode(const std::vector<std::string>& args)
{
  PunchOptions punch;
  std::string link_path;
  std::string file;
  std::string eob = "crlf";
  unsigned baud = 9600;
  bool no_end_percent = false;
  bool no_dc_codes = false;
  bool at_once = false;
  bool repeat = false;
  po::options_description options("sim_haas_serial punch --file PROGRAM [options]");
  options.add_options()("help,h", "this help")("file", po::value(&file), "the program the control holds")(
      "link", po::value(&link_path), "also reachable as this path (a symbolic link to the pty)")(
      "baud", po::value(&baud)->default_value(baud), "line rate to punch at (0 = as fast as the pty takes it)")(
      "7e1", po::bool_switch(&punch.seven_e1), "7 data bits + even parity: bit 7 set for even parity")(
      "eob", po::value(&eob)->default_value(eob), "end of block: lf, cr, crlf, lfcr, lfcrcr")(
      "leader", po::value(&punch.leader_length)->default_value(punch.leader_length), "NULs before and after")(
      "no-dc-codes", po::bool_switch(&no_dc_codes), "no DC2/DC4 around the program")(
      "no-end-percent", po::bool_switch(&no_end_percent), "leave out the closing '%' (host ends on silence)")(
      "at-once", po::bool_switch(&at_once), "punch at once instead of when the host sends DC1")(
      "repeat", po::bool_switch(&repeat), "punch again each time the host asks");
  po::variables_map vm;
  try
  {
    po::store(po::command_line_parser(args).options(options).run(), vm);
    po::notify(vm);
    punch.eob = dnc::parseEob(eob);
  }
  catch (const std::exception& e)
  {
    std::cerr << e.what() << "\n" << options;
    return 2;
  }
  if (vm.count("help") || file.empty())
  {
    std::cout << options;
    return file.empty() && !vm.count("help") ? 2 : 0;
  }
  punch.end_percent = !no_end_percent;
  punch.dc_codes = !no_dc_codes;
  punch.wait_for_dc1 = !at_once;
  StopSignal& stop = installStopHandler();
  try
  {
    PtyMaster pty(link_path);
    onStop([&pty] { pty.interrupt(); });
    const unsigned bits = bitsPerCharacter(punch.seven_e1 ? 7 : 8, punch.seven_e1, 1);
    PacedTransport paced(pty, baud > 0 ? static_cast<double>(baud) / bits : 1e9);
    Transport& link = baud > 0 ? static_cast<Transport&>(paced) : pty;
    announce("sim_haas_serial", "pty " + pty.slavePath());
    do
    {
      const uint64_t sent = punchProgram(link, file, punch, stop);
      if (sent > 0)
      {
        std::cout << "sim_haas_serial punch: sent " << sent << " characters" << std::endl;
      }
      punch.wait_for_dc1 = true;  // a repeat waits for the host to ask again
    } while (repeat && !stop.stopped());
    return 0;
  }
  catch (const CancelledError&)
  {
    return 0;
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial punch: " << e.what() << std::endl;
    return 1;
  }
}

const SimMode kPunchMode("punch", "program backup: the control punches a program (leader, DC2/DC4, % framing)",
                         &runPunchMode);
}  // namespace
}  // namespace sim
}  // namespace cnc_bridge
