// sim_haas_mdc: a simulated Haas control answering Machine Data Collection queries from a scripted
// machine (mdc::SimMachine). TCP mode behaves like an NGC control with setting 143 set: at most two
// connections, and every reply goes to every connection (a third connection is closed at once).
// Serial mode (--link PATH) is a Classic control's RS-232 port on a pty, one peer, silent during a
// `drop` phase.
//
// usage: sim_haas_mdc [--script FILE] [--port N] [--host ADDR] [--link PATH] [--classic-framing]
// First line: "sim_haas_mdc tcp <host>:<port>" or "sim_haas_mdc pty <path>".
#include <boost/asio.hpp>
#include <boost/program_options.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <list>
#include <memory>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "sim/mdc/sim_machine.h"
#include "sim/sim_support.h"
#include "testing/pty.h"

namespace asio = boost::asio;
using asio::ip::tcp;
using cnc_bridge::mdc::SimMachine;

namespace
{
// The default machine when no script is given: idle, a 2 s cycle with moving axes, a part counted.
const char* kDefaultScript = R"(serial 1234567
model VF2D
software 100.20.000.1200
units inch
work 5 4 -2
phase 1.0 mode=MEM status=IDLE program=O00110 tool=1 parts=4523 x=0 y=0 z=0 spindle=0
phase 2.0 status=BUSY x=8 y=6 z=-3 spindle=8000
phase 1.0 status=IDLE parts+=1 x=0 y=0 z=0 spindle=0
)";

// How a reply is framed on the wire (test/data/mdc/README.md has the sources). NGC (TCP): ">",
// reply, CR LF, and the ">" prompt, as clients in use against NGC controls wait for it. Classic
// serial as the operator's manual describes it: STX, reply, ETB, CR LF, then the ">" prompt.
std::string frame(const std::string& reply, bool classic)
{
  if (classic)
    return "\x02" + reply + "\x17\r\n>";
  return ">" + reply + "\r\n>";
}

class TcpSim
{
 public:
  TcpSim(asio::io_context& io, SimMachine& machine, const std::string& host, uint16_t port, bool classic)
      : io_(io),
        machine_(machine),
        acceptor_(io, tcp::endpoint(asio::ip::make_address(host), port)),
        timer_(io),
        classic_(classic)
  {
    acceptor_.set_option(tcp::acceptor::reuse_address(true));
  }

  uint16_t port() const { return acceptor_.local_endpoint().port(); }
  uint64_t answered() const { return answered_; }

  void start()
  {
    accept();
    tick();
  }

 private:
  struct Client
  {
    explicit Client(asio::io_context& io) : socket(io) {}
    tcp::socket socket;
    asio::streambuf input;
    std::string output;  // queued for writing
    bool writing = false;
  };
  using ClientPtr = std::shared_ptr<Client>;

  void accept()
  {
    auto client = std::make_shared<Client>(io_);
    acceptor_.async_accept(client->socket,
                           [this, client](const boost::system::error_code& error)
                           {
                             if (error)
                               return;
                             if (clients_.size() >= 2)
                             {
                               // The control takes at most two MDC connections.
                               boost::system::error_code ignored;
                               client->socket.close(ignored);
                             }
                             else
                             {
                               client->socket.set_option(tcp::no_delay(true));
                               clients_.push_back(client);
                               read(client);
                             }
                             accept();
                           });
  }

  void read(const ClientPtr& client)
  {
    asio::async_read_until(client->socket, client->input, '\n',
                           [this, client](const boost::system::error_code& error, size_t)
                           {
                             if (error)
                             {
                               drop(client);
                               return;
                             }
                             std::istream in(&client->input);
                             std::string line;
                             std::getline(in, line);
                             const std::string reply = machine_.answer(line, SimMachine::Clock::now());
                             if (!reply.empty())
                             {
                               ++answered_;
                               // Every connection sees every reply.
                               for (auto& c : clients_)
                                 send(c, frame(reply, classic_));
                             }
                             read(client);
                           });
  }

  void send(const ClientPtr& client, const std::string& bytes)
  {
    client->output += bytes;
    if (!client->writing)
      flush(client);
  }

  void flush(const ClientPtr& client)
  {
    if (client->output.empty())
    {
      client->writing = false;
      return;
    }
    client->writing = true;
    auto data = std::make_shared<std::string>(std::move(client->output));
    client->output.clear();
    asio::async_write(client->socket, asio::buffer(*data),
                      [this, client, data](const boost::system::error_code& error, size_t)
                      {
                        if (error)
                        {
                          drop(client);
                          return;
                        }
                        flush(client);
                      });
  }

  void drop(const ClientPtr& client)
  {
    boost::system::error_code ignored;
    client->socket.close(ignored);
    clients_.remove(client);
  }

  // Every 10 ms: a `drop` phase closes every connection (a network outage seen from the host).
  void tick()
  {
    if (machine_.dropDue(SimMachine::Clock::now()) && !clients_.empty())
    {
      std::cerr << "sim_haas_mdc: dropping " << clients_.size() << " connection(s)" << std::endl;
      auto all = clients_;
      for (auto& c : all)
        drop(c);
    }
    timer_.expires_after(std::chrono::milliseconds(10));
    timer_.async_wait(
        [this](const boost::system::error_code& error)
        {
          if (!error)
            tick();
        });
  }

  asio::io_context& io_;
  SimMachine& machine_;
  tcp::acceptor acceptor_;
  asio::steady_timer timer_;
  bool classic_;
  std::list<ClientPtr> clients_;
  uint64_t answered_ = 0;
};

// Serial mode: one peer on a pty; a `drop` phase is a line outage (a control switched off, a cable
// pulled): nothing the host sends is answered until the phase ends.
int runSerial(SimMachine& machine, const std::string& link, bool classic)
{
  auto& stop = cnc_bridge::sim::installStopHandler();
  cnc_bridge::PtyMaster pty(link);
  cnc_bridge::sim::onStop([&] { pty.interrupt(); });
  cnc_bridge::sim::announce("sim_haas_mdc", "pty " + pty.slavePath());
  std::string partial;
  try
  {
    while (!stop.stopped())
    {
      uint8_t buffer[256];
      const size_t n = pty.read(buffer, sizeof buffer, std::chrono::milliseconds(10));
      if (machine.inDropPhase(SimMachine::Clock::now()))
      {
        partial.clear();
        continue;
      }
      partial.append(reinterpret_cast<const char*>(buffer), n);
      size_t end;
      while ((end = partial.find_first_of("\r\n")) != std::string::npos)
      {
        const std::string line = partial.substr(0, end);
        partial.erase(0, end + 1);
        const std::string reply = machine.answer(line, SimMachine::Clock::now());
        if (!reply.empty())
          pty.write(frame(reply, classic));
      }
      if (partial.size() > 4096)
        partial.clear();
    }
  }
  catch (const cnc_bridge::CancelledError&)
  {
  }
  return 0;
}
}  // namespace

int main(int argc, char** argv)
{
  namespace po = boost::program_options;
  po::options_description options("sim_haas_mdc options");
  std::string script, host, link, query_log;
  int port = 0;
  options.add_options()("help,h", "this help")("script", po::value(&script),
                                               "machine script (see src/sim/mdc/sim_machine.h)")(
      "port", po::value(&port)->default_value(0), "TCP port (Haas setting 143); 0 picks a free one")(
      "host", po::value(&host)->default_value("127.0.0.1"), "address to listen on")(
      "link", po::value(&link), "serial mode: a pty, with this symbolic link to its device")(
      "classic-framing",
      "reply as a Classic serial control: STX reply ETB CR LF '>', \"MACRO, n, value\", \"UNKNOWN\"")(
      "query-log", po::value(&query_log), "append every query received to this file, one per line");
  po::variables_map vm;
  try
  {
    // Unregistered arguments are allowed: roslaunch appends __name:= and __log:= to every node.
    po::store(po::command_line_parser(argc, argv).options(options).allow_unregistered().run(), vm);
    po::notify(vm);
    if (port < 0 || port > 65535)
      throw po::error("--port out of range");
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_haas_mdc: " << e.what() << "\n" << options;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << options;
    return 0;
  }
  try
  {
    std::unique_ptr<std::istream> in;
    if (script.empty())
      in = std::make_unique<std::istringstream>(kDefaultScript);
    else
    {
      auto file = std::make_unique<std::ifstream>(script);
      if (!*file)
        throw cnc_bridge::ConfigError("cannot open script " + script);
      in = std::move(file);
    }
    SimMachine machine = SimMachine::fromScript(*in, script.empty() ? "default script" : script);
    machine.start(SimMachine::Clock::now());
    if (!query_log.empty())
    {
      auto log = std::make_shared<std::ofstream>(query_log, std::ios::app);
      if (!*log)
        throw cnc_bridge::ConfigError("cannot open --query-log " + query_log);
      machine.logQueriesTo(log);
    }
    // The timeline's start on the wall clock, so a benchmark can tell when each phase began.
    std::cerr << "sim_haas_mdc: timeline starts at " << std::fixed
              << std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count() << " ("
              << machine.timelineSeconds() << " s per loop)" << std::endl;
    const bool classic = vm.count("classic-framing") > 0;
    machine.setClassic(classic);
    if (!link.empty())
      return runSerial(machine, link, classic);

    auto& stop = cnc_bridge::sim::installStopHandler();
    asio::io_context io;
    TcpSim sim(io, machine, host, static_cast<uint16_t>(port), classic);
    cnc_bridge::sim::onStop([&] { asio::post(io, [&] { io.stop(); }); });
    if (stop.stopped())
      return 0;  // a signal came before the callback was registered
    sim.start();
    cnc_bridge::sim::announce("sim_haas_mdc", "tcp " + host + ":" + std::to_string(sim.port()));
    const auto started = std::chrono::steady_clock::now();
    io.run();
    // For benchmarks: how many queries the clients got answered.
    std::cerr << "sim_haas_mdc: answered " << sim.answered() << " queries in " << std::fixed
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() << " s" << std::endl;
    return 0;
  }
  catch (const std::exception& e)
  {
    std::cerr << "sim_haas_mdc: " << e.what() << std::endl;
    return 1;
  }
}
