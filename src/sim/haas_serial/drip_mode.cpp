// sim_haas_serial drip: a control in DNC mode executing a drip-fed program from a finite buffer.
// It sends XOFF above a high mark and XON below a low mark, executes at a set rate, and reports on
// exit how many characters arrived after its XOFFs (the host may send at most 10). With --baud its
// UART takes characters no faster than the line, so what the host queued counts after an XOFF.
// For tests of a feed that breaks off: a log of the blocks it executes and of its waits for data,
// SIGHUP as the operator's RESET, and a cable pulled once (--drop-link-after).
#include <signal.h>

#include <atomic>
#include <boost/program_options.hpp>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
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
std::atomic<bool> reset_requested{false};

void onResetSignal(int)
{
  reset_requested = true;  // only an atomic store: async-signal-safe
}

/// The control's serial port as a cable that can be pulled: after the \p drop_after th character
/// received (once; 0 = never) the pty is closed, so what the host wrote beyond it is lost and the
/// host's port fails, and a new pty is made at the same link, the cable plugged back in.
class ReplugLink : public Transport
{
 public:
  ReplugLink(std::string link_path, uint64_t drop_after)
      : path_(std::move(link_path)), drop_after_(drop_after), pty_(std::make_unique<PtyMaster>(path_))
  {
  }

  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    const bool armed = drop_after_ > 0 && received_ < drop_after_;
    const size_t n = pty_->read(buffer, armed ? std::min<uint64_t>(size, drop_after_ - received_) : size, timeout);
    received_ += n;
    if (armed && received_ == drop_after_)
    {
      replug();
    }
    return n;
  }
  using Transport::write;
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    pty_->write(data, size, timeout);
  }
  void drain() override { pty_->drain(); }
  void discardInput() override { pty_->discardInput(); }
  void interrupt() override
  {
    std::lock_guard<std::mutex> lock(mutex_);  // from the stop handler's thread
    pty_->interrupt();
  }
  void close() override { pty_->close(); }
  bool isOpen() const override { return pty_->isOpen(); }
  std::string describe() const override { return pty_->describe(); }

 private:
  void replug()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pty_.reset();  // first: it removes the link it made
    pty_ = std::make_unique<PtyMaster>(path_);
    std::cerr << "sim_haas_serial drip: link dropped after " << received_ << " characters; new " << pty_->describe()
              << std::endl;
  }

  std::string path_;
  uint64_t drop_after_;
  uint64_t received_ = 0;
  std::mutex mutex_;
  std::unique_ptr<PtyMaster> pty_;
};

/// Writes the control's execution (DripControlHooks) to \p log, one line each, flushed at once:
/// "block <text>", "waiting for data", "reset".
DripControlHooks executionLog(std::ofstream& log)
{
  DripControlHooks hooks;
  const auto line = [&log](const std::string& text)
  {
    if (log.is_open())
    {
      log << text << std::endl;
    }
  };
  hooks.executed = [line](const std::string& block) { line("block " + block); };
  hooks.waiting_for_data = [line] { line("waiting for data"); };
  hooks.reset = [line]
  {
    const bool reset = reset_requested.exchange(false);
    if (reset)
    {
      line("reset");
    }
    return reset;
  };
  return hooks;
}

/// SIGHUP becomes the operator's RESET (DripControlHooks::reset); the pid goes to \p path if given.
void listenForReset(const std::string& path)
{
  if (!path.empty())
  {
    writePidFile(path);
  }
  struct sigaction action
  {
  };
  action.sa_handler = onResetSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGHUP, &action, nullptr);
}

/// Takes one program as the control would, its characters to \p output, its report printed and to
/// \p stats_path. \returns true when the host overran the control's buffer.
bool takeProgram(Transport& link, const DripControlOptions& control, StopSignal& stop, std::ofstream& output,
                 UartModel& uart, const DripControlHooks& hooks, const std::string& stats_path)
{
  const auto stats = runDripControl(
      link, control, stop,
      [&](const uint8_t* data, size_t size)
      {
        if (output.is_open())
        {
          output.write(reinterpret_cast<const char*>(data), size);
          output.flush();  // read while a feed runs, and after one that broke off
        }
      },
      &uart, hooks);
  std::cout << "sim_haas_serial drip: " << stats.summary() << std::endl;
  if (!stats_path.empty())
  {
    AtomicFileWriter file(stats_path);
    file.write(stats.summary() + "\n");
    file.commit();
  }
  return stats.overruns > 0 || stats.overflow_beyond_late > 0;  // its own lateness is not the host's
}

int runDripMode(const std::vector<std::string>& args)
{
  DripControlOptions control;
  std::string link_path;
  std::string output_path;
  std::string stats_path;
  std::string execution_log_path;
  std::string pid_path;
  uint64_t drop_after = 0;
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
      "repeat", po::bool_switch(&repeat), "take program after program instead of exiting after the first")(
      "execution-log", po::value(&execution_log_path),
      "write each block executed, each wait for data mid-program and each reset to this file, a line each")(
      "pid-file", po::value(&pid_path), "write the process id here (SIGHUP: the operator's RESET)")(
      "drop-link-after", po::value(&drop_after)->default_value(0),
      "close the pty after this many characters received (once) and make a new one at --link (0 = never)");
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
    listenForReset(pid_path);
    ReplugLink pty(link_path, drop_after);
    onStop([&pty] { pty.interrupt(); });
    const unsigned bits = bitsPerCharacter(control.seven_e1 ? 7 : 8, control.seven_e1, 1);
    PacedTransport paced(pty, baud > 0 ? static_cast<double>(baud) / bits : 1e9);
    control.line_cps = baud > 0 ? static_cast<double>(baud) / bits : 0;
    Transport& link = baud > 0 ? static_cast<Transport&>(paced) : pty;
    announce("sim_haas_serial", pty.describe());
    std::ofstream output;
    if (!output_path.empty())
    {
      output.open(output_path, std::ios::binary | std::ios::trunc);
    }
    std::ofstream execution_log;
    if (!execution_log_path.empty())
    {
      execution_log.open(execution_log_path, std::ios::trunc);
    }
    const DripControlHooks hooks = executionLog(execution_log);
    bool bad = false;
    UartModel uart(control.line_cps);  // one line across programs: writing the report takes time
    do
    {
      bad = takeProgram(link, control, stop, output, uart, hooks, stats_path) || bad;
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
