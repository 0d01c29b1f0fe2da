// Program requests over RS-232: the operator at the control asks for a program by punching a short
// request program, `O00001 (LOAD O1234)` (docs/dnc_node.md, "Program requests from the control").
// A control punches the way its RS-232 is set (Haas setting 14): with XMODEM it is an XModem
// sender and waits for the PC's NAK before its first block (OpenDNC's Haas capture,
// test/data/xmodem/haas_xmodem_capture.json: NAK NAK from the PC, then block 1); with RTS/CTS or
// XON/XOFF it punches '%'-framed text unasked. RequestListener waits on an idle line for either,
// reads the punch with the project's own XModem receiver or backup parser, and sends a control the
// short answer program that says why a request was refused. What a request asks for and what is
// done about it is programs::decideRequest(), shared with share_node.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/transport/transport.h"
#include "cnc_bridge/xmodem/file_transfer.h"

namespace cnc_bridge::dnc
{
/// \brief How the control punches and takes programs.
enum class RequestWire
{
  kXmodem,  ///< XModem, the control the sender of a punch (Haas setting 14 = XMODEM)
  kText     ///< '%'-framed text, flow control by XON/XOFF or RTS/CTS (drip-feed wire)
};
/// \brief "xmodem" -> kXmodem, "drip" -> kText. \throws ConfigError naming the choices.
RequestWire parseRequestWire(const std::string& text);

struct RequestListenerOptions
{
  RequestWire wire = RequestWire::kXmodem;
  /// XModem only: checksum for a Haas. The idle listener invites a punch with its start request
  /// (NAK, or 'C' in the CRC modes).
  xmodem::Mode mode = xmodem::Mode::kChecksum;
  /// XModem only: nak_interval is how often the idle listener invites a punch; the other waits
  /// and limits are the receiver's and the answer's sender's as for any transfer.
  xmodem::Config xmodem;
  /// The control's end of block and the stored programs' (both wires).
  xmodem::TextOptions text;
  /// While idle, the stop flag is looked at this often (how long a transfer waits for the line).
  Milliseconds poll{100};
  /// Text only: a punch without its closing '%' ends after this long without a byte.
  Milliseconds text_quiet{3000};
  /// Text only: a punch longer than this is refused as a babbling line.
  size_t max_text_bytes = 16u << 20;
};

/// \brief One program the control punched.
struct Punch
{
  std::string text;     ///< the program, '\n' line ends (XModem padding removed)
  uint64_t wire_bytes;  ///< bytes received
  std::string how;      ///< "by XModem, 3 blocks" / "as text, 12 lines", for messages
};

/// \brief Waits for punches on one line and answers them. Not thread-safe: one thread listens and
/// answers; the flags given to listen() and answer() are the way other threads stop them.
class RequestListener
{
 public:
  /// \brief Called once the first byte of a punch has arrived (XModem: the SOH of block 1; text:
  /// the first '%'). Return false to leave the punch unread (the line is needed for something else).
  using StartCallback = std::function<bool()>;

  /// \param link must outlive the listener.
  RequestListener(Transport& link, RequestListenerOptions options);

  /// \brief Waits until the control punches a program and reads it whole.
  /// \param stop while no punch has begun, listen() returns nothing within `poll` of it being set;
  ///        nothing but the XModem start requests has been written to the control by then.
  /// \param may_start see StartCallback; when it returns false listen() returns nothing.
  /// \param start_timeout 0: wait as long as it takes; else throw TimeoutError if no punch began
  ///        within this long (a SAVE's program that never comes).
  /// \param cancel stops a punch being read (XModem sends CANs) with CancelledError.
  /// \returns the punch, or nothing (stopped, or refused by may_start).
  /// \throws TimeoutError, ProtocolError (a damaged or cancelled punch, a babbling line),
  ///         CancelledError, LinkError.
  std::optional<Punch> listen(const std::atomic<bool>& stop, const StartCallback& may_start,
                              Milliseconds start_timeout = Milliseconds(0), const std::atomic<bool>* cancel = nullptr);

  /// \brief Sends \p program (a short answer) the way the control takes programs: by XModem,
  /// once the control asks with its NAK (within xmodem.start_wait: the operator starts the
  /// control's receive), or as text.
  /// \returns one line saying what went.
  /// \throws as xmodem::Sender::send(), LinkError.
  std::string answer(const std::string& program, const std::atomic<bool>* cancel = nullptr);

 private:
  std::optional<Punch> listenXmodem(const std::atomic<bool>& stop, const StartCallback& may_start,
                                    Milliseconds start_timeout, const std::atomic<bool>* cancel);
  std::optional<Punch> listenText(const std::atomic<bool>& stop, const StartCallback& may_start,
                                  Milliseconds start_timeout, const std::atomic<bool>* cancel);
  /// Reads what was left after the last text punch first, then the link.
  size_t readSome(uint8_t* buffer, size_t size, Milliseconds timeout);

  Transport& link_;
  RequestListenerOptions options_;
  std::vector<uint8_t> pending_;  ///< text read past a punch's closing '%': the start of the next
};
}  // namespace cnc_bridge::dnc
