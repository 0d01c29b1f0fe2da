// sim_haas_serial classic: a Haas Classic control's one RS-232 port as a cell meets it, carrying
// three things on one pty: the MDC replies to ?Q queries (Setting 143 on; STX reply ETB CR LF '>',
// replies from an .mdcsim script as sim_haas_mdc gives them), the DPRNT lines of a macro program
// running in MEM (bare text ended by CR, as the dprnt mode prints them), and an XModem receive
// (the operator pressing RECV): after --recv-after DPRNT lines the program waits while the control
// NAKs every --nak-interval, takes one program and stores it in --dir, then the program goes on.
// While in RECV the control answers no query and ignores what is not a packet. Each reply and each
// DPRNT line leaves whole, never one inside the other, as from the control's one UART. --repeat
// runs the program again after its end (0: until stopped; the RECV comes once, counted over all runs).
//
//   sim_haas_serial classic --program FILE --script FILE [--link PATH] [--recv-after N] [--dir DIR]
//                           [--start-file PATH] [--resume-file PATH] [--rate N] [--nak-interval S]
//                           [--repeat N]
#include <boost/program_options.hpp>

#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>
#include <utility>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "dprnt_program.h"
#include "sim/haas_serial/modes.h"
#include "sim/mdc/sim_machine.h"
#include "sim/sim_support.h"
#include "testing/pty.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace sim
{
namespace
{
constexpr uint8_t kSoh = 0x01, kEot = 0x04, kAck = 0x06, kNak = 0x15;

struct ClassicOptions
{
  std::string link, program_file, script_file, dir, start_file, resume_file;
  unsigned recv_after = 0;
  unsigned repeat = 1;
  double rate = 0;
  double nak_interval = 1.0;
};

std::string readFile(const std::string& path)
{
  std::ifstream file(path);
  if (!file)
    throw ConfigError("cannot read " + path);
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

/// The port: one writer at a time, so that replies, DPRNT lines and XModem answers never interleave.
class ClassicPort
{
 public:
  explicit ClassicPort(const std::string& link) : pty_(link) {}
  void write(const std::string& bytes)
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    pty_.write(std::vector<uint8_t>(bytes.begin(), bytes.end()), Milliseconds(5000));
  }
  PtyMaster& pty() { return pty_; }

 private:
  PtyMaster pty_;
  std::mutex write_mutex_;
};

/// The operator's CYCLE START: a file appears (nothing to wait on but its presence).
void waitForFile(const std::string& path, StopSignal& stop)
{
  while (!path.empty() && !std::filesystem::exists(path) && !stop.stopped())
    stop.waitFor(Milliseconds(20));
}

/// \returns whether all \p size bytes came within \p timeout.
bool readExact(Transport& link, uint8_t* out, size_t size, Milliseconds timeout)
{
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  size_t got = 0;
  while (got < size && std::chrono::steady_clock::now() < deadline)
    got += link.read(out + got, size - got, Milliseconds(50));
  return got == size;
}

/// The control in RECV (checksum XModem): NAKs until the first packet, ignores what is not a
/// packet (the queries of an MDC poller that does not know the port is taken), ACKs each good
/// packet, NAKs a bad one. \returns the data, SUB padding removed, at the EOT, which the caller
/// ACKs once the program is stored (so that a sender told "done" finds it stored).
std::string receiveProgram(ClassicPort& port, StopSignal& stop, Milliseconds nak_interval)
{
  std::string data;
  uint8_t expected = 1;
  bool started = false;
  auto last_nak = std::chrono::steady_clock::now() - nak_interval;
  while (!stop.stopped())
  {
    if (!started && std::chrono::steady_clock::now() - last_nak >= nak_interval)
    {
      port.write(std::string(1, static_cast<char>(kNak)));
      last_nak = std::chrono::steady_clock::now();
    }
    uint8_t byte = 0;
    if (port.pty().read(&byte, 1, Milliseconds(50)) == 0)
      continue;
    if (byte == kEot && started)
      return data.substr(0, data.find_last_not_of('\x1a') + 1);
    if (byte != kSoh)
      continue;
    uint8_t packet[131];  // block, its complement, 128 data bytes, checksum
    uint8_t sum = 0;
    const bool whole = readExact(port.pty(), packet, sizeof packet, Milliseconds(2000));
    for (size_t i = 2; i < 130; ++i)
      sum = static_cast<uint8_t>(sum + packet[i]);
    if (!whole || static_cast<uint8_t>(packet[0] + packet[1]) != 0xFF || sum != packet[130])
    {
      port.write(std::string(1, static_cast<char>(kNak)));
      continue;
    }
    if (packet[0] == expected)  // else a repeat of the last one: ACK it again
    {
      data.append(reinterpret_cast<const char*>(packet + 2), 128);
      ++expected;
      started = true;
    }
    port.write(std::string(1, static_cast<char>(kAck)));
  }
  throw CancelledError("stopped in RECV");
}

/// Runs the program on the port; after \p options.recv_after lines it asks the reader for one
/// receive and waits for it.
class ClassicControl
{
 public:
  ClassicControl(ClassicPort& port, mdc::SimMachine& mdc, const ClassicOptions& options, StopSignal& stop)
      : port_(port), mdc_(mdc), options_(options), stop_(stop)
  {
  }

  /// The port's reader: answers queries, and runs a receive when the program asked for one.
  void serveQueries()
  {
    std::string partial;
    while (!stop_.stopped())
    {
      if (receiving_)
      {
        partial.clear();
        receiveOne();
        continue;
      }
      uint8_t buffer[256];
      const size_t n = port_.pty().read(buffer, sizeof buffer, Milliseconds(50));
      partial.append(reinterpret_cast<const char*>(buffer), n);
      for (size_t end; (end = partial.find_first_of("\r\n")) != std::string::npos;)
      {
        const std::string reply = mdc_.answer(partial.substr(0, end), mdc::SimMachine::Clock::now());
        partial.erase(0, end + 1);
        if (!reply.empty())
          port_.write("\x02" + reply + "\x17\r\n>");
      }
      if (partial.size() > 4096)
        partial.clear();
    }
  }

  /// The program in MEM, options.repeat times (0: until stopped): every DPRNT line to the port, a
  /// RECV after options.recv_after lines of all runs.
  void runProgram(const MacroProgram& program, MacroMachine& machine)
  {
    const auto period =
        options_.rate > 0 ? std::chrono::duration<double>(1.0 / options_.rate) : std::chrono::duration<double>(0);
    uint64_t lines = 0;
    bool go_on = true;
    bool unread = false;
    const auto print = [&](const std::string& text)
    {
      if (stop_.stopped())
        return go_on = false;
      if (period.count() > 0)
        stop_.waitFor(std::chrono::duration_cast<Milliseconds>(period));
      try
      {
        port_.write(text + "\r");
      }
      catch (const TimeoutError&)
      {
        // Nobody reads the port (no node on it, the pty full): the line goes nowhere, as from a
        // control whose cable nobody listens to, and the program runs on.
        if (!std::exchange(unread, true))
          std::cerr << "sim_haas_serial classic: nobody reads the port; DPRNT lines are lost until a reader comes\n";
      }
      if (++lines == options_.recv_after)
        return go_on = waitForReceive();
      return true;
    };
    for (unsigned run = 0; go_on && (options_.repeat == 0 || run < options_.repeat) && !stop_.stopped(); ++run)
    {
      // Variables persist from run to run as on the control (#3901 counts parts); the axes start at 0.
      machine.position[0] = machine.position[1] = machine.position[2] = 0;
      machine.incremental = false;
      program.run(machine, print);
    }
  }

 private:
  bool waitForReceive()
  {
    std::unique_lock<std::mutex> lock(mutex_);
    receiving_ = true;
    std::cerr << "sim_haas_serial classic: in RECV\n";
    while (receiving_ && !stop_.stopped())
      received_.wait_for(lock, std::chrono::milliseconds(100));  // wakes for stop_ too
    lock.unlock();
    waitForFile(options_.resume_file, stop_);
    return !stop_.stopped();
  }

  void receiveOne()
  {
    const std::string program = receiveProgram(
        port_, stop_, std::chrono::duration_cast<Milliseconds>(std::chrono::duration<double>(options_.nak_interval)));
    const std::string path = options_.dir + "/received_" + std::to_string(++received_count_) + ".nc";
    AtomicFileWriter file(path);
    file.write(program);
    file.commit();
    port_.write(std::string(1, static_cast<char>(kAck)));  // the EOT's
    std::cerr << "sim_haas_serial classic: received " << program.size() << " bytes into " << path << "\n";
    std::lock_guard<std::mutex> lock(mutex_);
    receiving_ = false;
    received_.notify_all();
  }

  ClassicPort& port_;
  mdc::SimMachine& mdc_;
  const ClassicOptions& options_;
  StopSignal& stop_;
  std::mutex mutex_;
  std::condition_variable received_;
  std::atomic<bool> receiving_{false};
  unsigned received_count_ = 0;
};

bool parseOptions(const std::vector<std::string>& args, ClassicOptions& o)
{
  po::options_description options("sim_haas_serial classic [options]");
  options.add_options()("help,h", "this help")  //
      ("program", po::value(&o.program_file)->required(), "macro program printing DPRNT lines")(
          "script", po::value(&o.script_file)->required(), "MDC machine script (.mdcsim) the replies come from")(
          "link", po::value(&o.link)->default_value(""), "symbolic link to create to the pty (serial port)")(
          "recv-after", po::value(&o.recv_after)->default_value(0),
          "after this many DPRNT lines the control goes into RECV for one program (0: never)")(
          "dir", po::value(&o.dir)->default_value("."), "where received programs are stored")(
          "start-file", po::value(&o.start_file)->default_value(""),
          "start the program when this file exists (the operator's CYCLE START); empty: at once")(
          "resume-file", po::value(&o.resume_file)->default_value(""),
          "after the receive, go on when this file exists (CYCLE START again); empty: at once")(
          "rate", po::value(&o.rate)->default_value(0), "DPRNT lines per second (0: as fast as the port takes them)")(
          "repeat", po::value(&o.repeat)->default_value(1), "run the program this many times (0: until stopped)")(
          "nak-interval", po::value(&o.nak_interval)->default_value(1.0), "s between NAKs while in RECV");
  po::variables_map vm;
  po::store(po::command_line_parser(args).options(options).run(), vm);
  if (vm.count("help"))
  {
    std::cout << options;
    return false;
  }
  po::notify(vm);
  return true;
}

int runClassic(const std::vector<std::string>& args)
{
  ClassicOptions options;
  MacroProgram program;
  std::unique_ptr<mdc::SimMachine> mdc;
  try
  {
    if (!parseOptions(args, options))
      return 0;
    program = MacroProgram::parse(readFile(options.program_file));
    std::istringstream script(readFile(options.script_file));
    mdc = std::make_unique<mdc::SimMachine>(mdc::SimMachine::fromScript(script, options.script_file));
    mdc->setClassic(true);
    mdc->start(mdc::SimMachine::Clock::now());
    std::filesystem::create_directories(options.dir);  // the control's memory
  }
  catch (const std::exception& e)
  {
    std::cerr << "sim_haas_serial classic: " << e.what() << "\n";
    return 2;
  }
  StopSignal& stop = installStopHandler();
  try
  {
    ClassicPort port(options.link);
    onStop([&] { port.pty().interrupt(); });
    announce("sim_haas_serial", "pty " + port.pty().slavePath());
    ClassicControl control(port, *mdc, options, stop);
    std::thread reader(
        [&]
        {
          try
          {
            control.serveQueries();
          }
          catch (const CancelledError&)
          {
          }
        });
    try
    {
      waitForFile(options.start_file, stop);
      MacroMachine machine;
      control.runProgram(program, machine);
      std::cerr << "sim_haas_serial classic: program ended\n";
      // The port stays up after the program (MDC is still answered); stop with a signal.
      while (!stop.stopped())
        stop.waitFor(Milliseconds(1000));
    }
    catch (...)
    {
      stop.stop();  // the reader too, before its thread is left
      reader.join();
      throw;
    }
    reader.join();
  }
  catch (const CancelledError&)
  {
  }
  catch (const Error& e)
  {
    std::cerr << "sim_haas_serial classic: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

const SimMode kClassicMode("classic",
                           "Haas Classic's one RS-232 port: MDC replies, DPRNT of a running program and an XModem "
                           "receive on one pty",
                           &runClassic);
}  // namespace
}  // namespace sim
}  // namespace cnc_bridge
