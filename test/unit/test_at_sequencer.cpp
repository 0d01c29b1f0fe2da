// The sequencing rules of docs/protocols/at_protocol.md#sequence-of-one-machining (steps 1-18).
#include <gtest/gtest.h>

#include "cnc_bridge/at_protocol/sequencer.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

TEST(AtSequencer, AWholeMachiningInTheProtocolsOrder)
{
  Sequencer s;
  s.apply(JogMode{Axis::kY});
  EXPECT_EQ(s.jogAxis(), Axis::kY);
  s.apply(JogFeed{100});
  s.apply(Machining{true});  // (1)
  EXPECT_EQ(s.phase(), Phase::kMachining);
  s.apply(StartOperation{true});  // (5) with coolant (6)
  EXPECT_TRUE(s.coolant());
  s.apply(ToolChange{3, 40});  // (7)
  s.apply(Spindle{150});       // (8)
  s.apply(Setpoint{});         // (10)
  s.apply(Setpoint{});
  s.apply(EndOperation{});  // (15) coolant off (16)
  EXPECT_FALSE(s.coolant());
  EXPECT_EQ(s.phase(), Phase::kMachining);
  s.apply(StartOperation{false});  // the next operation
  s.apply(Setpoint{});
  s.apply(EndOperation{});
  s.apply(Machining{false});  // (17) spindle to 0 (18)
  EXPECT_EQ(s.spindle(), 0);
  EXPECT_EQ(s.tool(), 3);
  EXPECT_EQ(s.phase(), Phase::kIdle);
}

TEST(AtSequencer, JogAndHomeRefusedWhileMachining)
{
  Sequencer s;
  s.apply(Machining{true});
  EXPECT_NE(s.refusal(JogMode{Axis::kX}).find("refused while machining"), std::string::npos);
  EXPECT_THROW(s.apply(JogMode{Axis::kX}), ProtocolError);
  EXPECT_THROW(s.apply(JogFeed{10}), ProtocolError);
  EXPECT_THROW(s.apply(Home{}), ProtocolError);
  s.apply(StartOperation{false});
  EXPECT_THROW(s.apply(JogMode{Axis::kZ}), ProtocolError);
  EXPECT_EQ(s.phase(), Phase::kOperation);  // a refusal leaves the state alone
}

TEST(AtSequencer, MovesOnlyInsideAnOperation)
{
  Sequencer s;
  EXPECT_NE(s.refusal(Setpoint{}).find("P0@ or P1@"), std::string::npos);
  EXPECT_THROW(s.apply(StartOperation{true}), ProtocolError);  // P before M1
  s.apply(Machining{true});
  EXPECT_THROW(s.apply(Setpoint{}), ProtocolError);      // P before moves
  EXPECT_THROW(s.apply(EndOperation{}), ProtocolError);  // # only after P
  s.apply(StartOperation{false});
  EXPECT_THROW(s.apply(StartOperation{false}), ProtocolError);  // one operation at a time
  EXPECT_THROW(s.apply(Machining{false}), ProtocolError);       // # before M0
  s.apply(Setpoint{});
  EXPECT_THROW(s.apply(ToolChange{2, 10}), ProtocolError);  // not once moving
  s.apply(Spindle{20});                                     // allowed at any time
  s.apply(EndOperation{});
  EXPECT_THROW(s.apply(Machining{true}), ProtocolError);
  s.apply(Machining{false});
  EXPECT_THROW(s.apply(Machining{false}), ProtocolError);
}

TEST(AtSequencer, ResetReturnsToIdle)
{
  Sequencer s;
  s.apply(Machining{true});
  s.apply(StartOperation{true});
  s.apply(Spindle{99});
  s.reset();
  EXPECT_EQ(s.phase(), Phase::kIdle);
  EXPECT_FALSE(s.coolant());
  EXPECT_EQ(s.spindle(), 0);
  s.apply(JogMode{Axis::kX});
}
