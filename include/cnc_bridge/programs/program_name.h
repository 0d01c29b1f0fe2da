// Program names and numbers as a control sees them. A Haas (and a Fanuc) stores each program
// under an O number: on a share its file is named after the number (`O01234.nc`), and inside the
// file the first block carries the number and, in parentheses, the program's title
// (`O01234 (FACE AND PROBE)`, as in the Haas Mill Operator's Manual, "Program numbers"). This file
// turns names into numbers and back, reads the number and first comment from a program's text,
// and guards a range of numbers that must not be overwritten (Haas keeps its probing/WIPS and OEM
// macros in O08000-O09999).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

namespace cnc_bridge::programs
{
/// \brief A file-name pattern with one number field, printf style: "O%05d.nc" names program 1234
/// `O01234.nc`. Matching is case-insensitive for the letters around the number (a control may
/// write `o01234.NC`) and takes any count of digits up to 8. Thread-safe (immutable).
class NamePattern
{
 public:
  /// \throws ConfigError unless \p pattern holds exactly one `%d` or `%0Nd` (N 1..8) and no other `%`
  /// conversion (`%%` is a literal percent sign), and no '/'.
  explicit NamePattern(const std::string& pattern = "O%05d.nc");

  /// \brief The file name of program \p number ("O01234.nc").
  std::string format(uint32_t number) const;
  /// \brief The program number a file name carries, if it matches the pattern.
  std::optional<uint32_t> number(const std::string& name) const;
  const std::string& text() const { return text_; }

 private:
  std::string text_;
  std::string prefix_, suffix_;
  int width_ = 0;
};

/// \brief What the head of a program says about it.
struct ProgramHeader
{
  /// The number of the first block that holds program text, when it starts with `O` or `:`
  std::optional<uint32_t> number;
  /// That block starts with `O` or `:` but no number of 1 to 8 digits follows (`O`, `O(X)`,
  /// `O123456789`): a control would take some number from it that this code cannot tell.
  bool number_unreadable = false;
  std::string first_block;  ///< the start of that block (at most 32 characters), for messages
  std::string comment;      ///< the text of the first (comment), trimmed; "" if none
};

/// How much of the start of a program is looked at for its first comment (its title in a listing).
/// The number is looked for up to the first block of program text, however far that is.
constexpr size_t kHeaderBytes = 4096;

/// \brief Reads a program's number as a control does, from bytes fed in any pieces (bounded memory
/// whatever the input: nothing is kept but the first comment and the start of the first block).
///
/// Skipped before the number: leader (NUL, space, tab, DEL), blank blocks, `%` blocks and blocks
/// that hold only comments `( ... )`. The first block with anything else is the program's first
/// block: `O1234` or Fanuc's `:1234` (any case, spaces before the digits) gives the number; any
/// other text there means the program carries no number (the control names it). The first comment
/// is looked for up to kHeaderBytes, or up to the number's block when that lies further.
class HeaderScanner
{
 public:
  /// \brief Feeds the next bytes. \returns true once the header is known (more bytes change nothing).
  bool feed(const char* data, size_t size);
  bool feed(const std::string& text) { return feed(text.data(), text.size()); }
  /// \brief The input ended (a number block cut short by the end is read as it stands).
  void finish();
  bool done() const { return done_; }
  const ProgramHeader& header() const { return header_; }

 private:
  enum class State
  {
    kBlockStart,  // leader, blanks and comment-only blocks so far
    kPercent,     // a `%` block: skipped to its end
    kComment,     // inside ( ... ); back to comment_return_ at ')'
    kNumberLetter,
    kNumberDigits,
    kText  // the rest of a block whose number is decided
  };
  void take(char c);
  void addDigit(char c);
  void text(char c);
  void endNumber(bool numbered, bool valid);
  void endComment();

  State state_ = State::kBlockStart;
  State comment_return_ = State::kBlockStart;
  ProgramHeader header_;
  bool number_decided_ = false;
  bool comment_found_ = false;
  bool done_ = false;
  bool first_block_open_ = false;  // first_block collects until the end of that block
  std::string comment_;
  uint32_t value_ = 0;
  size_t digits_ = 0;
  uint64_t consumed_ = 0;
};

/// \brief Reads the O number and the first comment from the head of a program's text, as
/// HeaderScanner does (the whole of \p text is looked at if the number needs it). Never throws.
ProgramHeader readHeader(const std::string& text);
/// \brief readHeader() of a file, read in pieces up to the program's first block (memory bounded
/// whatever the file's size). Only a regular file is read: a FIFO, a device or a directory is
/// refused before anything blocks. \throws Error if it cannot be read or is not a regular file.
ProgramHeader readHeaderOfFile(const std::string& path);

/// \brief "O01234" (at least five digits).
std::string programLabel(uint32_t number);

/// \brief A range of program numbers that no wire may overwrite unless allowed (Haas:
/// O08000-O09999, probing/WIPS and OEM macros). Thread-safe (immutable).
class ProtectedRange
{
 public:
  /// \brief Parses "O08000-O09999" (the O is optional), or "" or "none" (nothing protected).
  /// \param allowed the switch that lets protected numbers through (a parameter, a CLI option).
  /// \param switch_name how the user sets it, named in the refusal ("~allow_protected_programs").
  /// \throws ConfigError for a malformed range or one whose end lies before its start.
  ProtectedRange(const std::string& range, bool allowed, std::string switch_name);

  bool contains(uint32_t number) const { return !empty_ && number >= first_ && number <= last_; }
  std::string describe() const;

  /// \brief Refuses the program unless allowed: its file name's number (by \p pattern) and the O
  /// number in its text are both checked, since a control stores a program by either.
  /// \param what how the refusal names the program (a path, a share name).
  /// \throws DisabledError naming the number, the range and the switch.
  void check(const std::string& what, const std::optional<uint32_t>& name_number,
             const std::optional<uint32_t>& text_number) const;
  /// \brief check() with the number of \p header, and a program whose number a control would take
  /// but this code cannot read (ProgramHeader::number_unreadable) refused as well, unless allowed
  /// or nothing is protected. \throws DisabledError naming what to check and the switch.
  void checkHeader(const std::string& what, const std::optional<uint32_t>& name_number,
                   const ProgramHeader& header) const;

 private:
  uint32_t first_ = 0, last_ = 0;
  bool empty_ = true;
  bool allowed_ = false;
  std::string switch_name_;
};

/// \brief Checks a file about to be sent: number from its base name and from its head
/// (readHeaderOfFile()). \throws DisabledError as ProtectedRange::check(), Error if the file cannot
/// be read or is not a regular file.
void checkProtectedFile(const ProtectedRange& range, const NamePattern& pattern, const std::string& path,
                        const std::string& sent_name = "");
}  // namespace cnc_bridge::programs
