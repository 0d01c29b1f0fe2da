// sim_haas_serial dprnt: a Haas control printing DPRNT output. It runs a macro program file (see
// dprnt_program.h) over a synthetic surface and sends every DPRNT line, Haas-formatted and ended
// with CR, to a pty (the RS-232 port of a Classic control) or to a TCP client (NGC setting 261 =
// TCP: the control listens on the port of setting 263). Fault injection (parity bits, line noise,
// over-long lines, a dropped connection) exercises the reader's robustness.
#include <boost/program_options.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/tcp.h"
#include "dprnt_program.h"
#include "sim/haas_serial/modes.h"
#include "sim/sim_support.h"
#include "testing/pty.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace sim
{
namespace
{
uint8_t withParity(uint8_t c, const std::string& parity)
{
  if (parity == "none")
    return c;
  const bool odd_ones = __builtin_popcount(c & 0x7F) % 2 == 1;
  // Even parity: bit 7 makes the count of ones even; odd parity: odd.
  const bool set = parity == "even" ? odd_ones : !odd_ones;
  return static_cast<uint8_t>((c & 0x7F) | (set ? 0x80 : 0));
}

struct DprntOptions
{
  std::string program_file, link, eol, parity, surface_text, part_corner_text, bind;
  std::vector<std::string> var_args;
  int tcp_port = -1;
  bool tcp = false;
  double rate = 0;
  unsigned repeat = 1, garbage_every = 0, overlong_every = 0, drop_after = 0;
  bool popen = false;
};

/// \returns 0 to go on (or, with \p help set, to exit after the help), else the exit status.
int parseDprntOptions(const std::vector<std::string>& args, DprntOptions& o, bool& help)
{
  po::options_description options("sim_haas_serial dprnt [options]");
  options.add_options()("help,h", "this help")  //
      ("program", po::value(&o.program_file)->required(), "macro program file to run")(
          "link", po::value(&o.link)->default_value(""), "symbolic link to create to the pty (serial port)")(
          "tcp", po::value(&o.tcp_port), "listen on this TCP port instead of a pty (NGC setting 263); 0 = any")(
          "bind", po::value(&o.bind)->default_value("127.0.0.1"), "address to listen on with --tcp")(
          "var", po::value(&o.var_args)->composing(), "N=VALUE: macro variable #N before the run (repeatable)")(
          "surface", po::value(&o.surface_text)->default_value("0,0,0"),
          "Z0,AX,AY[,AMP,PERIOD]: probed height z = Z0 + AX*x + AY*y + AMP*sin(2 pi x/PERIOD)*sin(2 pi y/PERIOD), "
          "program units")("part-corner", po::value(&o.part_corner_text)->default_value(""),
                           "X,Y,YAW: the part's sides for G65 P9811 X/Y probes: its corner at X,Y (work "
                           "coordinates, program units), its X side turned YAW degrees about Z, the part toward "
                           "+X and +Y; empty: no sides")("rate", po::value(&o.rate)->default_value(0),
                                                         "lines per second (0: as fast as the link takes them)")(
          "repeat", po::value(&o.repeat)->default_value(1), "run the program this many times (0: until stopped)")(
          "eol", po::value(&o.eol)->default_value("cr"), "line end: cr (Haas), lf, crlf")(
          "parity", po::value(&o.parity)->default_value("none"), "set bit 7 as none/even/odd parity (7E1 seen as 8N1)")(
          "popen", po::bool_switch(&o.popen), "wrap each run in DC2 + NUL leader ... DC4, as Fanuc POPEN/PCLOS")(
          "garbage-every", po::value(&o.garbage_every)->default_value(0), "line noise inside every Nth line")(
          "overlong-every", po::value(&o.overlong_every)->default_value(0),
          "a 1000-character line before every Nth line")("drop-after", po::value(&o.drop_after)->default_value(0),
                                                         "with --tcp: close the client after N lines, once");
  po::variables_map vm;
  try
  {
    po::store(po::command_line_parser(args).options(options).run(), vm);
    if (vm.count("help"))
    {
      std::cout << options << "\n#3001 reads as wall-clock milliseconds modulo 100000 (for latency checks).\n";
      help = true;
      return 0;
    }
    po::notify(vm);
    o.tcp = vm.count("tcp") > 0;
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_haas_serial dprnt: " << e.what() << "\n" << options;
    return 2;
  }
  return 0;
}

/// The part's sides of --part-corner X,Y,YAW (program units, degrees).
std::function<bool(const double[2], const double[2], double[2])> partSides(const std::string& text)
{
  std::istringstream fields(text);
  std::string item;
  std::vector<double> values;
  while (std::getline(fields, item, ','))
  {
    size_t used = 0;
    double value = 0;
    try
    {
      value = std::stod(item, &used);
    }
    catch (const std::exception&)
    {
      used = 0;
    }
    if (used != item.size() || !std::isfinite(value))
      throw ConfigError("--part-corner " + text + ": '" + item + "' is not a finite number");
    values.push_back(value);
  }
  if (values.size() != 3)
    throw ConfigError("--part-corner " + text + ": expected X,Y,YAW (three numbers)");
  return rectangularPartSides(values[0], values[1], values[2] * M_PI / 180.0);
}

/// The program, the machine's variables and surface, the line end, from the options.
/// \throws ConfigError (std::exception) naming the option at fault.
std::string setUpRun(const DprntOptions& o, MacroProgram& program, MacroMachine& machine)
{
  std::ifstream file(o.program_file);
  if (!file)
    throw ConfigError("cannot read " + o.program_file);
  std::ostringstream text;
  text << file.rdbuf();
  program = MacroProgram::parse(text.str());
  for (const auto& var : o.var_args)
  {
    const size_t eq = var.find('=');
    if (eq == std::string::npos)
      throw ConfigError("--var " + var + ": expected N=VALUE");
    machine.variables[std::stoi(var.substr(var[0] == '#' ? 1 : 0, eq))] = std::stod(var.substr(eq + 1));
  }
  double s[5] = {0, 0, 0, 0, 1};
  std::istringstream surface(o.surface_text);
  std::string item;
  for (int i = 0; i < 5 && std::getline(surface, item, ','); ++i)
    s[i] = std::stod(item);
  if (s[4] == 0)
    throw ConfigError("--surface: PERIOD must not be 0");
  machine.surface = [s](double x, double y)
  { return s[0] + s[1] * x + s[2] * y + s[3] * std::sin(2 * M_PI * x / s[4]) * std::sin(2 * M_PI * y / s[4]); };
  if (!o.part_corner_text.empty())
    machine.side_contact = partSides(o.part_corner_text);
  if (o.parity != "none" && o.parity != "even" && o.parity != "odd")
    throw ConfigError("--parity must be none, even or odd");
  if (o.eol == "cr")
    return "\r";
  if (o.eol == "lf")
    return "\n";
  if (o.eol == "crlf")
    return "\r\n";
  throw ConfigError("--eol must be cr, lf or crlf");
}

/// Where the lines go: the pty, or the current TCP client (waiting for one if none; a client that
/// went away is replaced by the next).
class DprntSink
{
 public:
  DprntSink(const DprntOptions& o, StopSignal& stop) : options_(o), stop_(stop)
  {
    if (o.tcp)
    {
      server_ = std::make_unique<TcpServer>(static_cast<uint16_t>(o.tcp_port), o.bind);
      onStop([this] { server_->interrupt(); });
      announce("sim_haas_serial", "tcp " + o.bind + ":" + std::to_string(server_->port()));
    }
    else
    {
      pty_ = std::make_unique<PtyMaster>(o.link);
      onStop([this] { pty_->interrupt(); });
      announce("sim_haas_serial", "pty " + pty_->slavePath());
    }
    onStop(
        [this]
        {
          std::lock_guard<std::mutex> lock(client_mutex_);
          if (client_)
            client_->interrupt();
        });
  }

  bool send(const std::string& bytes)
  {
    std::vector<uint8_t> out(bytes.begin(), bytes.end());
    for (auto& b : out)
      b = withParity(b, options_.parity);
    for (;;)
    {
      Transport* link_out = current();
      if (!link_out)
        return false;
      try
      {
        link_out->write(out, Milliseconds(5000));
        return true;
      }
      catch (const LinkError& e)
      {
        if (pty_)
          throw;
        std::cerr << "sim_haas_serial dprnt: client gone (" << e.what() << "), waiting for the next\n";
        std::lock_guard<std::mutex> lock(client_mutex_);
        client_.reset();
      }
    }
  }

  /// The machine closes the socket (power cycle, network glitch).
  void dropClient()
  {
    std::lock_guard<std::mutex> lock(client_mutex_);
    client_.reset();
  }
  bool isTcp() const { return server_ != nullptr; }
  void drain()
  {
    if (pty_)
      pty_->drain();
  }

 private:
  Transport* current()
  {
    if (pty_)
      return pty_.get();
    while (!client_ && !stop_.stopped())
    {
      auto accepted = server_->accept(Milliseconds(500));
      std::lock_guard<std::mutex> lock(client_mutex_);
      client_ = std::move(accepted);
    }
    return client_.get();
  }

  const DprntOptions& options_;
  StopSignal& stop_;
  std::unique_ptr<PtyMaster> pty_;
  std::unique_ptr<TcpServer> server_;
  std::mutex client_mutex_;
  std::unique_ptr<Transport> client_;
};

/// Paces the lines (--rate) and refreshes #3001 before each, as the control's millisecond timer.
void paceAndStamp(MacroMachine& machine, double rate, StopSignal& stop)
{
  const auto period = rate > 0 ? std::chrono::duration<double>(1.0 / rate) : std::chrono::duration<double>(0);
  auto next_time = std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  machine.max_blocks = rate > 0 ? 0 : machine.max_blocks;  // a paced program may loop for hours
  machine.before_print = [period, next_time, &stop](MacroMachine& m)
  {
    // Pace first, then read the clock: #3001 is the moment the line is built and written.
    if (period.count() > 0)
    {
      *next_time += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      const auto wait = *next_time - std::chrono::steady_clock::now();
      if (wait.count() > 0)
        stop.waitFor(std::chrono::duration_cast<Milliseconds>(wait));
    }
    // Haas #3001 is a millisecond timer; here it is wall-clock ms modulo 100000 so that a reader on
    // the same host can compute the latency of each line from its text.
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    m.variables[3001] = std::fmod(std::chrono::duration<double, std::milli>(now).count(), 100000.0);
  };
}

/// Runs the program --repeat times, each line with its faults, then keeps the link open.
void printRuns(const DprntOptions& o, const MacroProgram& program, MacroMachine& machine, const std::string& line_end,
               DprntSink& sink, StopSignal& stop)
{
  uint64_t lines = 0;
  bool dropped = false;
  const auto print = [&](const std::string& text)
  {
    if (stop.stopped())
      return false;
    ++lines;
    if (o.overlong_every > 0 && lines % o.overlong_every == 0 && !sink.send(std::string(1000, 'A') + line_end))
      return false;
    std::string out = text;
    if (o.garbage_every > 0 && lines % o.garbage_every == 0)
      out.insert(out.size() / 2, "\x01\x07\x1b\x08\x15");  // noise of a plugged cable
    // Before the line is built, #3001 was refreshed, so this is the moment it leaves.
    if (!sink.send(out + line_end))
      return false;
    if (sink.isTcp() && o.drop_after > 0 && !dropped && lines == o.drop_after)
    {
      dropped = true;
      sink.dropClient();
    }
    return true;
  };
  for (unsigned run = 0; (o.repeat == 0 || run < o.repeat) && !stop.stopped(); ++run)
  {
    // Variables persist from run to run as on the control (#3901 counts parts); the axes start at 0.
    machine.position[0] = machine.position[1] = machine.position[2] = 0;
    machine.incremental = false;
    if (o.popen && !sink.send(std::string("\x12\0\0\0\0", 5)))
      break;
    program.run(machine, print);
    if (o.popen && !sink.send("\x14"))
      break;
  }
  sink.drain();
  // Keep the link open after the last run so the reader sees every byte; stop with a signal.
  while (!stop.stopped())
    stop.waitFor(Milliseconds(1000));
}

int runDprnt(const std::vector<std::string>& args)
{
  DprntOptions options;
  bool help = false;
  if (const int status = parseDprntOptions(args, options, help); status != 0 || help)
    return status;
  MacroMachine machine;
  MacroProgram program;
  std::string line_end;
  try
  {
    line_end = setUpRun(options, program, machine);
  }
  catch (const std::exception& e)
  {
    std::cerr << "sim_haas_serial dprnt: " << e.what() << "\n";
    return 2;
  }
  StopSignal& stop = installStopHandler();
  std::unique_ptr<DprntSink> sink;
  try
  {
    sink = std::make_unique<DprntSink>(options, stop);
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial dprnt: " << e.what() << "\n";
    return 1;
  }
  paceAndStamp(machine, options.rate, stop);
  try
  {
    printRuns(options, program, machine, line_end, *sink, stop);
  }
  catch (const CancelledError&)
  {
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial dprnt: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

const SimMode kDprntMode("dprnt", "Haas control printing DPRNT output of a macro program (pty or --tcp PORT)",
                         &runDprnt);
}  // namespace
}  // namespace sim
}  // namespace cnc_bridge
