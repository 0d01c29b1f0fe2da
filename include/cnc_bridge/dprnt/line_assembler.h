// Turns the raw bytes of a DPRNT stream into lines. A machine prints to a serial printer that was
// never meant to be a data link: lines end in CR (Haas), LF or CR LF; Fanuc-style controls wrap
// output in NUL leaders and DC2/DC4 (POPEN/PCLOS); a 7-bit even-parity line read as 8N1 sets the
// top bit of every other character; a cable plugged in mid-transfer produces noise. The assembler
// keeps every good line and counts everything it drops, so nothing disappears silently.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

namespace cnc_bridge
{
namespace dprnt
{
/// \brief Counters of what the assembler saw. Plain data.
struct AssemblerStats
{
  uint64_t lines = 0;            ///< complete lines delivered
  uint64_t empty_lines = 0;      ///< line ends with no text (DPRNT[] or a CR LF after a CR)
  uint64_t overlong = 0;         ///< lines longer than the limit, reported and skipped
  uint64_t garbage_bytes = 0;    ///< control bytes that have no place in DPRNT text, dropped
  uint64_t control_bytes = 0;    ///< NUL/DC1-DC4/SUB/DEL leaders and tape codes, dropped by design
  uint64_t partial_dropped = 0;  ///< unterminated lines dropped when the link went away (reset())
  uint64_t bytes = 0;            ///< every byte fed
};

/// \brief What a line handler receives.
struct LineEvent
{
  enum class Kind
  {
    kLine,      ///< a complete line; text is the line without its end
    kOverlong,  ///< a line exceeded the limit; text is its first max_length characters
  };
  Kind kind;
  std::string_view text;  ///< valid only during the call
};

/// \brief Splits a DPRNT byte stream into lines. Not thread-safe (one reader thread feeds it).
///
/// Byte handling (docs/protocols/dprnt.md#bytes-to-lines):
///   - bit 7 is cleared first when mask_parity is set (7E1/7O1 read as 8N1; DPRNT text is ASCII);
///   - CR, LF end a line; an LF right after a CR belongs to the same CR LF end;
///   - NUL, DC1..DC4 (reader/punch control, POPEN/PCLOS leaders), SUB (0x1A) and DEL (0x7F, tape
///     feed) are dropped and counted as control bytes;
///   - TAB becomes a space; other bytes below 0x20 (and 0x80..0xFF when not masking) are garbage:
///     dropped, counted, the line around them kept;
///   - a line longer than max_length is reported once (kOverlong) and everything up to the next
///     line end is skipped, so the stream recovers at the next line.
class LineAssembler
{
 public:
  using Handler = std::function<void(const LineEvent&)>;

  /// \param max_length longest line accepted, in characters (at least 1).
  /// \param mask_parity clear bit 7 of every byte before anything else.
  /// \param emit_empty deliver empty lines (kLine with empty text) instead of only counting them.
  explicit LineAssembler(size_t max_length = 256, bool mask_parity = true, bool emit_empty = false);

  /// \brief Feeds bytes; calls \p handler for every complete or over-long line they finish.
  void feed(const uint8_t* data, size_t size, const Handler& handler);
  void feed(std::string_view text, const Handler& handler)
  {
    feed(reinterpret_cast<const uint8_t*>(text.data()), text.size(), handler);
  }

  /// \brief Drops an unfinished line (the link went away mid-line); counted in partial_dropped.
  void reset();

  /// \brief Characters of the unfinished line held so far.
  size_t pending() const { return line_.size(); }
  /// \brief The unfinished line held so far (for a report before reset()).
  std::string_view pendingText() const { return line_; }
  const AssemblerStats& stats() const { return stats_; }
  void clearStats() { stats_ = AssemblerStats(); }
  size_t maxLength() const { return max_length_; }

 private:
  void endLine(const Handler& handler);

  size_t max_length_;
  bool mask_parity_;
  bool emit_empty_;
  std::string line_;
  bool skipping_ = false;  // inside an over-long line, until the next line end
  bool after_cr_ = false;  // the previous byte was CR: a following LF is part of that line end
  AssemblerStats stats_;
};
}  // namespace dprnt
}  // namespace cnc_bridge
