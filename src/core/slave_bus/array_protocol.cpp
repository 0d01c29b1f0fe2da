// Serial array protocol: step encoder, the master's receive state machine and the uplink codec
// (see array_protocol.h for the wire formats and how they read the universal-CNC paper).
#include "cnc_bridge/slave_bus/array_protocol.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace slave_bus
{
Framing parseFraming(const std::string& text)
{
  if (text == "raw")
  {
    return Framing::kRaw;
  }
  if (text == "framed")
  {
    return Framing::kFramed;
  }
  throw ConfigError("framing '" + text + "' is neither raw nor framed");
}

const char* toString(Framing framing)
{
  return framing == Framing::kRaw ? "raw" : "framed";
}

const char* toString(MasterStatus status)
{
  switch (status)
  {
    case MasterStatus::kBadFrame:
      return "bad frame from the PC (dropped)";
    case MasterStatus::kNoSuchSlave:
      return "no such slave";
    case MasterStatus::kSlaveNoAnswer:
      return "I2C read of the slave failed (no acknowledge, or its answer failed the CRC check)";
    case MasterStatus::kPayloadTooLong:
      return "payload longer than one I2C frame of the master carries (not delivered)";
  }
  return "unknown master status";
}

std::vector<uint8_t> encodeStep(const StepPayloads& payloads, size_t max_payload)
{
  max_payload = std::min(max_payload, kMaxPayload);
  if (payloads.empty())
  {
    throw ProtocolError(
        "step frame with no slaves: the universal-CNC paper's master needs a slave count of at least 1");
  }
  if (payloads.size() > kMaxSlaves)
  {
    throw ProtocolError("step frame for " + std::to_string(payloads.size()) + " slaves: at most " +
                        std::to_string(kMaxSlaves) + " (7-bit I2C addresses)");
  }
  size_t size = 1 + payloads.size();
  for (size_t i = 0; i < payloads.size(); ++i)
  {
    if (payloads[i].size() > max_payload)
    {
      throw ProtocolError("payload of " + std::to_string(payloads[i].size()) + " bytes for slave " +
                          std::to_string(i + 1) + ": one I2C frame of the master carries at most " +
                          std::to_string(max_payload));
    }
    size += payloads[i].size();
  }
  std::vector<uint8_t> frame;
  frame.reserve(size);
  frame.push_back(static_cast<uint8_t>(payloads.size()));
  for (const auto& payload : payloads)
  {
    frame.push_back(static_cast<uint8_t>(payload.size()));
    frame.insert(frame.end(), payload.begin(), payload.end());
  }
  return frame;
}

std::vector<uint8_t> encodeStepForLink(const StepPayloads& payloads, Framing framing, const WireFormat& format)
{
  auto frame = encodeStep(payloads, format.max_data);
  if (framing == Framing::kRaw)
  {
    return frame;
  }
  if (frame.size() > format.max_data)
  {
    throw ProtocolError("framed step of " + std::to_string(frame.size()) + " bytes: at most " +
                        std::to_string(format.max_data) + " fit in one WirePacker frame of the master");
  }
  return WirePacker::pack(frame, format);
}

StepReceiver::StepReceiver(size_t bus_size, DeliverFn deliver, FrameDoneFn frame_done)
    : bus_size_(bus_size), deliver_(std::move(deliver)), frame_done_(std::move(frame_done))
{
}

void StepReceiver::feed(const uint8_t* data, size_t size)
{
  for (size_t i = 0; i < size; ++i)
  {
    feed(data[i]);
  }
}

void StepReceiver::feed(uint8_t byte)
{
  switch (state_)
  {
    case State::kSlavesNum:
      if (byte == 0)
      {
        // An empty frame. The universal-CNC paper's code would enter RS_SLAVE_LEN with slave_n = 0 and count down past
        // zero; treating it as complete keeps a stray zero from desynchronising the stream.
        ++frames_;
        if (frame_done_)
        {
          frame_done_();
        }
        return;
      }
      slaves_left_ = byte;
      address_ = 1;
      state_ = State::kSlaveLen;
      return;
    case State::kSlaveLen:
      if (byte == 0)
      {
        slaveDone();  // nothing for this slave this step
        return;
      }
      length_ = byte;
      payload_.clear();
      state_ = State::kSlaveBytes;
      return;
    case State::kSlaveBytes:
      payload_.push_back(byte);
      if (payload_.size() >= length_)
      {
        if (deliver_)
        {
          deliver_(Delivery{static_cast<uint8_t>(address_), payload_, address_ <= bus_size_});
        }
        slaveDone();
      }
      return;
  }
}

void StepReceiver::slaveDone()
{
  ++address_;
  if (--slaves_left_ == 0)
  {
    state_ = State::kSlavesNum;
    ++frames_;
    if (frame_done_)
    {
      frame_done_();
    }
  }
  else
  {
    state_ = State::kSlaveLen;
  }
}

bool StepReceiver::reset()
{
  const bool partial = state_ != State::kSlavesNum;
  state_ = State::kSlavesNum;
  payload_.clear();
  return partial;
}

std::vector<uint8_t> encodeUplink(const UplinkRecord& record, Framing framing, const WireFormat& format)
{
  std::vector<uint8_t> bytes;
  if (framing == Framing::kRaw)
  {
    if (record.payload.size() > 255)
    {
      throw ProtocolError("uplink payload of " + std::to_string(record.payload.size()) + " bytes: at most 255");
    }
    bytes.reserve(record.payload.size() + 2);
    bytes.push_back(record.address);
    bytes.push_back(static_cast<uint8_t>(record.payload.size()));
    bytes.insert(bytes.end(), record.payload.begin(), record.payload.end());
    return bytes;
  }
  bytes.reserve(record.payload.size() + 1);
  bytes.push_back(record.address);
  bytes.insert(bytes.end(), record.payload.begin(), record.payload.end());
  return WirePacker::pack(bytes, format);
}

UplinkParser::UplinkParser(Framing framing, uint8_t max_address, const WireFormat& format)
    : framing_(framing), max_address_(max_address), unpacker_(format)
{
}

std::vector<UplinkRecord> UplinkParser::feed(const uint8_t* data, size_t size)
{
  if (framing_ == Framing::kFramed)
  {
    return toRecords(unpacker_.feed(data, size));
  }
  std::vector<UplinkRecord> records;
  for (size_t i = 0; i < size; ++i)
  {
    const uint8_t byte = data[i];
    if (raw_.empty())
    {
      if (byte > max_address_)
      {
        ++raw_garbage_;  // cannot be an address: skip it
        continue;
      }
      raw_.push_back(byte);
      continue;
    }
    if (raw_.size() == 1 && raw_[0] == 0 && byte == 0)
    {
      // A master status record needs a code: [0, 0] is not a record. Drop the first byte and
      // look at this one as a possible address.
      ++raw_garbage_;
      continue;
    }
    raw_.push_back(byte);
    if (raw_.size() >= 2 && raw_.size() == 2u + raw_[1])
    {
      UplinkRecord record;
      record.address = raw_[0];
      record.payload.assign(raw_.begin() + 2, raw_.end());
      records.push_back(std::move(record));
      ++raw_records_;
      raw_.clear();
    }
  }
  return records;
}

std::vector<UplinkRecord> UplinkParser::toRecords(std::vector<std::vector<uint8_t>> frames)
{
  std::vector<UplinkRecord> records;
  for (auto& frame : frames)
  {
    // A valid frame that is no record (no address, an impossible address, or a master status
    // without its code): count it, deliver nothing.
    if (frame.empty() || frame[0] > max_address_ || (frame[0] == 0 && frame.size() == 1))
    {
      ++framed_empty_;
      continue;
    }
    UplinkRecord record;
    record.address = frame[0];
    record.payload.assign(frame.begin() + 1, frame.end());
    records.push_back(std::move(record));
  }
  return records;
}

std::vector<UplinkRecord> UplinkParser::resync()
{
  if (framing_ == Framing::kFramed)
  {
    return toRecords(unpacker_.resync());
  }
  raw_garbage_ += raw_.size();
  raw_.clear();
  return {};
}

size_t UplinkParser::pending() const
{
  return framing_ == Framing::kFramed ? unpacker_.pending() : raw_.size();
}

UplinkParser::Stats UplinkParser::stats() const
{
  Stats stats;
  if (framing_ == Framing::kFramed)
  {
    const auto& s = unpacker_.stats();
    stats.records = s.frames - framed_empty_;
    stats.crc_errors = s.crc_errors;
    stats.framing_errors = s.framing_errors + framed_empty_;
    stats.garbage_bytes = s.garbage_bytes;
  }
  else
  {
    stats.records = raw_records_;
    stats.garbage_bytes = raw_garbage_;
  }
  return stats;
}
}  // namespace slave_bus
}  // namespace cnc_bridge
