// The simulated master and slaves (see sim_master.h).
#include "sim/slave_bus/sim_master.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace slave_bus
{
SimRole parseSimRole(const std::string& text)
{
  if (text == "axis" || text == "x" || text == "y" || text == "z")
  {
    return SimRole::kAxis;
  }
  if (text == "tool")
  {
    return SimRole::kTool;
  }
  if (text == "generic")
  {
    return SimRole::kGeneric;
  }
  throw ConfigError("slave role '" + text + "' is not one of axis (x, y, z), tool, generic");
}

SimSlave::SimSlave(uint8_t address, SimRole role, Encoding encoding)
    : address_(address), role_(role), encoding_(encoding)
{
}

void SimSlave::receive(const std::vector<uint8_t>& i2c_frame)
{
  std::vector<uint8_t> payload;
  std::vector<int32_t> values;
  try
  {
    payload = WirePacker::unpack(i2c_frame, wire_);
    if (role_ != SimRole::kGeneric)
    {
      values = decodeValues(payload, encoding_);
      if (values.empty())
      {
        throw ProtocolError("no value");
      }
    }
  }
  catch (const ProtocolError& e)
  {
    ++rejected_;
    CNC_LOG_WARN("slave " << int(address_) << " ignores its payload: " << e.what());
    return;
  }
  switch (role_)
  {
    case SimRole::kAxis:
      position_ = values.front();
      reply_ = encodeValues({position_}, encoding_);
      break;
    case SimRole::kTool:
      tool_on_ = values.front() != 0;
      reply_ = encodeValues({tool_on_ ? 1 : 0}, encoding_);
      break;
    case SimRole::kGeneric:
      // Echo, as the universal-CNC paper's slave sketch does (docs/protocols/slave_bus.md#source), but no more than the
      // master reads (nor than one of the bus's frames carries).
      reply_.assign(payload.begin(), payload.begin() + static_cast<std::ptrdiff_t>(
                                                           std::min({payload.size(), kMaxReply, wire_.max_data})));
      break;
  }
  has_reply_ = true;
}

std::vector<uint8_t> SimSlave::request()
{
  if (!has_reply_)
  {
    return {};
  }
  has_reply_ = false;
  auto frame = WirePacker::pack(reply_, wire_);
  if (noisy_)
  {
    frame[frame.size() - 2] ^= 0x01;  // the CRC byte: the answer no longer checks
  }
  return frame;
}

SimMaster::SimMaster(Transport& link, std::vector<SimSlave> slaves, Options options)
    : link_(link),
      slaves_(std::move(slaves)),
      options_(options),
      receiver_(
          slaves_.size(), [this](const StepReceiver::Delivery& d) { deliver(d); }, [this] { ++stats_.frames; }),
      unpacker_(options.wire)
{
  if (options_.framing == Framing::kFramed && options_.wire.max_data < 1 + kMaxReply)
  {
    throw ConfigError("framed uplink records carry an address and up to " + std::to_string(kMaxReply) +
                      " bytes of answer: frames of " + std::to_string(options_.wire.max_data) +
                      " data bytes are too small (at least " + std::to_string(1 + kMaxReply) + ")");
  }
  for (size_t i = 0; i < slaves_.size(); ++i)
  {
    if (slaves_[i].address() != i + 1)
    {
      throw ConfigError("simulated slaves must have addresses 1..N in order (slave " + std::to_string(i + 1) + " has " +
                        std::to_string(slaves_[i].address()) + ")");
    }
    slaves_[i].setWireFormat(options_.wire);
  }
}

void SimMaster::deliver(const StepReceiver::Delivery& delivery)
{
  if (!delivery.known)
  {
    ++stats_.unknown_slaves;
    sendStatus(MasterStatus::kNoSuchSlave, delivery.address);
    return;
  }
  if (delivery.payload.size() > options_.wire.max_data)
  {
    // A raw step frame's length byte allows 255, one WirePacker frame carries 251 (124 with the
    // library's buffers): the master cannot forward it, so it says so rather than sending a torn
    // I2C write (the library's WirePacker::write() would silently drop the bytes beyond its buffer).
    ++stats_.oversize_payloads;
    sendStatus(MasterStatus::kPayloadTooLong, delivery.address);
    return;
  }
  CNC_LOG_DEBUG("slave " << int(delivery.address) << " <- " << delivery.payload.size() << " bytes");
  // The real bytes of the I2C write, as I2C_send_packed() sends them.
  slaves_[delivery.address - 1].receive(WirePacker::pack(delivery.payload, options_.wire));
  ++stats_.deliveries;
  if (options_.on_delivery)
  {
    options_.on_delivery(delivery.address, delivery.payload);
  }
}

void SimMaster::sendStatus(MasterStatus status, int address)
{
  UplinkRecord record;
  record.address = 0;
  record.payload.push_back(static_cast<uint8_t>(status));
  if (address >= 0)
  {
    record.payload.push_back(static_cast<uint8_t>(address));
  }
  queueUplink(record);
}

void SimMaster::queueUplink(const UplinkRecord& record)
{
  const auto bytes = encodeUplink(record, options_.framing, options_.wire);
  uplink_.insert(uplink_.end(), bytes.begin(), bytes.end());
  ++stats_.uplink_records;
}

void SimMaster::flushUplink()
{
  if (uplink_.empty())
  {
    return;
  }
  ++uplink_writes_;
  if (options_.corrupt_uplink_every > 0 && uplink_writes_ % options_.corrupt_uplink_every == 0)
  {
    uplink_[uplink_.size() / 2] ^= 0x5A;  // a noise burst on the line: one byte changed
  }
  link_.write(uplink_);
  uplink_.clear();
}

void SimMaster::processInput(const uint8_t* data, size_t size)
{
  if (options_.framing == Framing::kRaw)
  {
    receiver_.feed(data, size);
  }
  else
  {
    const auto before = unpacker_.stats();
    const auto frames = unpacker_.feed(data, size);
    processFrames(frames, before);
  }
  flushUplink();
}

void SimMaster::processFrames(const std::vector<std::vector<uint8_t>>& frames, const WireStreamUnpacker::Stats& before)
{
  // A corrupted frame makes the unpacker reject several candidates (its own start byte, then any
  // 0x02 inside it): tell the PC once per burst that its step was lost, so that it need not wait
  // out its reply timeout. Rejected candidates followed by a good frame were line noise before the
  // step, not the step: the step is served, and a status 1 would make the PC give up on it.
  const auto& after = unpacker_.stats();
  if ((after.crc_errors != before.crc_errors || after.framing_errors != before.framing_errors) && frames.empty())
  {
    ++stats_.bad_frames;
    sendStatus(MasterStatus::kBadFrame);
  }
  for (const auto& frame : frames)
  {
    // One WirePacker frame holds exactly one step frame: anything else is malformed.
    receiver_.reset();
    receiver_.feed(frame.data(), frame.size());
    if (frame.empty() || !receiver_.idle())
    {
      receiver_.reset();
      ++stats_.bad_frames;
      sendStatus(MasterStatus::kBadFrame);
    }
  }
}

void SimMaster::pollSlaves()
{
  for (auto& slave : slaves_)
  {
    const auto frame = slave.request();
    if (frame.empty())
    {
      continue;
    }
    UplinkRecord record;
    record.address = slave.address();
    try
    {
      record.payload = WirePacker::unpack(frame, options_.wire);  // WireSlaveRequest checks the slave's CRC
    }
    catch (const ProtocolError&)
    {
      ++stats_.slave_errors;
      sendStatus(MasterStatus::kSlaveNoAnswer, slave.address());
      continue;
    }
    queueUplink(record);
  }
  flushUplink();
}

Milliseconds SimMaster::resyncGap() const
{
  if (options_.framing == Framing::kFramed && options_.resync_gap.count() == 0)
  {
    return kFramedResyncGap;
  }
  return options_.resync_gap;  // raw: 0 = never, as the universal-CNC paper's firmware (it has no timeout)
}

void SimMaster::onSilence()
{
  if (options_.framing == Framing::kRaw)
  {
    if (options_.resync_gap.count() > 0 && receiver_.reset())
    {
      ++stats_.resyncs;
    }
    return;
  }
  if (unpacker_.pending() > 0)
  {
    ++stats_.resyncs;
    const auto before = unpacker_.stats();
    const auto frames = unpacker_.resync();
    processFrames(frames, before);
    flushUplink();
  }
}

void SimMaster::run(StopSignal& stop)
{
  std::vector<uint8_t> buffer(4096);
  auto last_byte = std::chrono::steady_clock::now();
  while (!stop.stopped())
  {
    try
    {
      serveOnce(buffer, last_byte);
    }
    catch (const CancelledError&)
    {
      // The stop handler interrupted a read or a write: the loop condition decides. (A write can
      // see the interrupt after its bytes went out; on stop nothing more is owed to the PC.)
    }
  }
}

void SimMaster::serveOnce(std::vector<uint8_t>& buffer, std::chrono::steady_clock::time_point& last_byte)
{
  const size_t n = link_.read(buffer.data(), buffer.size(), Milliseconds(20));
  const auto now = std::chrono::steady_clock::now();
  if (n > 0)
  {
    last_byte = now;
    processInput(buffer.data(), n);
  }
  else
  {
    const auto gap = resyncGap();
    if (gap.count() > 0 && now - last_byte >= gap)
    {
      onSilence();
    }
  }
  // The universal-CNC paper's master polls its slaves only between frames.
  if (receiver_.idle())
  {
    pollSlaves();
  }
}
}  // namespace slave_bus
}  // namespace cnc_bridge
