// bench_slave_bus: synchronous steps per second through the PC-side BusSession to a master on a
// serial device (sim_slave_bus on a pty, or a real board), each step one 8-slave frame that waits
// for every slave's answer. With --baud the PC's writes reach the link when a UART of that rate
// would have finished them (PacedTransport, Release::kWhenSent; the simulator times its own the
// same way), and the result is compared with the line-rate bound two ways: the bytes that crossed
// the link over the whole timed run against what the line carries in that time, and the median
// step against the line time of one step's bytes.
#include <algorithm>
#include <boost/program_options.hpp>
#include <chrono>
#include <iomanip>
#include <iostream>
#include <memory>

#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/slave_bus/value_codec.h"
#include "cnc_bridge/transport/serial_port.h"
#include "testing/paced_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;

int main(int argc, char** argv)
{
  namespace po = boost::program_options;
  po::options_description options("bench_slave_bus options");
  std::string port, framing, wirepacker_crc;
  unsigned steps = 2000, baud = 0, slaves = 8;
  options.add_options()("help,h", "this help")("port", po::value(&port)->required(), "serial device of the master")(
      "framing", po::value(&framing)->default_value("raw"), "raw or framed")(
      "steps", po::value(&steps)->default_value(2000), "steps to time")("slaves", po::value(&slaves)->default_value(8),
                                                                        "slaves per frame, each gets a 2-byte value")(
      "baud", po::value(&baud)->default_value(0),
      "time writes as a line of this rate, 8N1 (0: as fast as the link takes)")(
      "wirepacker-crc", po::value(&wirepacker_crc)->default_value("spec"), "spec or library (as the simulator's)");
  po::variables_map vm;
  try
  {
    po::store(po::parse_command_line(argc, argv, options), vm);
    if (vm.count("help"))
    {
      std::cout << options;
      return 0;
    }
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "bench_slave_bus: " << e.what() << "\n" << options;
    return 2;
  }
  try
  {
    SerialSettings settings;
    settings.device = port;
    settings.baud = baud > 0 ? baud : 115200;
    SerialPort serial(settings);
    const double cps = baud / static_cast<double>(bitsPerCharacter(8, false, 1));
    std::unique_ptr<PacedTransport> timed;
    Transport* link = &serial;
    if (baud > 0)
    {
      timed = std::make_unique<PacedTransport>(serial, cps, PacedTransport::Release::kWhenSent);
      link = timed.get();
    }
    BusSession session(*link, parseFraming(framing), slaves, Milliseconds(50),
                       WireFormat::of(parseWireCrc(wirepacker_crc)));
    std::vector<double> latencies;
    latencies.reserve(steps);
    uint64_t missing = 0;
    constexpr unsigned kWarmUp = 20;
    uint64_t sent0 = 0, received0 = 0;
    auto start = std::chrono::steady_clock::now();
    for (unsigned i = 0; i < steps + kWarmUp; ++i)
    {
      if (i == kWarmUp)
      {
        // The first steps warm up; the timed run starts here, its bytes counted from here.
        latencies.clear();
        missing = 0;
        sent0 = session.stats().bytes_sent;
        received0 = session.stats().bytes_received;
        start = std::chrono::steady_clock::now();
      }
      StepPayloads payloads(slaves);
      for (unsigned s = 0; s < slaves; ++s)
      {
        // Axes and generic slaves alike take one be16s value (a tool slave takes 0/1 as two bytes too).
        payloads[s] = encodeValues({static_cast<int32_t>((i * 7 + s) % 2)}, Encoding::kBigEndian16s);
      }
      const auto t0 = std::chrono::steady_clock::now();
      const auto result = session.step(payloads, Milliseconds(2000));
      latencies.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
      missing += result.missing.size();
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::sort(latencies.begin(), latencies.end());
    const auto& stats = session.stats();
    const double bytes_down = static_cast<double>(stats.bytes_sent - sent0);
    const double bytes_up = static_cast<double>(stats.bytes_received - received0);
    const double down = bytes_down / steps;
    const double up = bytes_up / steps;
    const double rate = steps / seconds;  // over the whole timed run, stalls and all
    std::cout << std::fixed << std::setprecision(1);
    std::cout << "framing=" << framing << " slaves=" << slaves << " baud=" << (baud ? std::to_string(baud) : "pty")
              << " steps=" << steps << " missing=" << missing << "\n";
    std::cout << "  bytes per step: " << down << " down, " << up << " up\n";
    const double median = latencies[latencies.size() / 2];
    std::cout << "  steps/s: " << rate << " over " << std::setprecision(2) << seconds
              << " s (at the median latency: " << std::setprecision(1) << 1e6 / median << ")   latency us: median "
              << median << ", p99 " << latencies[latencies.size() * 99 / 100] << "\n";
    if (baud > 0)
    {
      // Each step waits for the answers before the next frame: the line carries down + up bytes
      // one after the other, so the bound is the character rate over both. Run fraction: the bytes
      // that crossed the link in the timed run over what the line carries in that time. Median
      // fraction: one step's line time over the median step. Neither can exceed 1 (a byte is
      // handed over only once the line would have finished it), unless the clock lies.
      const double bound = cps / (down + up);
      const double run_fraction = (bytes_down + bytes_up) / (cps * seconds);
      const double median_fraction = (down + up) / cps / (median / 1e6);
      std::cout << "  line-rate bound: " << bound << " steps/s   run: " << std::setprecision(0) << bytes_down + bytes_up
                << " bytes in " << std::setprecision(2) << seconds << " s = " << std::setprecision(3) << run_fraction
                << " of the line   median step: " << median_fraction << " of the line\n";
    }
    return missing == 0 ? 0 : 1;
  }
  catch (const std::exception& e)
  {
    std::cerr << "bench_slave_bus: " << e.what() << std::endl;
    return 1;
  }
}
