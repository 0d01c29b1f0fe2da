// bench_mdc_poll: how fast the MDC core polls a control. Connects to sim_haas_mdc (or a real
// control) over TCP and runs the same poller haas_mdc_node runs, with every period set to 0 (each
// query as soon as the previous reply arrived), for a given time; prints queries per second and
// reply latency. Run by bench/mdc/run.sh.
//
// With --port-lock the poller holds a port lock for each query, as on a serial line shared with
// dnc_node (the lock's cost per query).
//
// usage: bench_mdc_poll HOST PORT SECONDS [VARIABLES] [--port-lock]
#include <unistd.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>

#include "cnc_bridge/mdc/mdc_monitor.h"
#include "cnc_bridge/transport/tcp.h"

int main(int argc, char** argv)
{
  using namespace cnc_bridge;
  if (argc < 4)
  {
    std::fprintf(stderr, "usage: bench_mdc_poll HOST PORT SECONDS [VARIABLES] [--port-lock]\n");
    return 2;
  }
  const std::string host = argv[1];
  const auto port = static_cast<uint16_t>(std::atoi(argv[2]));
  const double seconds = std::atof(argv[3]);
  const int variables = argc > 4 ? std::atoi(argv[4]) : 6;
  const bool port_lock = argc > 5 && std::string(argv[5]) == "--port-lock";
  try
  {
    auto link = TcpConnection::connect(host, port, Milliseconds(3000));
    mdc::PollPlan plan;
    plan.status_period = plan.variables_period = plan.counters_period = Milliseconds(0);
    const int positions[] = {5021, 5022, 5023, 5041, 5042, 5043, 4006, 3027};
    for (int i = 0; i < variables && i < 8; ++i)
      plan.variables.push_back(positions[i]);
    std::unique_ptr<PortLock> lock;
    if (port_lock)
      lock = std::make_unique<PortLock>("bench_mdc_poll_" + std::to_string(::getpid()));
    mdc::MdcPoller poller(plan, Milliseconds(1000), lock.get());
    StopSignal stop;
    const auto start = std::chrono::steady_clock::now();
    std::thread runner([&] { poller.run(*link, stop); });
    stop.waitFor(Milliseconds(static_cast<long>(seconds * 1000)));
    stop.stop();
    runner.join();
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const auto stats = poller.stats();
    std::printf(
        "queries %llu answered %llu unanswered %llu in %.2f s: %.0f queries/s, latency mean %.3f ms max %.3f ms\n",
        static_cast<unsigned long long>(stats.sent), static_cast<unsigned long long>(stats.answered),
        static_cast<unsigned long long>(stats.unanswered), elapsed, stats.answered / elapsed,
        stats.answered ? stats.total_latency_ms / stats.answered : 0.0, stats.max_latency_ms);
    if (lock)
    {
      ::unlink(lock->lockFile().c_str());
      ::unlink((lock->lockFile() + ".want").c_str());
    }
    return 0;
  }
  catch (const std::exception& e)
  {
    std::fprintf(stderr, "bench_mdc_poll: %s\n", e.what());
    return 1;
  }
}
