// dnc_drip_bench: drip-feeds a generated program over a pty to the simulated control (in a thread
// of this process) and prints what the benchmark in bench/dnc/ measures: throughput against the
// line rate, characters sent after each XOFF, and the resident memory of the process.
//   dnc_drip_bench --bytes N [--baud B] [--exec-rate CPS] [--buffer N] [--high N] [--low N]
//                  [--seconds S] [--dir DIR] [--line pty|memory] [--rss-every BYTES]
// --line pty (default): the sender on a SerialPort on a pty, the control's UART taking characters
// at the line rate; memory: both on a SimulatedLine (a wire in memory, free of the pty's kernel
// delivery delays, which under load can hold a DC3 for milliseconds).
// The program is written to DIR (default /tmp) and deleted afterwards. --seconds stops the feed
// (cancel) after S seconds, for programs too large to send whole at the line rate. With --baud 0
// the control takes characters as fast as they come (no UART model): the memory measurement, where
// --rss-every samples the resident memory each time that many more bytes reached the control.
#include <unistd.h>

#include <atomic>
#include <boost/program_options.hpp>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <future>
#include <iostream>
#include <memory>
#include <string>
#include <thread>

#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/transport/serial_port.h"
#include "dnc_sim.h"
#include "testing/pty.h"
#include "testing/simulated_line.h"

namespace po = boost::program_options;
using namespace cnc_bridge;

namespace
{
long statusKb(const char* field)
{
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
  {
    if (line.rfind(field, 0) == 0)
    {
      return std::stol(line.substr(std::string(field).size()));
    }
  }
  return -1;
}

void generate(const std::string& path, uint64_t bytes)
{
  std::FILE* out = std::fopen(path.c_str(), "wb");
  if (out == nullptr)
  {
    throw std::runtime_error("cannot write " + path);
  }
  std::fputs("%\nO0001 (BENCH)\nN1 G21 G90 G54\nN2 T1 M6\nN3 S6000 M3\n", out);
  uint64_t written = 48;
  char line[96];
  for (uint64_t n = 4; written + 16 < bytes; ++n)
  {
    const int len = std::snprintf(line, sizeof(line), "N%llu G1 X%llu.%llu Y%llu.5 F900.\n",
                                  static_cast<unsigned long long>(n), static_cast<unsigned long long>(n % 500),
                                  static_cast<unsigned long long>(n % 10), static_cast<unsigned long long>(n % 300));
    std::fwrite(line, 1, static_cast<size_t>(len), out);
    written += static_cast<uint64_t>(len);
  }
  std::fputs("M30\n%\n", out);
  std::fclose(out);
}
}  // namespace

int main(int argc, char** argv)
{
  uint64_t bytes = 1 << 20;
  unsigned baud = 115200;
  double seconds = 0;
  std::string dir = "/tmp";
  std::string line = "pty";
  int realtime_priority = 0;
  uint64_t rss_every = 0;
  sim::DripControlOptions control;
  control.execution_cps = 0;
  control.realtime = true;  // as a control's UART: see DripControlOptions::realtime
  po::options_description options("dnc_drip_bench");
  options.add_options()("bytes", po::value(&bytes)->default_value(bytes), "program size")(
      "baud", po::value(&baud)->default_value(baud), "host pacing (0 = none)")(
      "exec-rate", po::value(&control.execution_cps)->default_value(0), "control execution, char/s (0 = instant)")(
      "buffer", po::value(&control.buffer_size)->default_value(control.buffer_size), "control buffer")(
      "high", po::value(&control.high_mark)->default_value(control.high_mark), "XOFF mark")(
      "low", po::value(&control.low_mark)->default_value(control.low_mark), "XON mark")(
      "seconds", po::value(&seconds)->default_value(0), "cancel after this long (0 = send it all)")(
      "dir", po::value(&dir)->default_value(dir), "where to generate the program")(
      "line", po::value(&line)->default_value(line), "pty or memory (SimulatedLine)")(
      "realtime", po::value(&realtime_priority)->default_value(0), "sender SCHED_FIFO priority (0 = normal)")(
      "rss-every", po::value(&rss_every)->default_value(0), "sample RSS each time this many bytes arrived (0 = off)");
  po::variables_map vm;
  po::store(po::parse_command_line(argc, argv, options), vm);
  po::notify(vm);

  const std::string path = dir + "/dnc_drip_bench." + std::to_string(::getpid()) + ".nc";
  generate(path, bytes);
  const long rss_before = statusKb("VmRSS:");
  int status = 0;
  try
  {
    // The control's UART takes characters at the line rate: what the sender queues beyond it stays
    // on the host's side and counts against the sender after an XOFF.
    const double line_cps = (baud == 0 ? 115200 : baud) / 10.0;
    std::unique_ptr<PtyMaster> pty;
    std::unique_ptr<SerialPort> port;
    std::unique_ptr<sim::SimulatedLine> wire;
    Transport* control_end = nullptr;
    Transport* host_end = nullptr;
    if (line == "memory")
    {
      // --baud 0: a line as fast as memory (a billion characters a second), the memory measurement.
      wire = std::make_unique<sim::SimulatedLine>(baud == 0 ? 1e9 : line_cps);
      control_end = &wire->control();
      host_end = &wire->host();
    }
    else
    {
      control.line_cps = baud == 0 ? 0 : line_cps;
      pty = std::make_unique<PtyMaster>();
      control_end = pty.get();
    }
    StopSignal stop;
    sim::DripControlStats stats;
    std::atomic<uint64_t> received{0};
    std::thread control_thread(
        [&] {
          stats = sim::runDripControl(*control_end, control, stop, [&](const uint8_t*, size_t n) { received += n; });
        });
    // RSS against bytes delivered: a sample each time another rss_every bytes reached the control.
    std::atomic<bool> sampling{rss_every > 0};
    std::string rss_samples;
    std::thread sampler(
        [&]
        {
          for (uint64_t mark = 0; sampling;)
          {
            const uint64_t now = received;
            if (now >= mark)
            {
              rss_samples +=
                  (rss_samples.empty() ? "" : ",") + std::to_string(now) + ":" + std::to_string(statusKb("VmRSS:"));
              mark += rss_every;
              continue;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
          }
        });
    if (!wire)
    {
      SerialSettings settings;
      settings.device = pty->slavePath();
      settings.baud = baud == 0 ? 115200 : baud;
      port = std::make_unique<SerialPort>(settings);
      host_end = port.get();
    }
    dnc::DripOptions drip;
    drip.pace_cps = baud / 10.0;
    drip.realtime_priority = realtime_priority;
    const auto plan = dnc::planDrip(path, drip);
    const long rss_planned = statusKb("VmRSS:");
    dnc::DripSender sender(*host_end, drip);
    const auto start = std::chrono::steady_clock::now();
    auto done = std::async(std::launch::async, [&] { return sender.send(plan); });
    if (seconds > 0 && done.wait_for(std::chrono::duration<double>(seconds)) == std::future_status::timeout)
    {
      sender.cancel();
    }
    const auto result = done.get();
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!result.completed())
    {
      stop.stop();
    }
    control_thread.join();
    sampling = false;
    sampler.join();
    if (!rss_samples.empty())
      std::printf("rss_samples=%s\n", rss_samples.c_str());
    const double cps = static_cast<double>(result.bytes) / elapsed;
    std::printf(
        "bytes_file=%llu bytes_sent=%llu seconds=%.3f chars_per_s=%.0f line_cps=%.0f line_fraction=%.4f "
        "xoff=%llu max_after_xoff=%llu xoff_over_allowance=%llu overruns=%llu overflow=%llu "
        "sender_xoff=%llu sender_max_queued_at_xoff=%llu rss_start_kb=%ld "
        "rss_after_scan_kb=%ld "
        "rss_end_kb=%ld hwm_kb=%ld outcome=%s\n",
        static_cast<unsigned long long>(bytes), static_cast<unsigned long long>(result.bytes), elapsed, cps,
        drip.pace_cps, drip.pace_cps > 0 ? cps / drip.pace_cps : 0.0,
        static_cast<unsigned long long>(stats.xoff_events), static_cast<unsigned long long>(stats.max_after_xoff),
        static_cast<unsigned long long>(stats.xoff_over_allowance), static_cast<unsigned long long>(stats.overruns),
        static_cast<unsigned long long>(stats.overflow), static_cast<unsigned long long>(result.xoff_events),
        static_cast<unsigned long long>(result.max_queued_at_xoff), rss_before, rss_planned, statusKb("VmRSS:"),
        statusKb("VmHWM:"),
        result.completed() ? "completed"
                           : (result.outcome == dnc::DripResult::Outcome::kCancelled ? "cancelled" : "failed"));
    if (result.outcome == dnc::DripResult::Outcome::kFailed)
    {
      std::fprintf(stderr, "%s\n", result.message.c_str());
      status = 1;
    }
  }
  catch (const std::exception& e)
  {
    std::fprintf(stderr, "dnc_drip_bench: %s\n", e.what());
    status = 1;
  }
  std::remove(path.c_str());
  return status;
}
