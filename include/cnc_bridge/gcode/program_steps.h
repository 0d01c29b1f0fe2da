// ProgramSteps: a part program as a streaming node must carry it out: its moves, and between them
// the program's own commands in the order a control executes them within a block (LinuxCNC's
// "G-code order of execution", docs/gcode.md): tool change, spindle, coolant, dwell, the moves,
// then a stop or the end (M00, M01, M02, M30). Nothing after M02/M30 is read. The parser stays
// the one of gcode.h; this class only puts what a Block says into that order.
#pragma once

#include <cstdint>
#include <deque>
#include <istream>
#include <string>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace gcode
{
/// \brief One thing a streaming node does next.
struct ProgramStep
{
  enum class Kind : uint8_t
  {
    kMove,          ///< move: a straight move (or an arc's chord)
    kToolChange,    ///< M06: tool is now in the spindle
    kSpindle,       ///< M03/M04/M05 or S: spindle, spindle_rpm are the new values
    kCoolant,       ///< M07/M08/M09: coolant is the new value
    kDwell,         ///< G04 (or a canned cycle's P at the bottom): dwell_s seconds
    kStop,          ///< M00: program stop at the end of this block
    kOptionalStop,  ///< M01: stop at the end of this block when the operator's OPT STOP is on
    kEnd            ///< M02/M30: the program ends; nothing after it
  };
  Kind kind = Kind::kMove;
  uint32_t line = 0;  ///< 1-based source line of the block
  Move move;          ///< kMove
  int32_t tool = -1;  ///< kToolChange
  Spindle spindle = Spindle::kOff;
  double spindle_rpm = 0.0;
  bool coolant = false;
  double dwell_s = 0.0;
  uint16_t m_code = 0;  ///< kStop, kOptionalStop, kEnd: 0, 1, 2 or 30

  /// \brief "M00 program stop at line 12", "G04 dwell of 1.5 s at line 8", ... for messages.
  std::string describe() const;
  /// \brief True for the program's commands a node may have to refuse (spindle, coolant, tool).
  bool isMachineCommand() const
  {
    return kind == Kind::kToolChange || kind == Kind::kSpindle || kind == Kind::kCoolant;
  }
};

/// \brief Reads a program block by block and hands out its steps in execution order. Memory as
/// Reader (one block at a time). Not thread-safe.
class ProgramSteps
{
 public:
  /// \param in the program; must outlive this object.
  ProgramSteps(std::istream& in, const ParserOptions& options) : reader_(in, options) {}

  /// \brief The next step. \returns false at the end of the stream and after kEnd.
  /// \throws ParseError, Error as Reader.
  bool next(ProgramStep& step)
  {
    while (pending_.empty())
    {
      if (ended_)
        return false;
      const Block* block = reader_.nextBlock();
      if (!block)
        return false;
      queue(*block);
    }
    step = pending_.front();
    pending_.pop_front();
    return true;
  }

 private:
  void queue(const Block& block)
  {
    const ModalState& now = reader_.parser().state();
    ProgramStep step;
    step.line = block.line;
    if (block.tool_change)
      push(step, ProgramStep::Kind::kToolChange, [&](ProgramStep& s) { s.tool = now.tool; });
    if (now.spindle != before_.spindle || now.spindle_rpm != before_.spindle_rpm)
      push(step, ProgramStep::Kind::kSpindle,
           [&](ProgramStep& s)
           {
             s.spindle = now.spindle;
             s.spindle_rpm = now.spindle_rpm;
           });
    if (now.coolant != before_.coolant)
      push(step, ProgramStep::Kind::kCoolant, [&](ProgramStep& s) { s.coolant = now.coolant; });
    if (block.dwell_s >= 0.0)
      push(step, ProgramStep::Kind::kDwell, [&](ProgramStep& s) { s.dwell_s = block.dwell_s; });
    for (const Move& move : block.moves)
    {
      push(step, ProgramStep::Kind::kMove, [&](ProgramStep& s) { s.move = move; });
      if (move.dwell_after_s > 0.0)
        push(step, ProgramStep::Kind::kDwell, [&](ProgramStep& s) { s.dwell_s = move.dwell_after_s; });
    }
    for (uint8_t i = 0; i < block.m_count; ++i)
    {
      const uint16_t m = block.m_codes[i];
      if (m == 0 || m == 1)
        push(step, m == 0 ? ProgramStep::Kind::kStop : ProgramStep::Kind::kOptionalStop,
             [&](ProgramStep& s) { s.m_code = m; });
      if (m == 2 || m == 30)
      {
        push(step, ProgramStep::Kind::kEnd, [&](ProgramStep& s) { s.m_code = m; });
        ended_ = true;
        break;
      }
    }
    before_ = now;
  }

  template <typename Fill>
  void push(const ProgramStep& base, ProgramStep::Kind kind, Fill fill)
  {
    ProgramStep s = base;
    s.kind = kind;
    fill(s);
    pending_.push_back(s);
  }

  Reader reader_;
  ModalState before_;
  std::deque<ProgramStep> pending_;
  bool ended_ = false;
};

inline std::string ProgramStep::describe() const
{
  const std::string at = " at line " + std::to_string(line);
  switch (kind)
  {
    case Kind::kMove:
      return "move" + at;
    case Kind::kToolChange:
      return "tool change to T" + std::to_string(tool) + at;
    case Kind::kSpindle:
      return std::string(spindle == Spindle::kOff         ? "spindle stop (M05)"
                         : spindle == Spindle::kClockwise ? "spindle clockwise (M03)"
                                                          : "spindle counter-clockwise (M04)") +
             " S" + std::to_string(static_cast<long>(spindle_rpm)) + at;
    case Kind::kCoolant:
      return std::string(coolant ? "coolant on (M07/M08)" : "coolant off (M09)") + at;
    case Kind::kDwell:
      return "G04 dwell of " + std::to_string(dwell_s).substr(0, std::to_string(dwell_s).find('.') + 4) + " s" + at;
    case Kind::kStop:
      return "M00 program stop" + at;
    case Kind::kOptionalStop:
      return "M01 optional stop" + at;
    case Kind::kEnd:
      return std::string(m_code == 30 ? "M30" : "M02") + " program end" + at;
  }
  return "step" + at;
}
}  // namespace gcode
}  // namespace cnc_bridge
