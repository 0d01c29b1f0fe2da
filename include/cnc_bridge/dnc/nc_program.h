// Reading an NC program file for drip-feed without holding it in memory: a line reader with a
// fixed buffer (programs can be hundreds of megabytes), the character check a control needs before
// anything is sent (it cannot take a lowercase letter under ISO, a byte above 0x7E, a DC code in the
// text), and the modal state tracker that lets a feed restart mid-program with the tool, spindle,
// units, distance mode, work offset and feed restated.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace dnc
{
/// \brief Reads a file one line at a time with a fixed-size buffer. Not thread-safe.
///
/// A line ends at LF, CR or CR LF (files from any editor); the end is not part of the line.
/// Memory stays at the buffer size plus the longest line, whatever the file size.
class LineReader
{
 public:
  /// \param path file to read.
  /// \param max_line_length longer lines raise ConfigError (no NC control takes a block that long,
  ///        and a binary file would otherwise grow the line buffer without bound).
  /// \throws ConfigError if the file cannot be opened.
  explicit LineReader(const std::string& path, size_t max_line_length = 4096);
  ~LineReader();
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  /// \brief Reads the next line into \p line (without its end).
  /// \returns false at the end of the file.
  /// \throws ConfigError for a line longer than the limit (with its line number), Error on a read error.
  bool next(std::string& line);

  /// \brief 1-based number of the line last returned by next(); 0 before the first.
  uint64_t lineNumber() const { return line_number_; }
  /// \brief Size of the file in bytes as opened (for progress).
  uint64_t fileSize() const { return file_size_; }

 private:
  int fill();  // next byte or -1 at end of file

  std::string path_;
  size_t max_line_length_;
  std::FILE* file_ = nullptr;
  std::vector<char> buffer_;
  size_t pos_ = 0;
  size_t end_ = 0;
  uint64_t line_number_ = 0;
  uint64_t file_size_ = 0;
};

/// \brief One character of a program that the control cannot take.
struct CharacterIssue
{
  uint64_t line = 0;    ///< 1-based line of the file
  uint64_t column = 0;  ///< 1-based byte column
  uint8_t byte = 0;
  std::string reason;

  /// \brief "line 12 column 5: lowercase 'x' (0x78) ..." for messages.
  std::string describe() const;
};

/// \brief What the control accepts in program text.
struct CharacterRules
{
  /// Under ISO (7 data bits + even parity) a Fanuc or Haas rejects lowercase; on 8N1 most accept
  /// it in comments. Default on: the safe choice when the format is not known.
  bool reject_lowercase = true;
  /// A '%' inside the program ends it at the control: allowed only as the first or last line.
  bool reject_inner_percent = true;
};

/// \brief Checks one line. Printable ASCII (0x20..0x7E) and TAB pass; control codes (DC1..DC4
/// would stop or start the reader mid-program), bytes above 0x7E and, per \p rules, lowercase fail.
/// \param out issues are appended here (at most \p limit in all).
void checkLine(const std::string& line, uint64_t line_number, const CharacterRules& rules,
               std::vector<CharacterIssue>& out, size_t limit = 100);

/// \brief The modal state a control keeps between blocks, as far as a restart must restate it.
/// Each field holds the words as written in the program (e.g. "G54.1 P3", "F1500."), empty when
/// the program has not set it.
struct ModalState
{
  std::string units;          ///< G20 | G21
  std::string distance;       ///< G90 | G91
  std::string plane;          ///< G17 | G18 | G19
  std::string work_offset;    ///< G54..G59, "G54.1 P3", G110..G129 (Haas)
  std::string tool;           ///< "T5" (the tool in the spindle: the T of the last M6)
  std::string tool_length;    ///< "G43 H5" | "G49" (empty when never set)
  std::string spindle_speed;  ///< "S1200"
  std::string spindle;        ///< M3 | M4 | M5
  std::string coolant;        ///< M7 | M8 | M9
  std::string motion;         ///< G0 | G1 | G2 | G3 (last modal motion)
  std::string feed;           ///< "F25." last F word
  std::string sequence;       ///< last N word, e.g. "N1190"
};

/// \brief Follows the modal words of a program block by block. Not thread-safe.
///
/// Reads words with the G-code parser's lexer in its lenient mode (gcode::BlockLexer): a letter
/// and a number (Fanuc/Haas syntax); (comments) and everything after ';' skipped. Macro
/// expressions ('#', '[') are not evaluated: a word whose value is an expression keeps its text.
class ModalTracker
{
 public:
  /// \brief Applies one block (one line of the file).
  void apply(const std::string& line);
  const ModalState& state() const { return state_; }

  /// \brief The blocks to send before restarting at \p line_number: a comment saying where, then
  /// units/plane/distance/work offset, the tool change, the length offset, the spindle, the
  /// coolant, and the motion mode with the feed. G2/G3 are not restated (an arc needs its end
  /// point): the feed is restated with G1 and the caller is warned through \p warnings.
  /// \returns lines separated by '\n' (the sender converts them to the control's EOB).
  std::string restartPreamble(uint64_t line_number, std::vector<std::string>* warnings = nullptr) const;

 private:
  struct Block;  ///< what one block says that is settled once all its words are read
  void applyG(double value, Block& block);
  void applyM(double value, Block& block);
  /// The words that complete others (G54.1 P, G43 H) and the tool change (T with or before M6).
  void settle(const Block& block);

  bool pending_m6_ = false;
  std::string last_t_;
  ModalState state_;
};

/// \brief Where a restart begins: \p line (1-based file line) or the first block with sequence
/// number \p block (e.g. "N1234" or "1234"), whichever is given.
struct RestartPoint
{
  uint64_t line = 0;  ///< 0 = not a line restart
  std::string block;  ///< empty = not a block restart
  bool active() const { return line > 0 || !block.empty(); }
};

/// \brief What a streaming pass over a program found, before anything is sent.
struct ProgramScan
{
  uint64_t lines = 0;                  ///< lines in the file
  uint64_t first_text_line = 0;        ///< first line that is not blank (0: none)
  uint64_t last_text_line = 0;         ///< last line that is not blank
  bool starts_with_percent = false;    ///< first non-blank line is "%"
  bool ends_with_percent = false;      ///< last non-blank line is "%" (and is not the first)
  std::vector<CharacterIssue> issues;  ///< characters the control cannot take (first 100)
  uint64_t issue_count = 0;            ///< all issues, including those past the first 100
  uint64_t start_line = 1;             ///< the first line to send (the restart line, or 1)
  ModalState state_at_start;           ///< modal state before start_line
  std::string computed_preamble;       ///< restartPreamble() at start_line ("" when not restarting)
  std::vector<std::string> warnings;   ///< restart caveats (an arc was active, ...)
  uint64_t body_bytes = 0;             ///< bytes of lines start_line..end incl. EOB (no framing)
};

/// \brief One pass over the file: counts, checks every character, finds the restart point and the
/// modal state there. Memory does not depend on the file size.
/// \param eob_size bytes per end of block, for body_bytes.
/// \throws ConfigError if the file cannot be read, a line is too long, or the restart point is not
///         in the file (line past the end, block number absent), naming it.
ProgramScan scanProgram(const std::string& path, const CharacterRules& rules, const RestartPoint& restart,
                        size_t eob_size, size_t max_line_length = 4096);

/// \brief The sequence number of a block ("N1234"), or "" if it has none.
std::string sequenceNumber(const std::string& line);
}  // namespace dnc
}  // namespace cnc_bridge
