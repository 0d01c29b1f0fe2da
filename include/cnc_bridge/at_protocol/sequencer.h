// The order in which the '@'-protocol allows commands (docs/protocols/at_protocol.md, "Sequence of
// one machining") as a state machine. The node checks every command it is about to send against it, so
// that a service call in the wrong phase is refused with the rule it breaks instead of confusing
// the controller; the simulator runs the same machine to behave like the controller.
#pragma once

#include <optional>
#include <string>

#include "cnc_bridge/at_protocol/codec.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief Where a machining sequence stands.
enum class Phase
{
  kIdle,       ///< no machining: jog, home and mode changes allowed
  kMachining,  ///< after M1@, between operations: jog blocked (step 2)
  kOperation,  ///< after P0@/P1@ and before #@: setpoints are movements (step 6)
};
const char* toString(Phase phase);

/// \brief The sequencing rules of docs/protocols/at_protocol.md#sequence-of-one-machining. Not thread-safe.
///
///   idle --M1@--> machining --P0@/P1@--> operation --setpoints...--> operation --#@--> machining
///   machining --M0@--> idle (spindle to 0)
///
/// - J<axis>@, F@ and H@ only when idle (the controller ignores a jog request while machining).
/// - P@ only while machining and outside an operation; setpoints and #@ only inside one.
/// - T@ outside an operation or inside one before its first setpoint (step 7 changes the
///   tool after P@); S@ at any time (step 8 sets the operation's speed after P@; 4.2 allows it in
///   jog mode too).
/// - M0@ only between operations (#@ closes the operation first); it stops the spindle (step 18).
/// - P1@ turns coolant on, #@ turns it off again (steps 6 and 16).
class Sequencer
{
 public:
  /// \returns why \p command is not allowed now, or an empty string if it is.
  std::string refusal(const Command& command) const;
  /// \brief Advances the state for a command that is sent or received.
  /// \throws ProtocolError with refusal() if the command is not allowed now (state unchanged).
  void apply(const Command& command);
  /// \brief Back to idle with spindle and coolant off (new connection, emergency stop abort).
  void reset();

  Phase phase() const { return phase_; }
  bool machining() const { return phase_ != Phase::kIdle; }
  bool coolant() const { return coolant_; }
  int spindle() const { return spindle_; }
  int tool() const { return tool_; }  ///< -1 until a T@ was sent
  int jogFeed() const { return jog_feed_; }
  /// \returns the jog axis if the last mode command was J<axis>@, nothing for auto/unknown.
  std::optional<Axis> jogAxis() const { return jog_axis_; }
  bool autoMode() const { return auto_mode_; }

 private:
  Phase phase_ = Phase::kIdle;
  bool coolant_ = false;
  bool moved_in_operation_ = false;
  int spindle_ = 0;
  int tool_ = -1;
  int jog_feed_ = 0;
  bool auto_mode_ = false;
  std::optional<Axis> jog_axis_;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
