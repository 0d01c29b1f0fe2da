// sim_ethernut: a simulated ethernut board on a TCP port, for tests, benchmarks and demos without
// the real ATmega128 board. It serves one client at a time (like the board's single TCP server
// task) and keeps the tool position across connections. Behaviour is in ethernut/board.h.
#include <boost/program_options.hpp>
#include <iostream>
#include <memory>

#include "cnc_bridge/common/log.h"
#include "cnc_bridge/transport/tcp.h"
#include "sim/ethernut/board.h"
#include "sim/ethernut/debug_port.h"
#include "sim/sim_support.h"
#include "testing/pty.h"

namespace po = boost::program_options;
using namespace cnc_bridge;

int main(int argc, char** argv)
{
  StopSignal& stop = sim::installStopHandler();
  ethernut::BoardOptions options;
  std::string address;
  int port = 0;
  long report_ms = 100;
  std::string debug_link;
  po::options_description desc("sim_ethernut: simulated ethernut board (qCNC opcode protocol) on TCP");
  desc.add_options()("help,h", "this help")                                                                           //
      ("address", po::value(&address)->default_value("127.0.0.1"), "address to listen on")                            //
      ("port", po::value(&port)->default_value(6666), "TCP port (0: any free port, printed on the first line)")       //
      ("speed", po::value(&options.speed_mm_per_s)->default_value(500.0), "tool speed, mm/s (0: instant)")            //
      ("report-period-ms", po::value(&report_ms)->default_value(100), "position report period, ms (0: none)")         //
      ("resend-every", po::value(&options.resend_every)->default_value(0), "RESEND every Nth coordinate (0: never)")  //
      ("resend-probability", po::value(&options.resend_probability)->default_value(0.0),
       "RESEND a coordinate with this probability")                                                 //
      ("seed", po::value(&options.seed)->default_value(1), "random seed for --resend-probability")  //
      ("drop-after", po::value(&options.drop_after)->default_value(0),
       "drop the connection when the Nth coordinate arrives (once; 0: never)")  //
      ("silent-after", po::value(&options.silent_after)->default_value(0),
       "stop answering anything, keepalives included, at the Nth coordinate (once; 0: never)")  //
      ("mute-keepalive-after", po::value(&options.mute_keepalive_after)->default_value(0),
       "stop answering alive requests (only those) once N coordinates were accepted (0: never)")         //
      ("log", po::value(&options.log_path), "append every accepted coordinate to this file as 'x y z'")  //
      ("message-log", po::value(&options.message_log_path),
       "append the name of every message received to this file")  //
      ("debug-link", po::value(&debug_link),
       "print the board's debug messages (connections, commands, job events) on a pty, with a symbolic link to it "
       "made here, as the board does on its RS-232 port");
  po::variables_map vm;
  try
  {
    po::store(po::parse_command_line(argc, argv, desc), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_ethernut: " << e.what() << "\n" << desc;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << desc;
    return 0;
  }
  if (port < 0 || port > 65535 || report_ms < 0 || options.resend_probability < 0 || options.resend_probability > 1)
  {
    std::cerr << "sim_ethernut: option out of range\n" << desc;
    return 2;
  }
  options.report_period = Milliseconds(report_ms);
  try
  {
    // The debug port first, so that the board's first words (boot) are on it.
    std::unique_ptr<PtyMaster> debug_pty;
    std::unique_ptr<ethernut::DebugPort> debug_port;
    if (!debug_link.empty())
    {
      debug_pty = std::make_unique<PtyMaster>(debug_link);
      debug_port = std::make_unique<ethernut::DebugPort>(*debug_pty);
      options.debug = [&debug_port](const ethernut::DebugMessage& message) { debug_port->print(message); };
      debug_port->print(ethernut::DebugMessage{0, "ucos", "DEBUG", "boot", 0});
    }
    ethernut::Board board(options);
    TcpServer server(static_cast<uint16_t>(port), address);
    sim::onStop([&] { server.interrupt(); });
    sim::announce("sim_ethernut", "tcp " + address + ":" + std::to_string(server.port()));
    while (!stop.stopped())
    {
      std::unique_ptr<TcpConnection> client;
      try
      {
        client = server.accept(Milliseconds(200));
      }
      catch (const CancelledError&)
      {
        break;
      }
      if (!client)
      {
        continue;
      }
      CNC_LOG_INFO("sim_ethernut: client " << client->describe());
      board.serve(*client, stop);
    }
  }
  catch (const Error& e)
  {
    std::cerr << "sim_ethernut: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
