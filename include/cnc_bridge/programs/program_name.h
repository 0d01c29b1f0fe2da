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
  std::optional<uint32_t> number;  ///< the O number of the first block that starts with `O` or `:`
  std::string comment;             ///< the text of the first (comment), trimmed; "" if none
};

/// How much of the start of a program readHeader() looks at.
constexpr size_t kHeaderBytes = 4096;
/// \brief Reads the O number and the first comment from the head of a program's text (the
/// leading '%' line and blank lines are skipped; only the first kHeaderBytes are looked at).
/// Never throws.
ProgramHeader readHeader(const std::string& text);
/// \brief readHeader() of the first kHeaderBytes of a file. \throws Error if it cannot be read.
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

 private:
  uint32_t first_ = 0, last_ = 0;
  bool empty_ = true;
  bool allowed_ = false;
  std::string switch_name_;
};

/// \brief Checks a file about to be sent: number from its base name and from its head.
/// \throws DisabledError as ProtectedRange::check(), Error if the file cannot be read.
void checkProtectedFile(const ProtectedRange& range, const NamePattern& pattern, const std::string& path,
                        const std::string& sent_name = "");
}  // namespace cnc_bridge::programs
