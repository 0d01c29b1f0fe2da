// Serial lines at a device server: raw TCP, and Telnet with COM Port Control (RFC 2217).
#include "cnc_bridge/transport/network_serial_line.h"

#include <algorithm>
#include <cstring>
#include <thread>

namespace cnc_bridge
{
namespace
{
using Clock = std::chrono::steady_clock;

constexpr const char* kWhenClosed =
    "the device server closed the connection or stopped answering: it restarted, the network path is down, or it "
    "serves its port to one client at a time and another client holds it";

std::unique_ptr<TcpConnection> connectToServer(const SerialSettings& settings, const SerialAddress& address,
                                               Milliseconds timeout)
{
  try
  {
    auto connection = TcpConnection::connect(address.host, address.port, timeout);
    connection->failUnansweredWithin(kDeadPeerWithin);
    return connection;
  }
  catch (const LinkError& error)
  {
    throw LinkError(settings.device + ": cannot reach the device server: " + error.what());
  }
}

/// What a server said before it closed the connection ("Port already in use"), when it is short
/// printable text; empty otherwise (line data, not a message).
std::string serverMessage(const uint8_t* bytes, size_t size)
{
  std::string text;
  for (size_t i = 0; i < size && text.size() <= 200; ++i)
  {
    const char c = static_cast<char>(bytes[i]);
    if (c == '\r' || c == '\n')
      continue;
    if (bytes[i] < 0x20 || bytes[i] > 0x7E)
      return "";
    text += c;
  }
  return text.size() <= 200 ? text : "";
}

/// A server closed a new connection at once: busy with another client, or still closing the
/// previous connection (ser2net lets its port's output drain first).
class TurnedAway : public LinkError
{
 public:
  using LinkError::LinkError;
};

/// Runs \p open until it does not meet a busy server, for up to kBusyRetryFor (within the connect
/// timeout): a client that closes a line and opens it again at once must not fail for it.
template <class Open>
auto openUnlessBusy(Milliseconds connect_timeout, Open open)
{
  const auto give_up = Clock::now() + std::min<Milliseconds>(connect_timeout, kBusyRetryFor);
  for (;;)
  {
    try
    {
      return open();
    }
    catch (const TurnedAway& busy)
    {
      if (Clock::now() >= give_up)
        throw LinkError(busy.what());
    }
    std::this_thread::sleep_for(kBusyRetryEvery);  // the server sends no notice when it is free
  }
}

std::string saying(const std::string& message)
{
  return message.empty() ? "" : ", saying '" + message + "'";
}

/// Waits until the server has acknowledged what was written. Nothing signals an acknowledgement,
/// so this looks at the send queue every millisecond, for at most kDeadPeerWithin (by then the
/// connection has failed anyway).
void waitUntilAcknowledged(const TcpConnection& connection)
{
  const auto give_up = Clock::now() + kDeadPeerWithin;
  while (connection.isOpen() && connection.unacknowledged() > 0 && Clock::now() < give_up)
  {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// Both kinds

NetworkSerialLine::NetworkSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection)
    : settings_(std::move(settings)), connection_(std::move(connection))
{
}

void NetworkSerialLine::fail(const LinkError& error) const
{
  throw LinkError(describe() + ": " + kWhenClosed + " (" + error.what() + ")");
}

void NetworkSerialLine::drain()
{
  waitUntilAcknowledged(*connection_);
}

size_t NetworkSerialLine::pendingOutput() const
{
  return connection_->unacknowledged();
}

void NetworkSerialLine::interrupt()
{
  connection_->interrupt();
}

void NetworkSerialLine::close()
{
  connection_->close();
}

bool NetworkSerialLine::isOpen() const
{
  return connection_->isOpen();
}

// ---------------------------------------------------------------------------------------------
// Raw TCP

RawTcpSerialLine::RawTcpSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection)
    : NetworkSerialLine(std::move(settings), std::move(connection))
{
}

std::unique_ptr<RawTcpSerialLine> RawTcpSerialLine::open(const SerialSettings& settings, const SerialAddress& address,
                                                         InputOnOpen on_open, Milliseconds connect_timeout)
{
  return openUnlessBusy(connect_timeout,
                        [&]
                        {
                          std::unique_ptr<RawTcpSerialLine> line(
                              new RawTcpSerialLine(settings, connectToServer(settings, address, connect_timeout)));
                          line->refuseIfTurnedAway();
                          if (on_open == InputOnOpen::kDiscard)
                          {
                            line->discardInput();
                          }
                          return line;
                        });
}

void RawTcpSerialLine::refuseIfTurnedAway()
{
  // A server that already serves another client accepts the connection, says so in plain text
  // ("Port already in use") and closes it. On raw TCP that text would pass for the control's
  // data, so the first moments of a connection are watched for it; whatever arrives meanwhile from
  // a connection that stays open is kept for read().
  const auto until = Clock::now() + kTurnedAwayWithin;
  uint8_t buffer[256];
  while (Clock::now() < until && held_.size() < sizeof buffer)
  {
    size_t got = 0;
    try
    {
      got = connection_->read(buffer, sizeof buffer - held_.size(),
                              std::chrono::ceil<Milliseconds>(until - Clock::now()));
    }
    catch (const LinkError& error)
    {
      throw TurnedAway(describe() + ": the device server closed the connection at once" +
                       saying(serverMessage(held_.data(), held_.size())) +
                       ": another client holds its port (most servers serve one client at a time), or the port is "
                       "disabled on the server (" +
                       error.what() + ")");
    }
    held_.insert(held_.end(), buffer, buffer + got);
  }
}

size_t RawTcpSerialLine::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  if (held_start_ < held_.size())
  {
    const size_t count = std::min(size, held_.size() - held_start_);
    std::memcpy(buffer, held_.data() + held_start_, count);
    held_start_ += count;
    return count;
  }
  try
  {
    return connection_->read(buffer, size, timeout);
  }
  catch (const LinkError& error)
  {
    fail(error);
  }
}

void RawTcpSerialLine::write(const uint8_t* data, size_t size, Milliseconds timeout)
{
  try
  {
    connection_->write(data, size, timeout);
  }
  catch (const LinkError& error)
  {
    fail(error);
  }
}

void RawTcpSerialLine::discardInput()
{
  held_.clear();
  held_start_ = 0;
  connection_->discardInput();
}

std::string RawTcpSerialLine::describe() const
{
  return settings_.device + " (line set up on the server)";
}

// ---------------------------------------------------------------------------------------------
// Telnet with COM Port Control

TelnetSerialLine::TelnetSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection,
                                   Milliseconds answer_timeout)
    : NetworkSerialLine(std::move(settings), std::move(connection)), answer_timeout_(answer_timeout)
{
}

std::unique_ptr<TelnetSerialLine> TelnetSerialLine::open(const SerialSettings& settings, const SerialAddress& address,
                                                         InputOnOpen on_open, Milliseconds connect_timeout)
{
  return openUnlessBusy(connect_timeout,
                        [&]
                        {
                          std::unique_ptr<TelnetSerialLine> line(new TelnetSerialLine(
                              settings, connectToServer(settings, address, connect_timeout), connect_timeout));
                          line->setUp();
                          if (on_open == InputOnOpen::kDiscard)
                          {
                            line->discardInput();
                          }
                          return line;
                        });
}

Milliseconds TelnetSerialLine::left(Clock::time_point deadline)
{
  if (deadline == Clock::time_point::max())
  {
    return kWaitForever;
  }
  const auto rest = std::chrono::ceil<Milliseconds>(deadline - Clock::now());
  return std::max(rest, Milliseconds(0));
}

void TelnetSerialLine::setUp()
{
  try
  {
    negotiate();
    applySettings();
  }
  catch (const LinkError&)
  {
    if (isOpen())
      throw;
    // Closed while setting up: a server that serves another client negotiates, says so and closes
    // (what it said may be lost when our next request meets the closed connection).
    const std::string message = serverMessage(data_.data() + data_start_, data_.size() - data_start_);
    throw TurnedAway(describe() + ": the device server closed the connection at once" + saying(message) +
                     ": another client holds its port (most servers serve one client at a time), or the port is "
                     "disabled on the server");
  }
}

void TelnetSerialLine::negotiate()
{
  send(options_.start(), answer_timeout_);
  const auto deadline = Clock::now() + answer_timeout_;
  while (!options_.comPortAccepted())
  {
    if (options_.comPortRefused())
    {
      throw LinkError(describe() +
                      ": the device server refuses COM Port Control (RFC 2217) on this port: set the port to RFC "
                      "2217 mode (ser2net: accepter telnet(rfc2217),tcp,...), or use tcp://host:port and set the "
                      "line up on the server");
    }
    if (Clock::now() >= deadline || !pump(left(deadline)))
    {
      throw LinkError(describe() + ": no answer to Telnet COM Port Control (RFC 2217) within " +
                      std::to_string(answer_timeout_.count()) +
                      " ms: the server port is probably in raw TCP mode (use tcp://host:port) or not a device "
                      "server's port");
    }
  }
  // The binary answers come with the COM port's: give them the same chance.
  if (options_.binaryRefused())
  {
    throw LinkError(describe() +
                    ": the device server refuses Telnet binary transmission (RFC 856), so bytes 0x0D and 0xFF "
                    "would not pass unchanged: set the port's Telnet mode to binary");
  }
}

void TelnetSerialLine::applySettings()
{
  request(rfc2217::lineSettings(settings_));
}

void TelnetSerialLine::setFlowControl(FlowControl flow)
{
  request({rfc2217::flowControlSetting(flow)});
}

void TelnetSerialLine::request(const std::vector<rfc2217::Setting>& settings)
{
  std::vector<uint8_t> out;
  for (const auto& setting : settings)
  {
    answers_.erase(setting.command);
    const auto bytes = rfc2217::subnegotiation(setting.command, setting.value);
    out.insert(out.end(), bytes.begin(), bytes.end());
  }
  send(out, answer_timeout_);
  const auto deadline = Clock::now() + answer_timeout_;
  for (const auto& setting : settings)
  {
    const std::string name = rfc2217::settingName(setting.command);
    const std::string asked = rfc2217::describeValue(setting.command, setting.value);
    while (answers_.count(setting.command) == 0)
    {
      if (Clock::now() >= deadline || !pump(left(deadline)))
      {
        throw LinkError(describe() + ": the device server did not answer the setting of " + name + " (" + asked +
                        ") within " + std::to_string(answer_timeout_.count()) + " ms");
      }
    }
    const auto& answer = answers_[setting.command];
    if (answer != setting.value)
    {
      throw LinkError(describe() + ": the device server set " + name + " " +
                      rfc2217::describeValue(setting.command, answer) + " when asked for " + asked +
                      ": check that its port supports " + asked + " and lets the client set the line");
    }
  }
}

bool TelnetSerialLine::pump(Milliseconds timeout)
{
  uint8_t raw[4096];
  size_t received = 0;
  try
  {
    received = connection_->read(raw, sizeof raw, timeout);
  }
  catch (const LinkError& error)
  {
    fail(error);
  }
  if (received == 0)
  {
    return false;
  }
  if (data_start_ == data_.size())
  {
    data_.clear();
    data_start_ = 0;
  }
  std::vector<rfc2217::Event> events;
  decoder_.feed(raw, received, data_, events);
  for (const auto& event : events)
  {
    handle(event);
  }
  return true;
}

void TelnetSerialLine::handle(const rfc2217::Event& event)
{
  using rfc2217::Command;
  if (event.kind != rfc2217::Event::Kind::kComPort)
  {
    const auto reply = options_.reply(event);
    if (!reply.empty())
    {
      send(reply, answer_timeout_);
    }
    return;
  }
  if (event.command < rfc2217::kServerOffset)
  {
    return;  // a client's command sent to us: not for a client to answer
  }
  const auto command = static_cast<Command>(event.command - rfc2217::kServerOffset);
  switch (command)
  {
    case Command::kFlowControlSuspend:
      suspended_ = true;
      break;
    case Command::kFlowControlResume:
      suspended_ = false;
      break;
    case Command::kSetBaudRate:
    case Command::kSetDataSize:
    case Command::kSetParity:
    case Command::kSetStopSize:
    case Command::kSetControl:
      answers_[command] = event.value;
      break;
    default:
      break;  // line and modem state notices, signature, purge answers: nothing depends on them
  }
}

void TelnetSerialLine::send(const std::vector<uint8_t>& bytes, Milliseconds timeout)
{
  try
  {
    connection_->write(bytes.data(), bytes.size(), timeout);
  }
  catch (const LinkError& error)
  {
    fail(error);
  }
}

size_t TelnetSerialLine::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  const auto deadline = timeout == kWaitForever ? Clock::time_point::max() : Clock::now() + timeout;
  while (data_start_ == data_.size())
  {
    // Telnet commands alone (a negotiation, a modem-state notice) are no data: wait on.
    if (!pump(left(deadline)) || (data_start_ == data_.size() && Clock::now() >= deadline))
    {
      return 0;
    }
  }
  const size_t count = std::min(size, data_.size() - data_start_);
  std::memcpy(buffer, data_.data() + data_start_, count);
  data_start_ += count;
  return count;
}

void TelnetSerialLine::write(const uint8_t* data, size_t size, Milliseconds timeout)
{
  const auto deadline = timeout == kWaitForever ? Clock::time_point::max() : Clock::now() + timeout;
  while (suspended_)
  {
    // The server asked us to hold (FLOWCONTROL-SUSPEND): what arrives meanwhile is kept for read().
    if (Clock::now() >= deadline || (!pump(left(deadline)) && Clock::now() >= deadline))
    {
      throw TimeoutError(describe() +
                         ": the device server asked to hold sending (its buffer is full) and did not "
                         "resume within " +
                         std::to_string(timeout.count()) + " ms");
    }
  }
  std::vector<uint8_t> escaped;
  rfc2217::appendEscaped(data, size, escaped);
  send(escaped, timeout);
}

void TelnetSerialLine::discardInput()
{
  send(rfc2217::subnegotiation(rfc2217::Command::kPurgeData, {rfc2217::kPurgeReceiveBuffer}), answer_timeout_);
  // What is already on its way is read through the decoder, so no Telnet command is lost with it;
  // a control that keeps sending is not waited out.
  const auto give_up = Clock::now() + Milliseconds(50);
  while (Clock::now() < give_up && pump(Milliseconds(1)))
  {
  }
  data_.clear();
  data_start_ = 0;
}

std::string TelnetSerialLine::describe() const
{
  return settings_.describe();
}

std::vector<std::string> TelnetSerialLine::serverSettings() const
{
  std::vector<std::string> out;
  for (const auto& answer : answers_)
  {
    out.push_back(std::string(rfc2217::settingName(answer.first)) + " " +
                  rfc2217::describeValue(answer.first, answer.second));
  }
  return out;
}
}  // namespace cnc_bridge
