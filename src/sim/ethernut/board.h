// The board side of the ethernut protocol, as a ROS-free class: the heart of sim_ethernut, and a
// peer for in-process tests and benchmarks. It answers every opcode of Table 1 the way client.h
// reads the table (pause-achieved from the board, resume by READYTOSEND), moves a simulated tool
// to each coordinate at a set speed, reports its position (status 4), and injects faults.
#pragma once

#include <atomic>
#include <cstdint>
#include <fstream>
#include <functional>
#include <mutex>
#include <random>
#include <string>

#include "cnc_bridge/ethernut/protocol.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief One message of the board's serial debug port, shaped as qCNC's Interfaces.h declares it
/// (struct Suart_debug: int type; char sender[10], destination[10], opcode[10]; int opcodev). The
/// document gives the struct, not its text; the simulated board prints it as debugLine() does.
struct DebugMessage
{
  int type = 0;             ///< 0 the board itself, 1 a connection, 2 a command received, 3 the job
  std::string sender;       ///< Table 1's origins and destinations: GUI, TCP, MCP, oLED, DEBUG
  std::string destination;  ///< (at most 9 characters each, as the struct's char[10] holds)
  std::string opcode;       ///< what happened: accept, close, init, reset, ready, coord, ...
  int opcodev = 0;          ///< its value: Table 1's x of the opcode, or a count
};

/// \brief "type sender destination opcode opcodev", e.g. "2 GUI TCP reset 0" (no line end).
std::string debugLine(const DebugMessage& message);

struct BoardOptions
{
  double speed_mm_per_s = 500.0;    ///< tool speed; 0 moves instantly
  Milliseconds report_period{100};  ///< status-4 position reports at most this often; 0: none
  unsigned resend_every = 0;        ///< RESEND the first receipt of every Nth coordinate; 0: never
  double resend_probability = 0.0;  ///< RESEND a first receipt with this probability
  uint32_t seed = 1;                ///< for resend_probability
  uint64_t drop_after = 0;          ///< close the connection after the Nth coordinate (once); 0: never
  uint64_t silent_after = 0;        ///< go silent (answer nothing, keep the socket) after the Nth (once)
  /// Stop answering alive requests (only those) once this many coordinates were accepted; 0: never.
  uint64_t mute_keepalive_after = 0;
  std::string log_path;  ///< append every accepted coordinate as "x y z" (mm)
  /// Append the name of every message received (toString of its opcode), one per line, so a test
  /// can check what the board was sent (e.g. that a refused kill never reached it).
  std::string message_log_path;
  /// Told every debug message the board prints on its serial port (connections, commands, job
  /// events); empty: none. Called on the serving thread: it must not block.
  std::function<void(const DebugMessage&)> debug;
};

/// \brief Simulated ethernut board. serve() runs one connection on the calling thread; the
/// counters may be read from any thread.
class Board
{
 public:
  explicit Board(const BoardOptions& options);

  /// \brief Serves one connected client until it goes away, the board drops it (kill, standalone,
  /// drop_after) or \p stop is set. Never throws for link failures (they end the connection).
  void serve(Transport& link, StopSignal& stop);

  uint64_t coordinatesAccepted() const { return accepted_; }
  uint64_t resendsSent() const { return resends_; }

 private:
  struct Connection;  // one served connection's state (board.cpp)

  void advance(Connection& c);
  void receive(Connection& c, const uint8_t* data, size_t n);
  bool answer(Connection& c, const Message& m);
  bool takeCoordinates(Connection& c, const Message& m);
  bool resendOnFirstReceipt(Connection& c);
  void log(float x, float y, float z);
  void logMessage(Opcode opcode);
  void say(int type, const char* sender, const char* destination, const char* opcode, int value);
  void sayReceived(Opcode opcode);

  BoardOptions options_;
  std::mt19937 rng_;
  std::ofstream log_;
  std::ofstream message_log_;
  std::atomic<uint64_t> accepted_{0};
  std::atomic<uint64_t> received_{0};
  std::atomic<uint64_t> resends_{0};
  int connections_ = 0;
  bool dropped_ = false;
  bool silenced_ = false;
  // Board memory survives reconnections (the machine does not move back when the PC goes away).
  float position_[3] = {0.0f, 0.0f, 0.0f};
};
}  // namespace ethernut
}  // namespace cnc_bridge
