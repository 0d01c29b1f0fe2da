// Streaming-rate benchmark of the ethernut client, and its bound: a bare 20-byte request/response
// echo over the same socket type (TcpConnection) between two processes. Run by run.sh:
//   bench_ethernut echo-server              prints "echo tcp 127.0.0.1:<port>", echoes one client
//   bench_ethernut echo-client <port> <n>   n round trips of 20 bytes; prints "n seconds cpu-seconds"
//   bench_ethernut stream <port> <n>        n coordinates to sim_ethernut; prints "n seconds cpu-seconds"
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <iostream>
#include <mutex>
#include <thread>

#include <time.h>

#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/transport/tcp.h"

using namespace cnc_bridge;
using Clock = std::chrono::steady_clock;

// CPU time of this process (all threads), s: unlike wall time it hardly depends on what else the
// machine is doing.
double cpuSeconds()
{
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

namespace
{
int echoServer()
{
  TcpServer server(0, "127.0.0.1");
  std::cout << "echo tcp 127.0.0.1:" << server.port() << std::endl;
  auto peer = server.accept(Milliseconds(30000));
  if (!peer)
  {
    return 1;
  }
  uint8_t buffer[ethernut::kMessageSize];
  size_t have = 0;
  try
  {
    for (;;)
    {
      have += peer->read(buffer + have, sizeof buffer - have, Milliseconds(30000));
      if (have == sizeof buffer)
      {
        peer->write(buffer, sizeof buffer, Milliseconds(5000));
        have = 0;
      }
    }
  }
  catch (const LinkError&)
  {
  }
  return 0;
}

int echoClient(uint16_t port, uint64_t n)
{
  auto link = TcpConnection::connect("127.0.0.1", port, Milliseconds(5000));
  const ethernut::Frame request = ethernut::encode(ethernut::makeMessage(ethernut::Opcode::kCoordinates, 1, 2, 3));
  uint8_t reply[ethernut::kMessageSize];
  const auto start = Clock::now();
  const double cpu_start = cpuSeconds();
  for (uint64_t i = 0; i < n; ++i)
  {
    link->write(request.data(), request.size(), Milliseconds(5000));
    size_t have = 0;
    while (have < sizeof reply)
    {
      have += link->read(reply + have, sizeof reply - have, Milliseconds(5000));
    }
  }
  std::cout << n << ' ' << std::chrono::duration<double>(Clock::now() - start).count() << ' '
            << cpuSeconds() - cpu_start << std::endl;
  return 0;
}

class Done : public ethernut::ClientListener
{
 public:
  void onJobFinished(ethernut::JobOutcome outcome, const std::string& message) override
  {
    std::lock_guard<std::mutex> lock(mutex);
    finished = true;
    ok = outcome == ethernut::JobOutcome::kCompleted;
    text = message;
    cv.notify_all();
  }
  std::mutex mutex;
  std::condition_variable cv;
  bool finished = false;
  bool ok = false;
  std::string text;
};

int stream(uint16_t port, uint64_t n)
{
  auto link = TcpConnection::connect("127.0.0.1", port, Milliseconds(5000));
  Done done;
  ethernut::ClientOptions options;
  options.ack_position_reports = false;
  ethernut::Client client(*link, options, &done);
  std::thread io(
      [&]
      {
        try
        {
          client.run();
        }
        catch (const Error& e)
        {
          std::cerr << e.what() << std::endl;
        }
      });
  while (client.mode() != ethernut::BoardMode::kFile)
  {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));  // handshake; outside the timing
  }
  uint64_t next = 0;
  const auto start = Clock::now();
  const double cpu_start = cpuSeconds();
  client.startJob(
      [&](ethernut::Coordinate& c)
      {
        if (next >= n)
        {
          return false;
        }
        c.x = static_cast<float>(next % 1000) * 0.01f;
        c.y = 1.0f;
        c.z = -1.0f;
        ++next;
        return true;
      });
  std::unique_lock<std::mutex> lock(done.mutex);
  done.cv.wait(lock, [&] { return done.finished; });
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  const double cpu = cpuSeconds() - cpu_start;
  lock.unlock();
  client.stop();
  io.join();
  if (!done.ok)
  {
    std::cerr << "job failed: " << done.text << std::endl;
    return 1;
  }
  std::cout << n << ' ' << seconds << ' ' << cpu << std::endl;
  return 0;
}
}  // namespace

int main(int argc, char** argv)
{
  const std::string mode = argc > 1 ? argv[1] : "";
  try
  {
    if (mode == "echo-server")
    {
      return echoServer();
    }
    if ((mode == "echo-client" || mode == "stream") && argc == 4)
    {
      const auto port = static_cast<uint16_t>(std::stoi(argv[2]));
      const uint64_t n = std::stoull(argv[3]);
      return mode == "stream" ? stream(port, n) : echoClient(port, n);
    }
  }
  catch (const std::exception& e)
  {
    std::cerr << "bench_ethernut: " << e.what() << std::endl;
    return 1;
  }
  std::cerr << "usage: bench_ethernut echo-server | echo-client <port> <n> | stream <port> <n>\n";
  return 2;
}
