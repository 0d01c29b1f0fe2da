// Cross-check of the G-code parser against LinuxCNC's rs274 (Debian linuxcnc-uspace), the
// descendant of the NIST RS274/NGC interpreter: every program in test/data/gcode/rs274/ is run
// through `rs274 -g` and through gcode::Reader, and every move must end at the same point within
// 0.001 mm. Arcs must also turn about the same centre the same way: each of our chord ends lies at
// the radius rs274's centre gives it (start radius to end radius, linearly). rs274 prints program
// coordinates (its G92 and G5x offsets printed beside them are added back) with four decimals in the
// program's units, so inch programs are compared within that print resolution (0.00005 in =
// 0.00127 mm) plus 0.001 mm.
//
// A program's first comment lines may say how it is read:
//   (cross-check: dialect=haas)            our parser's dialect (default linuxcnc)
//   (cross-check: tool_table=tools.tbl)    for G41/G42, given to both (rs274 reads it in inches)
//   (cross-check: peck_clearance=0.254)    G73/G83 clearance for our side (LinuxCNC's 0.010 in)
//   (cross-check: rs274_drop=G187,G103)    lines with these words are blanked for rs274 (Haas-only
//                                          hints that do not change the path)
//   (cross-check: rs274_append=M2)         a line added at the end of rs274's copy
//   (cross-check: rule=...)                where the dialects differ: which rule each side follows
// A program copied verbatim from elsewhere keeps these lines in a sidecar file beside it,
// PROGRAM.crosscheck (one directive a line, same spelling).
#include <dirent.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>

#include "cnc_bridge/gcode/gcode.h"
#include "temp_dir.h"

using namespace cnc_bridge::gcode;

namespace
{
const std::string kCorpus = CNC_BRIDGE_FIXTURE_DIR "/rs274";
const std::string kCamCorpus = CNC_BRIDGE_FIXTURE_DIR "/cam";

enum class Kind
{
  kTraverse,
  kFeed,
  kArc
};
const char* name(Kind k)
{
  return k == Kind::kTraverse ? "traverse" : (k == Kind::kFeed ? "feed" : "arc");
}

struct Canon
{
  Kind kind;
  Vec3 end;
  bool has_centre = false;
  Vec3 centre;                   // rs274: in the arc's plane (the normal axis left 0)
  Plane plane = Plane::kXY;      // rs274: the arc's plane
  double rotation = 0;           // rs274: turns, positive counterclockwise about the plane's normal
  Vec3 start;                    // ours: where the arc starts
  std::vector<Vec3> chord_ends;  // ours: every chord's end point
  uint32_t line = 0;
  std::string text;
};

std::vector<double> numbers(const std::string& text, size_t open)
{
  std::vector<double> out;
  std::istringstream in(text.substr(open + 1));
  std::string item;
  while (std::getline(in, item, ','))
  {
    out.push_back(std::strtod(item.c_str(), nullptr));
  }
  return out;
}

struct Rs274Result
{
  std::vector<Canon> moves;
  std::string error;  // what rs274 said if it stopped on an error
};

// \p home: rs274 keeps its tool data in $HOME/.tool.mmap, shared by every rs274 of that HOME
// (LinuxCNC 2.9's tool data memory map): two runs at once, of this test or of anything else,
// would read each other's tool table. Each run gets a HOME of its own.
Rs274Result runRs274(const std::string& program, const std::string& tool_table, const std::string& home)
{
  Rs274Result result;
  std::string command = "HOME='" + home + "' rs274 -g";
  if (!tool_table.empty())
  {
    command += " -t '" + tool_table + "'";
  }
  command += " '" + program + "' </dev/null 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command.c_str(), "r"), pclose);
  if (!pipe)
  {
    result.error = "cannot run rs274";
    return result;
  }
  double scale = 1.0;
  Vec3 g92, g5x;
  Plane plane = Plane::kXY;
  Vec3 last{0, 0, 0};
  char buffer[4096];
  while (fgets(buffer, sizeof buffer, pipe.get()))
  {
    std::string text(buffer);
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r'))
    {
      text.pop_back();
    }
    const size_t open = text.find('(');
    // Canonical lines: "   12 N..... NAME(...)" or "   12 N100   NAME(...)" (the block's N).
    size_t at = text.find_first_not_of(' ');
    const bool canonical = at != std::string::npos && std::isdigit(static_cast<unsigned char>(text[at])) &&
                           text.find(" N", at) != std::string::npos && open != std::string::npos;
    if (!canonical)
    {
      if (text != "executing" && !text.empty())
      {
        result.error += text + "\n";
      }
      continue;
    }
    auto has = [&](const char* word) { return text.find(word) != std::string::npos; };
    if (has("USE_LENGTH_UNITS("))
    {
      scale = has("CANON_UNITS_INCHES") ? 25.4 : 1.0;
    }
    else if (has("SET_G92_OFFSET("))
    {
      const auto v = numbers(text, open);
      g92 = {v[0] * scale, v[1] * scale, v[2] * scale};
    }
    else if (has("SET_G5X_OFFSET("))
    {
      const auto v = numbers(text, open);
      g5x = {v[1] * scale, v[2] * scale, v[3] * scale};
    }
    else if (has("SELECT_PLANE("))
    {
      plane = has("CANON_PLANE_XZ") ? Plane::kZX : (has("CANON_PLANE_YZ") ? Plane::kYZ : Plane::kXY);
    }
    else if (has("STRAIGHT_TRAVERSE(") || has("STRAIGHT_FEED(") || has("ARC_FEED("))
    {
      const auto v = numbers(text, open);
      Canon c;
      c.text = text;
      auto base = [&](double x, double y, double z) {
        return Vec3{x * scale + g92.x + g5x.x, y * scale + g92.y + g5x.y, z * scale + g92.z + g5x.z};
      };
      if (has("ARC_FEED("))
      {
        c.kind = Kind::kArc;
        c.has_centre = true;
        c.plane = plane;
        c.rotation = v[4];
        // ARC_FEED(first_end, second_end, first_centre, second_centre, rotation, axis_end, ...):
        // XY (x, y, .., z), XZ (z, x, .., y), YZ (y, z, .., x).
        if (plane == Plane::kXY)
        {
          c.end = base(v[0], v[1], v[5]);
          c.centre = base(v[2], v[3], 0);
          c.centre.z = 0;
        }
        else if (plane == Plane::kZX)
        {
          c.end = base(v[1], v[5], v[0]);
          c.centre = base(v[3], 0, v[2]);
          c.centre.y = 0;
        }
        else
        {
          c.end = base(v[5], v[0], v[1]);
          c.centre = base(0, v[2], v[3]);
          c.centre.x = 0;
        }
      }
      else
      {
        c.kind = has("STRAIGHT_TRAVERSE(") ? Kind::kTraverse : Kind::kFeed;
        c.end = base(v[0], v[1], v[2]);
        // rs274 prints moves that go nowhere (a G28 intermediate point equal to the current one).
        if (std::fabs(c.end.x - last.x) < 1e-9 && std::fabs(c.end.y - last.y) < 1e-9 &&
            std::fabs(c.end.z - last.z) < 1e-9)
        {
          continue;
        }
      }
      last = c.end;
      result.moves.push_back(c);
    }
  }
  return result;
}

// Axis values of a point in a plane's (u, v) axes: XY (x, y), ZX (z, x), YZ (y, z), as rs274 prints them.
void inPlane(const Vec3& p, Plane plane, double& u, double& v)
{
  u = plane == Plane::kXY ? p.x : (plane == Plane::kZX ? p.z : p.y);
  v = plane == Plane::kXY ? p.y : (plane == Plane::kZX ? p.x : p.z);
}

// How far our arc strays from rs274's: the largest difference between a chord end's distance from
// rs274's centre and the radius it should have there (start radius to end radius, linearly, as both
// interpolators turn a slightly inconsistent arc into a spiral). A circumcentre of our chord ends
// would be ill-conditioned for short arcs; this is not. Sets `turns_same_way` from the first chord.
double arcError(const Canon& mine, const Canon& reference, bool& turns_same_way)
{
  double cu, cv, su, sv, eu, ev;
  inPlane(reference.centre, reference.plane, cu, cv);
  inPlane(mine.start, reference.plane, su, sv);
  inPlane(mine.end, reference.plane, eu, ev);
  const double rs = std::hypot(su - cu, sv - cv);
  const double re = std::hypot(eu - cu, ev - cv);
  const size_t n = mine.chord_ends.size();
  double worst = 0;
  for (size_t k = 0; k < n; ++k)
  {
    double pu, pv;
    inPlane(mine.chord_ends[k], reference.plane, pu, pv);
    const double expected = rs + (re - rs) * static_cast<double>(k + 1) / static_cast<double>(n);
    worst = std::max(worst, std::fabs(std::hypot(pu - cu, pv - cv) - expected));
  }
  turns_same_way = true;
  if (n > 0)
  {
    double pu, pv;
    inPlane(mine.chord_ends[0], reference.plane, pu, pv);
    const double cross = (su - cu) * (pv - cv) - (sv - cv) * (pu - cu);
    if (std::fabs(cross) > 1e-9)
    {
      turns_same_way = (cross > 0) == (reference.rotation > 0);
    }
  }
  return worst;
}

struct Directives
{
  ParserOptions options;
  std::string tool_table;
  std::vector<std::string> rs274_drop;
  std::vector<std::string> rs274_append;
  std::vector<std::string> rules;
};

void readDirectivesFrom(const std::string& path, const std::string& dir, Directives& d);

// Directives from the program's own comments, then from its sidecar file if there is one.
Directives readDirectives(const std::string& path, const std::string& dir)
{
  Directives d;
  d.options.dialect = Dialect::kLinuxCnc;
  readDirectivesFrom(path, dir, d);
  readDirectivesFrom(path + ".crosscheck", dir, d);
  return d;
}

void readDirectivesFrom(const std::string& path, const std::string& dir, Directives& d)
{
  std::ifstream in(path);
  std::string line;
  const std::string tag = "(cross-check: ";
  while (std::getline(in, line))
  {
    const size_t at = line.find(tag);
    if (at == std::string::npos)
    {
      continue;
    }
    std::string body = line.substr(at + tag.size());
    body = body.substr(0, body.rfind(')'));
    const std::string key = body.substr(0, body.find('='));
    const std::string value = body.substr(body.find('=') + 1);
    if (key == "dialect")
    {
      d.options.dialect = parseDialect(value);
    }
    else if (key == "tool_table")
    {
      d.tool_table = dir + "/" + value;
      // rs274 without an ini file reads a tool table in inches: so do we here.
      d.options.tool_table = std::make_shared<ToolTable>(ToolTable::load(d.tool_table, Units::kInches));
    }
    else if (key == "peck_clearance")
    {
      d.options.peck_clearance_mm = std::stod(value);
    }
    else if (key == "rs274_drop")
    {
      std::istringstream words(value);
      std::string w;
      while (std::getline(words, w, ','))
      {
        d.rs274_drop.push_back(w);
      }
    }
    else if (key == "rs274_append")
    {
      d.rs274_append.push_back(value);
    }
    else if (key == "rule")
    {
      d.rules.push_back(value);
    }
  }
}

std::vector<Canon> ours(const std::string& path, const ParserOptions& options)
{
  std::ifstream in(path, std::ios::binary);
  Reader reader(in, options);
  std::vector<Canon> out;
  std::vector<Move> arc;
  auto flushArc = [&]()
  {
    const Move& last = arc.back();
    Canon c;
    c.kind = Kind::kArc;
    c.end = last.end;
    c.line = last.line;
    c.start = arc.front().start;
    for (const Move& chord : arc)
    {
      c.chord_ends.push_back(chord.end);
    }
    out.push_back(c);
    arc.clear();
  };
  while (const Block* block = reader.nextBlock())
  {
    for (const Move& m : block->moves)
    {
      if (m.motion == Motion::kArcCw || m.motion == Motion::kArcCcw)
      {
        arc.push_back(m);
        if (m.segment + 1 == m.segment_count)
        {
          flushArc();
        }
        continue;
      }
      Canon c;
      c.kind = m.motion == Motion::kRapid ? Kind::kTraverse : Kind::kFeed;
      c.end = m.end;
      c.line = m.line;
      out.push_back(c);
    }
  }
  return out;
}

double distance(const Vec3& a, const Vec3& b)
{
  return std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z));
}

std::vector<std::string> programsIn(const std::string& dir)
{
  std::vector<std::string> files;
  if (DIR* d = opendir(dir.c_str()))
  {
    while (dirent* e = readdir(d))
    {
      const std::string n = e->d_name;
      auto ends = [&n](const std::string& tail)
      { return n.size() > tail.size() && n.compare(n.size() - tail.size(), tail.size(), tail) == 0; };
      if (ends(".ngc") || ends(".nc") || ends(".gcode"))
      {
        files.push_back(n);
      }
    }
    closedir(d);
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Compares one program; returns the number of moves compared.
size_t crossCheck(const std::string& dir, const std::string& file, cnc_bridge::test::TempDir& tmp)
{
  SCOPED_TRACE(file);
  const std::string path = dir + "/" + file;
  const Directives d = readDirectives(path, dir);
  for (const std::string& rule : d.rules)
  {
    std::cout << "  " << file << ": " << rule << "\n";
  }
  std::string rs274_path = path;
  if (!d.rs274_drop.empty() || !d.rs274_append.empty())
  {
    std::ifstream in(path);
    rs274_path = tmp.file(file);
    std::ofstream out(rs274_path);
    std::string line;
    while (std::getline(in, line))
    {
      std::string upper = line;
      for (char& ch : upper)
      {
        ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
      }
      bool drop = false;
      for (const std::string& w : d.rs274_drop)
      {
        drop = drop || upper.find(w) != std::string::npos;
      }
      out << (drop ? "" : line) << "\n";
    }
    for (const std::string& extra : d.rs274_append)
    {
      out << extra << "\n";
    }
  }
  // Without a table of its own, rs274 would take tool lengths from somewhere: give it tools 0-99 of
  // length 0, so that G43 changes nothing there either (our parser leaves offsets to the control).
  std::string table = d.tool_table;
  if (table.empty())
  {
    table = tmp.file("zero_length.tbl");
    std::ofstream out(table);
    for (int t = 1; t < 100; ++t)
    {
      out << "T" << t << " P" << t << " Z0 D0\n";
    }
  }
  const Rs274Result reference = runRs274(rs274_path, table, tmp.path);
  EXPECT_EQ(reference.error, "") << "rs274 refused the program";
  std::vector<Canon> mine;
  try
  {
    mine = ours(path, d.options);
  }
  catch (const std::exception& e)
  {
    ADD_FAILURE() << "cnc_bridge refused the program: " << e.what();
    return 0;
  }
  EXPECT_EQ(mine.size(), reference.moves.size());
  // Two empty lists agree vacuously: every program of the corpus moves somewhere, so a side that
  // produced no move (rs274 not run, a parser that dropped everything) fails here.
  EXPECT_GT(reference.moves.size(), 0u) << "rs274 printed no move";
  EXPECT_GT(mine.size(), 0u) << "cnc_bridge produced no move";
  const double tolerance = 0.001 + 0.00005 * 25.4;  // inch programs: rs274 prints 0.0001 in
  const size_t n = std::min(mine.size(), reference.moves.size());
  size_t bad = 0;
  for (size_t k = 0; k < n && bad < 5; ++k)
  {
    const Canon& a = mine[k];
    const Canon& b = reference.moves[k];
    const double end_error = distance(a.end, b.end);
    const bool kind_ok = a.kind == b.kind;
    bool turns_same_way = true;
    const double arc_error = kind_ok && b.has_centre ? arcError(a, b, turns_same_way) : 0.0;
    if (!kind_ok || end_error > tolerance || arc_error > tolerance || !turns_same_way)
    {
      ++bad;
      ADD_FAILURE() << "move " << k << " (our line " << a.line << "): ours " << name(a.kind) << " to " << a.end.x << " "
                    << a.end.y << " " << a.end.z << ", rs274 " << b.text << " (" << b.end.x << " " << b.end.y << " "
                    << b.end.z << "), end error " << end_error << " mm, off rs274's arc by " << arc_error << " mm"
                    << (turns_same_way ? "" : ", turning the other way");
    }
  }
  return n;
}
}  // namespace

TEST(GcodeRs274, FeatureProgramsGiveTheSameMovesAsLinuxCnc)
{
  cnc_bridge::test::TempDir tmp;
  const auto files = programsIn(kCorpus);
  ASSERT_GE(files.size(), 8u) << "corpus missing in " << kCorpus;
  size_t moves = 0;
  for (const std::string& file : files)
  {
    moves += crossCheck(kCorpus, file, tmp);
  }
  std::cout << files.size() << " programs, " << moves << " moves compared with rs274\n";
}

TEST(GcodeRs274, CamProgramsGiveTheSameMovesAsLinuxCnc)
{
  cnc_bridge::test::TempDir tmp;
  const auto files = programsIn(kCamCorpus);
  ASSERT_GE(files.size(), 1u) << "corpus missing in " << kCamCorpus;
  size_t moves = 0;
  for (const std::string& file : files)
  {
    moves += crossCheck(kCamCorpus, file, tmp);
  }
  std::cout << files.size() << " CAM programs, " << moves << " moves compared with rs274\n";
}
