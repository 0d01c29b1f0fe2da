// The commanded position of a drip-feed: the end point of the last motion block the host has fed
// to the control, in the program's coordinates. The control buffers what it is fed, so this is a
// position AHEAD of the tool (by up to a buffer of blocks), never where the tool is. The G-code
// parser (gcode.h) follows the program's modal state (G20/G21, G90/G91, G92, arcs, canned
// cycles); this class adds what a host that only sees the blocks can and cannot know: an axis is
// known once the program has set it absolutely, and becomes unknown again where the numbers leave
// the program's frame (G53, G28/G30), the control runs blocks the host does not see (M98/M97), or
// a block could not be read.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace dnc
{
/// \brief Follows the blocks of a drip-feed as they are sent and keeps the end point of the last
/// motion block. Never throws for what it is fed: a line it cannot read is counted (refused()),
/// its unit, distance-mode and plane words still apply, and the axes it may have moved become
/// unknown. Memory is bounded (one line of at most gcode::ParserOptions::max_line_length bytes).
/// Not thread-safe.
///
/// What the position is: the numbers the program writes (program coordinates: the work offset the
/// control applies, G54..G59 and G43, is not known here), in metres, G20 inches converted, G92
/// shifts undone (the frame the program started in), arcs at their end point, canned cycles where
/// the cycle leaves the tool (the R plane or the initial level).
///
/// When an axis is known: after a motion block names it in G90; G91 moves keep what was known
/// (an incremental move from an unknown start is unknown). Unknown again: the axes a G53, G28 or
/// G30 block names (all of them for a bare G28/G30), every axis after M98/M97 (a subprogram the
/// control runs from its memory) or a refused line that sets a mode the parser could not follow,
/// the axes a refused or block-delete ('/') line names, and an axis G92 re-zeroes while it is
/// unknown (until G92.1).
class CommandedPosition
{
 public:
  explicit CommandedPosition(gcode::Dialect dialect = gcode::Dialect::kHaas);

  /// \brief Bytes as they are written to the control, split anywhere: a line ends at LF or CR
  /// (so every end-of-block pattern), control characters (DC2, DC4, leader NULs) are skipped.
  void feedBytes(std::string_view bytes);
  /// \brief One whole block as sent, without its end of block.
  void feedLine(std::string_view line);
  /// \brief Forgets everything: a new feed.
  void reset();

  /// \brief True when X, Y and Z are all known (see the class comment).
  bool known() const;
  /// \brief The commanded position, metres, program coordinates; meaningful only when known().
  gcode::Vec3 metres() const;
  /// \brief Motion blocks followed so far (a block whose moves were applied): changes each time the
  /// position may have changed, for a publisher that sends only news.
  uint64_t motionBlocks() const { return motion_blocks_; }
  /// \brief Lines fed so far, and those the parser refused (with the last reason).
  uint64_t lines() const { return lines_; }
  uint64_t refused() const { return refused_; }
  const std::string& lastRefusal() const { return last_refusal_; }

 private:
  struct Words;  // what the lenient lexer finds in a line (commanded_position.cpp)
  void follow(const gcode::Block& block, const Words& words);
  void refuse(const Words& words, const std::string& why);
  void forget(const std::array<bool, 3>& axes);
  void forgetAll();

  gcode::Dialect dialect_;
  gcode::Parser parser_;
  std::array<bool, 3> known_{};    ///< set absolutely since the last time it was lost
  std::array<bool, 3> shifted_{};  ///< G92 re-zeroed it while it was unknown: lost until G92.1
  std::string pending_;            ///< feedBytes(): the line being assembled
  bool overlong_ = false;          ///< the pending line was longer than the parser takes
  uint64_t motion_blocks_ = 0;
  uint64_t lines_ = 0;
  uint64_t refused_ = 0;
  std::string last_refusal_;
};
}  // namespace dnc
}  // namespace cnc_bridge
