// BusSession: step frames down, uplink records up (see bus_session.h).
#include "cnc_bridge/slave_bus/bus_session.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace slave_bus
{
namespace
{
size_t checkedBusSize(size_t bus_size)
{
  if (bus_size == 0 || bus_size > kMaxSlaves)
  {
    throw ProtocolError("bus size " + std::to_string(bus_size) + " is out of range 1.." + std::to_string(kMaxSlaves));
  }
  return bus_size;
}
}  // namespace

BusSession::BusSession(Transport& link, Framing framing, size_t bus_size, Milliseconds resync_gap,
                       const WireFormat& format)
    : link_(link),
      framing_(framing),
      format_(format),
      bus_size_(checkedBusSize(bus_size)),
      resync_gap_(resync_gap),
      parser_(framing, static_cast<uint8_t>(bus_size), format),
      read_buffer_(4096),
      last_byte_(Clock::now())
{
}

void BusSession::send(const StepPayloads& payloads)
{
  if (payloads.size() > bus_size_)
  {
    throw ProtocolError("step with payloads for " + std::to_string(payloads.size()) + " slaves on a bus of " +
                        std::to_string(bus_size_));
  }
  scratch_.resize(bus_size_);
  for (size_t i = 0; i < bus_size_; ++i)
  {
    if (i < payloads.size())
    {
      scratch_[i] = payloads[i];
    }
    else
    {
      scratch_[i].clear();
    }
  }
  const auto bytes = encodeStepForLink(scratch_, framing_, format_);
  link_.write(bytes);
  ++stats_.steps_sent;
  stats_.bytes_sent += bytes.size();
}

std::vector<UplinkRecord> BusSession::poll(Milliseconds timeout)
{
  const size_t n = link_.read(read_buffer_.data(), read_buffer_.size(), timeout);
  const auto now = Clock::now();
  if (n == 0)
  {
    if (parser_.pending() > 0 && now - last_byte_ >= resync_gap_)
    {
      const size_t dropped = parser_.pending();
      ++stats_.resyncs;
      CNC_LOG_WARN(link_.describe() << ": " << dropped << " bytes of an uplink record the master did not finish");
      auto records = parser_.resync();
      count(records);
      return records;
    }
    return {};
  }
  last_byte_ = now;
  stats_.bytes_received += n;
  auto records = parser_.feed(read_buffer_.data(), n);
  count(records);
  return records;
}

void BusSession::count(const std::vector<UplinkRecord>& records)
{
  for (const auto& record : records)
  {
    if (record.address == 0)
    {
      ++stats_.master_status;
    }
    else
    {
      ++stats_.replies;
    }
  }
}

BusSession::StepResult BusSession::step(const StepPayloads& payloads, Milliseconds reply_timeout)
{
  std::vector<uint8_t> expected;
  for (size_t i = 0; i < payloads.size(); ++i)
  {
    if (!payloads[i].empty())
    {
      expected.push_back(static_cast<uint8_t>(i + 1));
    }
  }
  send(payloads);
  StepResult result;
  // waiting: still expected this step; the master may tell us to stop waiting for a slave (or for
  // all of them, when it dropped the frame), but such a slave still counts as missing.
  std::vector<uint8_t> waiting = expected;
  const auto deadline = Clock::now() + reply_timeout;
  while (!waiting.empty())
  {
    const auto now = Clock::now();
    if (now >= deadline)
    {
      break;
    }
    const auto left = std::chrono::duration_cast<Milliseconds>(deadline - now) + Milliseconds(1);
    for (auto& record : poll(left))
    {
      if (record.address == 0)
      {
        if (!record.payload.empty() && record.payload[0] == static_cast<uint8_t>(MasterStatus::kBadFrame))
        {
          waiting.clear();
        }
        else if (record.payload.size() >= 2)
        {
          waiting.erase(std::remove(waiting.begin(), waiting.end(), record.payload[1]), waiting.end());
        }
        result.master_status.push_back(std::move(record));
        continue;
      }
      waiting.erase(std::remove(waiting.begin(), waiting.end(), record.address), waiting.end());
      expected.erase(std::remove(expected.begin(), expected.end(), record.address), expected.end());
      result.replies.push_back(std::move(record));
    }
  }
  result.missing = std::move(expected);
  return result;
}

const BusSession::Stats& BusSession::stats() const
{
  stats_.link = parser_.stats();
  return stats_;
}
}  // namespace slave_bus
}  // namespace cnc_bridge
