// libFuzzer target: arbitrary punched bytes through BackupParser, fed in two pieces split at the
// first input byte. The output must be the same as from one feed, contain no control codes, and
// end every line with '\n'.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "cnc_bridge/dnc/backup.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using cnc_bridge::dnc::BackupParser;
  if (size == 0)
  {
    return 0;
  }
  const size_t split = data[0] % size;
  BackupParser whole;
  std::string out_whole;
  whole.feed(data, size, out_whole);
  whole.finish(out_whole);

  BackupParser pieces;
  std::string out_pieces;
  const size_t used = pieces.feed(data, split, out_pieces);
  if (used == split)
  {
    pieces.feed(data + split, size - split, out_pieces);
  }
  pieces.finish(out_pieces);
  if (out_whole != out_pieces)
  {
    std::abort();
  }
  for (const char c : out_whole)
  {
    const auto byte = static_cast<unsigned char>(c);
    if ((byte < 0x20 && c != '\n' && c != '\t') || byte >= 0x7F)
    {
      std::abort();
    }
  }
  if (!out_whole.empty() && (out_whole.front() != '%' || out_whole.back() != '\n'))
  {
    std::abort();
  }
  return 0;
}
