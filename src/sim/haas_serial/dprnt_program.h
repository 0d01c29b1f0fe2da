// A small Haas macro interpreter for the DPRNT mode of sim_haas_serial: enough of the language to
// run the probing programs DPRNT exists for (docs/protocols/dprnt.md#surface-model: G65 P9995 ...;
// DPRNT[#5223[44]]; G00 G91 X.5;) against a synthetic surface, and print with real Haas formatting.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace sim
{
/// \brief The simulated machine a program runs on.
struct MacroMachine
{
  std::map<int, double> variables;  ///< macro variables; unset ones read as 0 (Haas #0 "null" prints 0)
  double position[3] = {0, 0, 0};   ///< X Y Z, work coordinates, program units
  bool incremental = false;         ///< G91 in effect
  /// Height of the part surface under (x, y), program units: what a G65 P9995 Z probe finds.
  std::function<double(double x, double y)> surface = [](double, double) { return 0.0; };
  /// The part's sides: where a probe moving from \p from to \p to in X/Y first touches one
  /// (\p contact), false when it touches none. What a G65 P9811 X/Y probe finds; unset: no sides.
  std::function<bool(const double from[2], const double to[2], double contact[2])> side_contact;
  /// Blocks a run may execute before it is taken for an endless loop; 0: no limit (a paced program).
  uint64_t max_blocks = 10000000;
  /// Called before each DPRNT statement (the simulator refreshes #3001, the millisecond timer).
  std::function<void(MacroMachine&)> before_print;
};

/// \brief The sides of a rectangular part whose corner is at (\p corner_x, \p corner_y) and whose
/// X side runs at \p yaw_rad from the X axis, the part lying toward +X and +Y of the corner: the
/// front face (along the part's X) and the left face (along its Y), each a half-line from the
/// corner. For MacroMachine::side_contact.
std::function<bool(const double from[2], const double to[2], double contact[2])> rectangularPartSides(double corner_x,
                                                                                                      double corner_y,
                                                                                                      double yaw_rad);

/// \brief A parsed macro program. Not thread-safe while running.
///
/// Supported (Haas mill programming manual, "Macros"): blocks separated by ';' or new lines;
/// (comments); N numbers; '%' and O-number lines ignored; `#n = expr`; `DPRNT[...]`;
/// `WHILE [expr] DOn` ... `ENDn`; `IF [expr] GOTOn` with `Nn` targets; G00/G01 X Y Z moves under
/// G90/G91; `G65 P9995` single-surface Z probe (sets #5223, the G54 Z offset OpenDNC prints, and
/// #5061..#5063, the probe trigger position); `G65 P9811 X..` or `Y..` single-surface X/Y probe
/// (moves toward the target from the current position, sets #5061..#5063 to where it touched the
/// part's side, returns; touching nothing is an error, as the control's alarm); after every block #5041..#5043 hold the
/// work position and #5021..#5023 the machine position (work position + G54 offset #5221..#5223); M30/M02/M99 end the
/// program. Expressions: numbers, #n, #[expr], + - * /, [ ], EQ NE GT GE LT LE, AND OR, ABS SQRT SIN COS TAN ROUND FIX
/// FUP.
class MacroProgram
{
 public:
  /// \throws ConfigError with the line number for anything it cannot run.
  static MacroProgram parse(const std::string& text);
  /// \brief Runs the program once; \p print gets every DPRNT line (without its line end) and
  /// returns false to stop early.
  /// \throws ConfigError on a run-time error (a loop without its END, a bad expression).
  using PrintFn = std::function<bool(const std::string&)>;
  void run(MacroMachine& machine, const PrintFn& print) const;
  size_t blocks() const { return blocks_.size(); }

 private:
  /// What step() returns when the program ends (M30, M02, M99) or print() asked it to stop.
  static constexpr size_t kStop = static_cast<size_t>(-1);
  struct Block
  {
    std::string text;  // upper case, spaces removed except inside DPRNT[...]
    int line;
    int n = -1;  // N number, for GOTO
  };
  std::vector<Block> blocks_;

  /// Runs block \p pc. \returns the next block's index, or kStop.
  size_t step(size_t pc, MacroMachine& m, const PrintFn& print) const;
  /// DPRNT[...]: \returns what print() returned.
  static bool printBlock(const std::string& text, MacroMachine& m, const PrintFn& print);
  size_t whileBlock(size_t pc, MacroMachine& m) const;
  size_t endBlock(size_t pc) const;
  size_t ifBlock(size_t pc, MacroMachine& m) const;
};
}  // namespace sim
}  // namespace cnc_bridge
