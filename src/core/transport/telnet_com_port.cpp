// Telnet framing and COM-PORT-OPTION values (RFC 854, 855, 2217).
#include "cnc_bridge/transport/telnet_com_port.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace rfc2217
{
namespace
{
// SET-PARITY and SET-STOPSIZE values.
constexpr uint8_t kParityNone = 1;
constexpr uint8_t kParityOdd = 2;
constexpr uint8_t kParityEven = 3;
constexpr uint8_t kStopOne = 1;
constexpr uint8_t kStopTwo = 2;

uint8_t parityValue(Parity parity)
{
  switch (parity)
  {
    case Parity::kOdd:
      return kParityOdd;
    case Parity::kEven:
      return kParityEven;
    case Parity::kNone:
      break;
  }
  return kParityNone;
}

uint8_t controlValue(FlowControl flow)
{
  switch (flow)
  {
    case FlowControl::kXonXoff:
      return kControlXonXoff;
    case FlowControl::kRtsCts:
      return kControlHardware;
    case FlowControl::kNone:
      break;
  }
  return kControlNoFlow;
}

std::string parityText(uint8_t value)
{
  static const char* const kNames[] = {"(ask)", "none", "odd", "even", "mark", "space"};
  return value < 6 ? kNames[value] : "value " + std::to_string(value);
}

std::string controlText(uint8_t value)
{
  switch (value)
  {
    case kControlNoFlow:
      return "none";
    case kControlXonXoff:
      return "xon/xoff";
    case kControlHardware:
      return "rts/cts";
    default:
      return "value " + std::to_string(value);
  }
}
}  // namespace

std::vector<Setting> lineSettings(const SerialSettings& settings)
{
  const uint32_t baud = settings.baud;
  return {
      {Command::kSetBaudRate,
       {static_cast<uint8_t>(baud >> 24), static_cast<uint8_t>(baud >> 16), static_cast<uint8_t>(baud >> 8),
        static_cast<uint8_t>(baud)}},
      {Command::kSetDataSize, {static_cast<uint8_t>(settings.data_bits)}},
      {Command::kSetParity, {parityValue(settings.parity)}},
      {Command::kSetStopSize, {settings.stop_bits == 2 ? kStopTwo : kStopOne}},
      flowControlSetting(settings.flow_control),
  };
}

Setting flowControlSetting(FlowControl flow)
{
  return {Command::kSetControl, {controlValue(flow)}};
}

const char* settingName(Command command)
{
  switch (command)
  {
    case Command::kSetBaudRate:
      return "baud rate";
    case Command::kSetDataSize:
      return "data bits";
    case Command::kSetParity:
      return "parity";
    case Command::kSetStopSize:
      return "stop bits";
    case Command::kSetControl:
      return "flow control";
    case Command::kPurgeData:
      return "purge";
    default:
      return "COM-PORT-OPTION command";
  }
}

std::string describeValue(Command command, const std::vector<uint8_t>& value)
{
  if (command == Command::kSetBaudRate && value.size() == 4)
  {
    const uint32_t baud =
        (uint32_t{value[0]} << 24) | (uint32_t{value[1]} << 16) | (uint32_t{value[2]} << 8) | value[3];
    return std::to_string(baud);
  }
  if (value.size() != 1)
  {
    return "(" + std::to_string(value.size()) + " bytes)";
  }
  switch (command)
  {
    case Command::kSetParity:
      return parityText(value[0]);
    case Command::kSetStopSize:
      return value[0] == 3 ? "1.5" : std::to_string(value[0]);
    case Command::kSetControl:
      return controlText(value[0]);
    default:
      return std::to_string(value[0]);
  }
}

void Decoder::feed(const uint8_t* bytes, size_t size, std::vector<uint8_t>& data, std::vector<Event>& events)
{
  for (size_t i = 0; i < size; ++i)
  {
    const uint8_t byte = bytes[i];
    switch (state_)
    {
      case State::kData:
        if (byte == kIac)
          state_ = State::kCommand;
        else
          data.push_back(byte);
        break;
      case State::kCommand:
        state_ = State::kData;
        if (byte == kIac)
        {
          data.push_back(kIac);  // an escaped data byte 0xFF
        }
        else if (byte >= kWill && byte <= kDont)
        {
          verb_ = byte;
          state_ = State::kOption;
        }
        else if (byte == kSb)
        {
          sub_.clear();
          state_ = State::kSubnegotiation;
        }
        else
        {
          events.push_back(Event{});  // NOP, AYT, GA, ...: nothing to do
        }
        break;
      case State::kOption:
      {
        Event event;
        event.kind = verb_ == kWill   ? Event::Kind::kWill
                     : verb_ == kWont ? Event::Kind::kWont
                     : verb_ == kDo   ? Event::Kind::kDo
                                      : Event::Kind::kDont;
        event.option = byte;
        events.push_back(event);
        state_ = State::kData;
        break;
      }
      case State::kSubnegotiation:
        if (byte == kIac)
          state_ = State::kSubnegotiationCommand;
        else
          sub_.push_back(byte);
        break;
      case State::kSubnegotiationCommand:
        if (byte == kIac)
        {
          sub_.push_back(kIac);
          state_ = State::kSubnegotiation;
        }
        else
        {
          // IAC SE ends it; any other command inside a subnegotiation ends it too (RFC 855 says
          // nothing else may appear there, and waiting for an SE that never comes would swallow data).
          endSubnegotiation(events);
          state_ = State::kData;
        }
        break;
    }
  }
}

void Decoder::endSubnegotiation(std::vector<Event>& events)
{
  Event event;
  if (sub_.size() >= 2 && sub_[0] == kOptionComPort)
  {
    event.kind = Event::Kind::kComPort;
    event.command = sub_[1];
    event.value.assign(sub_.begin() + 2, sub_.end());
  }
  events.push_back(std::move(event));
  sub_.clear();
}

bool Options::wantLocal(uint8_t option)
{
  return option == kOptionBinary || option == kOptionSuppressGoAhead || option == kOptionComPort;
}

bool Options::wantRemote(uint8_t option)
{
  return option == kOptionBinary || option == kOptionSuppressGoAhead || option == kOptionEcho;
}

std::vector<uint8_t> Options::start()
{
  std::vector<uint8_t> out;
  for (const uint8_t option : {kOptionComPort, kOptionBinary, kOptionSuppressGoAhead})
  {
    local_[option] = State::kWantYes;
    out.insert(out.end(), {kIac, kWill, option});
  }
  for (const uint8_t option : {kOptionBinary, kOptionSuppressGoAhead})
  {
    remote_[option] = State::kWantYes;
    out.insert(out.end(), {kIac, kDo, option});
  }
  return out;
}

std::vector<uint8_t> Options::reply(const Event& event)
{
  const uint8_t option = event.option;
  if (option == kOptionBinary && (event.kind == Event::Kind::kDont || event.kind == Event::Kind::kWont))
    refused_binary_ = true;
  switch (event.kind)
  {
    case Event::Kind::kDo:
      if (!wantLocal(option))
        return {kIac, kWont, option};  // refused; we never said WILL, so no loop
      if (local_[option] == State::kYes)
        return {};
      {
        const bool asked = local_[option] == State::kWantYes;
        local_[option] = State::kYes;
        return asked ? std::vector<uint8_t>{} : std::vector<uint8_t>{kIac, kWill, option};
      }
    case Event::Kind::kDont:
      if (option == kOptionComPort && local_[option] != State::kNo)
        refused_com_port_ = true;
      if (local_[option] == State::kNo)
        return {};
      {
        const bool agreed = local_[option] == State::kYes;
        local_[option] = State::kNo;
        return agreed ? std::vector<uint8_t>{kIac, kWont, option} : std::vector<uint8_t>{};
      }
    case Event::Kind::kWill:
      if (!wantRemote(option))
        return {kIac, kDont, option};
      if (remote_[option] == State::kYes)
        return {};
      {
        const bool asked = remote_[option] == State::kWantYes;
        remote_[option] = State::kYes;
        return asked ? std::vector<uint8_t>{} : std::vector<uint8_t>{kIac, kDo, option};
      }
    case Event::Kind::kWont:
      if (remote_[option] == State::kNo)
        return {};
      {
        const bool agreed = remote_[option] == State::kYes;
        remote_[option] = State::kNo;
        return agreed ? std::vector<uint8_t>{kIac, kDont, option} : std::vector<uint8_t>{};
      }
    default:
      return {};
  }
}

void appendEscaped(const uint8_t* data, size_t size, std::vector<uint8_t>& out)
{
  out.reserve(out.size() + size + size / 64);
  for (size_t i = 0; i < size; ++i)
  {
    out.push_back(data[i]);
    if (data[i] == kIac)
      out.push_back(kIac);
  }
}

std::vector<uint8_t> subnegotiation(Command command, const std::vector<uint8_t>& value)
{
  std::vector<uint8_t> out{kIac, kSb, kOptionComPort, static_cast<uint8_t>(command)};
  appendEscaped(value.data(), value.size(), out);
  out.insert(out.end(), {kIac, kSe});
  return out;
}
}  // namespace rfc2217
}  // namespace cnc_bridge
