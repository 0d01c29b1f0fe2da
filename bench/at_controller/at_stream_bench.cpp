// at_stream_bench: streams a long planned path to a controller (sim_at_controller) through the
// same SetpointSender the node uses, then prints the timing of the 1 ms stream: setpoints sent,
// underruns (a setpoint later than one period), interval between setpoints (p50/p99/max) and the
// lateness behind schedule. ROS-free, so the numbers are the sender's, not the ROS layer's.
#include <boost/program_options.hpp>
#include <cmath>
#include <iostream>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/transport/tcp.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

int main(int argc, char** argv)
{
  namespace po = boost::program_options;
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  double seconds = 60.0;
  int priority = 0;
  po::options_description description("at_stream_bench options");
  description.add_options()("help,h", "this help")("host", po::value(&host)->default_value(host), "controller")(
      "command-port", po::value(&port)->required(), "the controller's command port")(
      "seconds", po::value(&seconds)->default_value(seconds), "length of the stream (s)")(
      "realtime-priority", po::value(&priority)->default_value(0), "SCHED_FIFO priority of the sender (0: none)");
  try
  {
    po::variables_map vm;
    po::store(po::parse_command_line(argc, argv, description), vm);
    if (vm.count("help"))
    {
      std::cout << description;
      return 0;
    }
    po::notify(vm);

    // A zigzag of 40 mm legs in X, stepping 1 mm in Y, at 20 mm/s: about 2.05 s per leg.
    PlannerLimits limits;
    std::vector<Vec3> points{{0, 0, 0}};
    const int legs = static_cast<int>(std::ceil(seconds / 2.05));
    for (int leg = 0; leg < legs; ++leg)
    {
      const double x = (leg % 2 == 0) ? 40000.0 : 0.0;
      points.push_back({x, leg * 1000.0, 0});
      points.push_back({x, (leg + 1) * 1000.0, 0});
    }
    auto trajectory = std::make_shared<Trajectory>(points, 20.0, limits);

    SetpointSender::Options options;
    options.realtime_priority = priority;
    SetpointSender sender(options);
    sender.setLink(std::shared_ptr<Transport>(TcpConnection::connect(host, port, Milliseconds(2000))));
    Operation operation;
    operation.trajectory = trajectory;
    auto job = sender.start(operation);
    while (!job->waitFor(Milliseconds(1000)))
    {
    }
    const auto stats = sender.stats();
    std::cout << "state=" << Job::toString(job->state()) << " seconds=" << trajectory->duration()
              << " setpoints=" << stats.setpoints << " underruns=" << stats.underruns << " stalls=" << stats.stalls
              << " interval_p50_ms=" << stats.interval_p50 * 1e3 << " interval_p99_ms=" << stats.interval_p99 * 1e3
              << " interval_max_ms=" << stats.interval_max * 1e3 << " interval_min_ms=" << stats.interval_min * 1e3
              << " late_mean_ms=" << stats.mean_lateness * 1e3 << " late_max_ms=" << stats.max_lateness * 1e3
              << std::endl;
    return job->state() == Job::State::kSucceeded ? 0 : 1;
  }
  catch (const std::exception& e)
  {
    std::cerr << "at_stream_bench: " << e.what() << std::endl;
    return 2;
  }
}
