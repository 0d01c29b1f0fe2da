// Counters of one bus (see bus_monitor.h).
#include "cnc_bridge/slave_bus/bus_monitor.h"

namespace cnc_bridge
{
namespace slave_bus
{
BusMonitor::BusMonitor(const SlaveTable& table) : table_(table), slaves_(table.slaves().size()) {}

void BusMonitor::stepSent(const StepPayloads& payloads, const std::vector<uint8_t>& missing,
                          const BusSession::Stats& session)
{
  std::lock_guard<std::mutex> lock(mutex_);
  for (size_t i = 0; i < payloads.size(); ++i)
  {
    const int index = table_.indexOf(static_cast<uint8_t>(i + 1));
    if (!payloads[i].empty() && index >= 0)
    {
      ++slaves_[static_cast<size_t>(index)].payloads_sent;
    }
  }
  for (const uint8_t address : missing)
  {
    const int index = table_.indexOf(address);
    ++(index >= 0 ? slaves_[static_cast<size_t>(index)].timeouts : unconfigured_timeouts_);
  }
  session_ = session;
}

void BusMonitor::sessionStats(const BusSession::Stats& session)
{
  std::lock_guard<std::mutex> lock(mutex_);
  session_ = session;
}

void BusMonitor::reply(int index, bool decoded)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (index < 0)
  {
    ++unknown_replies_;
    return;
  }
  SlaveCounters& slave = slaves_[static_cast<size_t>(index)];
  ++slave.replies;
  slave.decode_errors += decoded ? 0 : 1;
}

std::string BusMonitor::masterStatus(const UplinkRecord& record)
{
  const uint8_t code = record.payload.empty() ? 0 : record.payload[0];
  const bool names_slave = record.payload.size() > 1;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++master_reports_[code];
    // Codes 3 and 4 name the slave: count them against it (an unconfigured address stays bus-wide).
    const int index = names_slave ? table_.indexOf(record.payload[1]) : -1;
    if (index >= 0)
    {
      SlaveCounters& slave = slaves_[static_cast<size_t>(index)];
      slave.read_failures += code == static_cast<uint8_t>(MasterStatus::kSlaveNoAnswer) ? 1 : 0;
      slave.too_long += code == static_cast<uint8_t>(MasterStatus::kPayloadTooLong) ? 1 : 0;
    }
  }
  if (code == static_cast<uint8_t>(MasterStatus::kBadFrame))
  {
    return "slave bus master: a step frame arrived corrupted and was dropped";
  }
  return std::string("slave bus master: ") + toString(static_cast<MasterStatus>(code)) +
         (names_slave ? " (address " + std::to_string(record.payload[1]) + ")" : std::string());
}

void BusMonitor::refused()
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++refused_;
}

void BusMonitor::droppedWithLink(size_t steps)
{
  std::lock_guard<std::mutex> lock(mutex_);
  dropped_with_link_ += steps;
}

uint64_t BusMonitor::masterReports(MasterStatus code) const
{
  const auto found = master_reports_.find(static_cast<uint8_t>(code));
  return found == master_reports_.end() ? 0 : found->second;
}

BusMonitor::Report BusMonitor::report()
{
  std::lock_guard<std::mutex> lock(mutex_);
  const auto& s = session_;
  uint64_t timeouts = unconfigured_timeouts_;
  for (const auto& slave : slaves_)
  {
    timeouts += slave.timeouts;
  }
  const uint64_t link_errors = s.link.crc_errors + s.link.framing_errors;
  const uint64_t bad_frames = masterReports(MasterStatus::kBadFrame);
  const uint64_t read_failures = masterReports(MasterStatus::kSlaveNoAnswer);
  const uint64_t too_long = masterReports(MasterStatus::kPayloadTooLong);
  const uint64_t slave_errors = read_failures + too_long;
  Report report;
  report.trouble = timeouts > last_timeouts_ || link_errors > last_link_errors_ || bad_frames > last_bad_frames_ ||
                   slave_errors > last_slave_errors_;
  report.summary = report.trouble ? "slaves timed out, frames were corrupted, or the master reported a slave error"
                                  : "steps flowing";
  last_timeouts_ = timeouts;
  last_link_errors_ = link_errors;
  last_bad_frames_ = bad_frames;
  last_slave_errors_ = slave_errors;
  report.counters = {
      {"frames sent", s.steps_sent},
      {"bytes sent", s.bytes_sent},
      {"bytes received", s.bytes_received},
      {"replies", s.replies},
      {"timeouts", timeouts},
      {"uplink CRC errors", s.link.crc_errors},
      {"uplink framing errors", s.link.framing_errors},
      {"uplink garbage bytes", s.link.garbage_bytes},
      {"uplink resyncs", s.resyncs},
      {"frames the master dropped (bad CRC)", bad_frames},
      {"payloads for absent slaves", masterReports(MasterStatus::kNoSuchSlave)},
      {"slave reads that failed (master status 3)", read_failures},
      {"payloads too long for the master (status 4)", too_long},
      {"replies from unconfigured addresses", unknown_replies_},
      {"refused inputs", refused_},
      {"steps dropped with the link", dropped_with_link_},
  };
  // Per slave, one numeric key each, "<name>: <counter>", so that tools and tests can read them.
  for (size_t i = 0; i < slaves_.size(); ++i)
  {
    const SlaveConfig& config = table_.slaves()[i];
    const SlaveCounters& slave = slaves_[i];
    const std::string prefix = config.name + ": ";
    report.counters.insert(report.counters.end(), {
                                                      {prefix + "address", config.address},
                                                      {prefix + "payloads sent", slave.payloads_sent},
                                                      {prefix + "replies", slave.replies},
                                                      {prefix + "timeouts", slave.timeouts},
                                                      {prefix + "undecodable replies", slave.decode_errors},
                                                      {prefix + "failed reads (status 3)", slave.read_failures},
                                                      {prefix + "payloads too long (status 4)", slave.too_long},
                                                  });
  }
  return report;
}
}  // namespace slave_bus
}  // namespace cnc_bridge
