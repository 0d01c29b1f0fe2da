// SerialPort: Boost.Asio's serial_port does the I/O; the line settings, output queue size, drain
// and input flush use termios directly.
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/transport/port_doctor.h"

#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace cnc_bridge
{
namespace asio = boost::asio;
namespace
{
// A stat() twice a second: cheap, and soon enough to follow a re-plugged adapter.
constexpr auto kDeviceCheckInterval = std::chrono::milliseconds(500);

bool isPtySlave(dev_t device)
{
  constexpr unsigned kFirstPtySlaveMajor = 136, kLastPtySlaveMajor = 143;  // UNIX98 ptys
  return major(device) >= kFirstPtySlaveMajor && major(device) <= kLastPtySlaveMajor;
}

bool before(const timespec& a, const timespec& b)
{
  return a.tv_sec < b.tv_sec || (a.tv_sec == b.tv_sec && a.tv_nsec < b.tv_nsec);
}

/// A simulator's link to its pty outlives the simulator when it is killed, and the kernel gives
/// the pty's number to the next program that asks for one. Opening the link then would take
/// another program's pty (and its bytes). Such a link is older than the pty it names: a pty's
/// inode change time is its creation (I/O and termios changes leave it), and a live simulator
/// makes its link after its pty.
void refuseStaleLinkToPty(const SerialSettings& settings)
{
  struct stat link, device;
  if (::lstat(settings.device.c_str(), &link) != 0 || !S_ISLNK(link.st_mode) ||
      ::stat(settings.device.c_str(), &device) != 0 || !isPtySlave(device.st_rdev))
  {
    return;
  }
  if (before(link.st_mtim, device.st_ctim))
  {
    throw LinkError(settings.describe() +
                    ": cannot open: the link is older than the pty it names, so the program that made it has "
                    "ended and the pty belongs to another program");
  }
}
}  // namespace

namespace
{
speed_t speedConstant(unsigned baud)
{
  static const std::pair<unsigned, speed_t> kRates[] = {
      {50, B50},           {75, B75},           {110, B110},         {134, B134},         {150, B150},
      {200, B200},         {300, B300},         {600, B600},         {1200, B1200},       {1800, B1800},
      {2400, B2400},       {4800, B4800},       {9600, B9600},       {19200, B19200},     {38400, B38400},
      {57600, B57600},     {115200, B115200},   {230400, B230400},   {460800, B460800},   {500000, B500000},
      {576000, B576000},   {921600, B921600},   {1000000, B1000000}, {1152000, B1152000}, {1500000, B1500000},
      {2000000, B2000000}, {2500000, B2500000}, {3000000, B3000000}, {3500000, B3500000}, {4000000, B4000000}};
  for (const auto& rate : kRates)
  {
    if (rate.first == baud)
    {
      return rate.second;
    }
  }
  throw ConfigError("baud rate " + std::to_string(baud) + " is not a standard rate (50 .. 4000000)");
}

tcflag_t characterSize(unsigned data_bits)
{
  switch (data_bits)
  {
    case 5:
      return CS5;
    case 6:
      return CS6;
    case 7:
      return CS7;
    default:
      return CS8;
  }
}
}  // namespace

SerialPort::SerialPort(SerialSettings settings, InputOnOpen on_open) : settings_(std::move(settings))
{
  settings_.validate();
  speedConstant(settings_.baud);  // an unsupported rate fails before the port is opened
  refuseStaleLinkToPty(settings_);
  boost::system::error_code error;
  stream_.open(settings_.device, error);
  if (error)
  {
    throw LinkError(settings_.describe() + ": cannot open: " + error.message() + ": " +
                    explainOpenFailure(settings_.device, error.value()));
  }
  try
  {
    applySettings();
  }
  catch (const LinkError&)
  {
    close();
    throw;
  }
  struct stat opened;
  if (::fstat(stream_.native_handle(), &opened) == 0)
  {
    device_number_ = opened.st_rdev;
  }
  next_device_check_ = std::chrono::steady_clock::now() + kDeviceCheckInterval;
  if (on_open == InputOnOpen::kDiscard)
  {
    discardInput();
  }
}

void SerialPort::applySettings()
{
  configure(settings_.flow_control);
}

void SerialPort::setFlowControl(FlowControl flow)
{
  configure(flow);
}

void SerialPort::configure(FlowControl flow)
{
  // termios directly rather than Asio's option classes: Asio reads each option back and rejects
  // what a pty does not emulate (character size, parity), and ptys are our test devices.
  struct termios tio;
  const int fd = stream_.native_handle();
  if (::tcgetattr(fd, &tio) != 0)
  {
    const std::string reason = std::strerror(errno);
    throw LinkError(settings_.describe() + ": not a serial port: " + reason);
  }
  ::cfmakeraw(&tio);  // no echo, no line editing, no CR/LF translation, all 8 bits kept
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag = (tio.c_cflag & ~CSIZE) | characterSize(settings_.data_bits);
  tio.c_cflag &= ~(PARENB | PARODD | CSTOPB | CRTSCTS);
  tio.c_iflag &= ~(INPCK | IXON | IXOFF | IXANY);
  if (settings_.parity != Parity::kNone)
  {
    tio.c_cflag |= PARENB | (settings_.parity == Parity::kOdd ? PARODD : 0);
    tio.c_iflag |= INPCK;
  }
  if (settings_.stop_bits == 2)
  {
    tio.c_cflag |= CSTOPB;
  }
  if (flow == FlowControl::kXonXoff)
  {
    tio.c_iflag |= IXON | IXOFF;
  }
  else if (flow == FlowControl::kRtsCts)
  {
    tio.c_cflag |= CRTSCTS;
  }
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, speedConstant(settings_.baud));
  ::cfsetospeed(&tio, speedConstant(settings_.baud));
  int result = ::tcsetattr(fd, TCSANOW, &tio);
  struct stat device;
  if (result != 0 && errno == EINVAL && ::fstat(fd, &device) == 0 && isPtySlave(device.st_rdev))
  {
    // A pty keeps 8 bits and no parity whatever it is told, and a request whose only changes are
    // ones the pty ignores fails with EINVAL (a pty set up 7E1 before, reopened or set up again):
    // ask for what a pty does emulate.
    tio.c_cflag = (tio.c_cflag & ~(CSIZE | PARENB | PARODD)) | CS8;
    tio.c_iflag &= ~INPCK;
    result = ::tcsetattr(fd, TCSANOW, &tio);
  }
  if (result != 0)
  {
    const std::string reason = std::strerror(errno);
    throw LinkError(settings_.describe() + ": cannot configure: " + reason);
  }
}

size_t SerialPort::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  // Checked before reading, so no byte is taken from the port and then dropped with the error.
  const auto now = std::chrono::steady_clock::now();
  if (now >= next_device_check_)
  {
    next_device_check_ = now + kDeviceCheckInterval;
    if (deviceReplaced())
    {
      throw LinkError(settings_.describe() + ": the path now names another device (re-plugged, or the peer restarted)");
    }
  }
  return AsioStreamTransport::read(buffer, size, timeout);
}

void SerialPort::write(const uint8_t* data, size_t size, Milliseconds timeout)
{
  ensureOpen();
  throwIfInterrupted();
  // Asio opens the port non-blocking, so this takes what fits and never waits. Whatever is left
  // (flow control holding, a full buffer) or any error goes the usual way, with its timeout.
  const ssize_t written = ::write(stream_.native_handle(), data, size);
  const size_t done = written > 0 ? static_cast<size_t>(written) : 0;
  if (done < size)
  {
    AsioStreamTransport::write(data + done, size - done, timeout);
  }
}

bool SerialPort::deviceReplaced() const
{
  struct stat now;
  return ::stat(settings_.device.c_str(), &now) != 0 || now.st_rdev != device_number_;
}

SerialPort::~SerialPort()
{
  close();
}

void SerialPort::drain()
{
  if (isOpen())
  {
    ::tcdrain(stream_.native_handle());
  }
}

size_t SerialPort::pendingOutput() const
{
  int queued = 0;
  auto& port = const_cast<asio::serial_port&>(stream_);
  if (!port.is_open() || ::ioctl(port.native_handle(), TIOCOUTQ, &queued) != 0 || queued < 0)
  {
    return 0;
  }
  return static_cast<size_t>(queued);
}

void SerialPort::discardInput()
{
  if (isOpen())
  {
    ::tcflush(stream_.native_handle(), TCIFLUSH);
  }
}
}  // namespace cnc_bridge
