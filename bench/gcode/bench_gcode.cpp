// Parse-rate benchmark of the G-code parser: reads a program through gcode::Reader (file I/O
// included, arcs cut into chords at the default 0.01 mm) and prints "lines seconds moves
// max_rss_kib", the last being the process's peak resident memory (getrusage ru_maxrss), which
// must not grow with the program's size (the reader streams). Run by bench/gcode/run.sh beside
// the npm package gcode-parser.
#include <sys/resource.h>

#include <chrono>
#include <fstream>
#include <iostream>

#include "cnc_bridge/gcode/gcode.h"

int main(int argc, char** argv)
{
  if (argc < 2)
  {
    std::cerr << "usage: bench_gcode <program.nc> [repeats]\n";
    return 2;
  }
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 3;
  double best = 1e300;
  uint64_t lines = 0, moves = 0;
  for (int r = 0; r < repeats; ++r)
  {
    std::ifstream in(argv[1], std::ios::binary);
    if (!in)
    {
      std::cerr << "cannot open " << argv[1] << "\n";
      return 1;
    }
    const auto start = std::chrono::steady_clock::now();
    cnc_bridge::gcode::Reader reader(in);
    moves = 0;
    while (const cnc_bridge::gcode::Block* block = reader.nextBlock())
    {
      moves += block->moves.size();
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    lines = reader.parser().lineCount();
    best = std::min(best, seconds);
  }
  struct rusage usage
  {
  };
  getrusage(RUSAGE_SELF, &usage);  // ru_maxrss: KiB on Linux
  std::cout << lines << ' ' << best << ' ' << moves << ' ' << usage.ru_maxrss << std::endl;
  return 0;
}
