// The SHDR adapter's server: an MTConnect agent connects (agents connect to their adapters), is
// sent the full state of every device first, then each change as a timestamped line; its
// `* PING` heartbeat is answered `* PONG <ms>`, which makes the agent expect a PING at that
// period and drop a silent adapter. Several agents may be connected at once. ROS-free.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/shdr.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge::mtconnect
{
struct AdapterSettings
{
  std::string address = "0.0.0.0";    ///< where agents connect
  uint16_t port = 7878;               ///< SHDR's usual port; 0 picks a free one
  Milliseconds heartbeat{10000};      ///< announced in `* PONG`: the agent's PING period
  Milliseconds write_timeout{2000};   ///< an agent that takes none of our lines this long is dropped
  size_t max_queued_bytes = 1 << 20;  ///< lines waiting for one agent at most; beyond, it is dropped
  size_t max_line_bytes = 1024;       ///< longest line an agent may send (it sends only PINGs)
};

struct AdapterStats
{
  uint64_t agents_connected = 0;  ///< connections accepted since start
  uint64_t agents_dropped = 0;    ///< closed by us: no line taken in time, a line too long
  uint64_t pings = 0;
  uint64_t lines = 0;  ///< change lines sent (to each agent)
  size_t agents = 0;   ///< connected now
};

/// \brief The adapter's server: one thread of its own runs every agent's connection (Boost.Asio).
class ShdrAdapter
{
 public:
  /// \brief Listens on settings.address:port (\throws LinkError if it cannot be bound) for agents
  /// that read \p devices.
  ShdrAdapter(AdapterSettings settings, const std::vector<std::string>& devices);
  ~ShdrAdapter();
  ShdrAdapter(const ShdrAdapter&) = delete;
  ShdrAdapter& operator=(const ShdrAdapter&) = delete;

  uint16_t port() const;
  /// \brief A machine's new report: what changed goes to every connected agent, stamped \p when.
  /// \throws ConfigError for a device that is not one of this adapter's. Thread-safe.
  void publish(const std::string& device, const MachineReport& report, std::chrono::system_clock::time_point when);
  AdapterStats stats() const;
  /// \brief Closes the listening socket and every agent's connection, joins the thread.
  void stop();

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};
}  // namespace cnc_bridge::mtconnect
