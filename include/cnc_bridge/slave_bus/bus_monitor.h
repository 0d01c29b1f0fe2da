// What happened on one bus, for diagnostics: per slave (payloads sent, replies, timeouts,
// undecodable replies, the master's failed reads and refused payloads) and bus-wide (the
// session's counters, master status codes, unknown addresses, refused inputs), and whether any
// trouble counter grew since the last report.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/slave_bus/slave_table.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief Counters of one bus. Thread-safe.
class BusMonitor
{
 public:
  /// \param table must outlive the monitor.
  explicit BusMonitor(const SlaveTable& table);

  /// \brief A step went out: its payloads per slave, the addresses that did not answer in time,
  /// the session's counters after it (taken together, so that one report shows them consistently).
  void stepSent(const StepPayloads& payloads, const std::vector<uint8_t>& missing, const BusSession::Stats& session);
  /// \brief The session's counters while idle.
  void sessionStats(const BusSession::Stats& session);
  /// \brief A slave record arrived: from slave \p index (-1: an unconfigured address), decoded or not.
  void reply(int index, bool decoded);
  /// \brief A master status record (address 0). \returns the line to log about it.
  std::string masterStatus(const UplinkRecord& record);
  /// \brief An input (frame, command, step) was refused; the caller logs why.
  void refused();
  /// \brief \p steps waiting for the link were dropped when it went down; the caller logs it.
  void droppedWithLink(size_t steps);

  struct Report
  {
    bool trouble = false;  ///< timeouts, link errors, dropped frames or slave errors grew since the last report
    std::string summary;
    std::vector<std::pair<std::string, uint64_t>> counters;  ///< bus-wide, then "<slave>: <counter>"
  };
  /// \brief The counters now; the next report compares its trouble counters with these.
  Report report();

 private:
  struct SlaveCounters
  {
    uint64_t payloads_sent = 0;  ///< non-empty payloads in frames that went out
    uint64_t replies = 0;
    uint64_t timeouts = 0;
    uint64_t decode_errors = 0;
    uint64_t read_failures = 0;  ///< master status 3: its I2C read of this slave failed
    uint64_t too_long = 0;       ///< master status 4: the payload did not fit its I2C frame
  };
  uint64_t masterReports(MasterStatus code) const;

  const SlaveTable& table_;
  std::mutex mutex_;
  std::vector<SlaveCounters> slaves_;
  BusSession::Stats session_;
  std::map<uint8_t, uint64_t> master_reports_;
  uint64_t unknown_replies_ = 0;
  uint64_t unconfigured_timeouts_ = 0;
  uint64_t refused_ = 0;
  uint64_t dropped_with_link_ = 0;
  uint64_t last_timeouts_ = 0, last_link_errors_ = 0, last_bad_frames_ = 0, last_slave_errors_ = 0;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
