// Cutter radius compensation (G41/G42) in the XY plane, with the rules of the RS-274/NGC
// interpreter as LinuxCNC's rs274 applies them: the entry move after G41/G42 is a straight line
// that ends at the programmed end point offset by the radius square to it; along the contour each move is offset by the
// tool radius; an outside corner gets an arc of the tool radius round the programmed corner, an inside corner ends both
// offset moves where they cross; the move after G40 goes straight from the offset path to the programmed point. One
// move is held back, since its end depends on the next move.
#include <algorithm>
#include <cmath>
#include <string>

#include "cnc_bridge/gcode/gcode.h"
#include "gcode_internal.h"

namespace cnc_bridge
{
namespace gcode
{
namespace
{
constexpr double kEps = 1e-9;

struct Point
{
  double x, y;
};

// Crossings of the offset paths near a corner: line (p, direction d) or circle (c, r).
bool lineLine(Point p, Point d, Point q, Point e, Point& out)
{
  const double den = d.x * e.y - d.y * e.x;
  if (std::fabs(den) < 1e-12)
  {
    return false;
  }
  const double t = ((q.x - p.x) * e.y - (q.y - p.y) * e.x) / den;
  out = {p.x + t * d.x, p.y + t * d.y};
  return true;
}

int lineCircle(Point p, Point d, Point c, double r, Point out[2])
{
  const double fx = p.x - c.x, fy = p.y - c.y;
  const double a = d.x * d.x + d.y * d.y;
  const double b = 2 * (fx * d.x + fy * d.y);
  const double cc = fx * fx + fy * fy - r * r;
  double disc = b * b - 4 * a * cc;
  if (disc < 0)
  {
    if (disc < -1e-9 * (b * b + 1))
    {
      return 0;
    }
    disc = 0;
  }
  const double s = std::sqrt(disc);
  out[0] = {p.x + (-b - s) / (2 * a) * d.x, p.y + (-b - s) / (2 * a) * d.y};
  out[1] = {p.x + (-b + s) / (2 * a) * d.x, p.y + (-b + s) / (2 * a) * d.y};
  return 2;
}

int circleCircle(Point c1, double r1, Point c2, double r2, Point out[2])
{
  const double dx = c2.x - c1.x, dy = c2.y - c1.y;
  const double d = std::hypot(dx, dy);
  if (d < 1e-12)
  {
    return 0;
  }
  const double a = (r1 * r1 - r2 * r2 + d * d) / (2 * d);
  double h2 = r1 * r1 - a * a;
  if (h2 < 0)
  {
    if (h2 < -1e-9 * r1 * r1)
    {
      return 0;
    }
    h2 = 0;
  }
  const double h = std::sqrt(h2);
  const Point m{c1.x + a * dx / d, c1.y + a * dy / d};
  out[0] = {m.x - h * dy / d, m.y + h * dx / d};
  out[1] = {m.x + h * dy / d, m.y - h * dx / d};
  return 2;
}

// Unit tangent of an arc about c at p, in the direction of travel.
Point arcTangent(double cu, double cv, const Vec3& p, bool cw)
{
  const double rx = p.x - cu, ry = p.y - cv;
  const double r = std::hypot(rx, ry);
  return cw ? Point{ry / r, -rx / r} : Point{-ry / r, rx / r};
}

// The arc of the tool radius round an outside corner, from the held move's offset end to the next
// move's offset start, at the height of the former.
Arc outsideCornerArc(const Vec3& corner, double r, double side, const Vec3& from, const Vec3& to)
{
  Arc arc;
  arc.cu = corner.x;
  arc.cv = corner.y;
  arc.rs = arc.re = r;
  arc.cw = side > 0;  // on the left of a right turn the tool goes round clockwise
  arc.start = {from.x, from.y, from.z};
  arc.end = {to.x, to.y, from.z};
  arc.a0 = std::atan2(arc.start.y - arc.cv, arc.start.x - arc.cu);
  arc.sweep = sweepBetween(arc.a0, std::atan2(arc.end.y - arc.cv, arc.end.x - arc.cu), arc.cw, false);
  return arc;
}

// The next move's offset path: a line through its offset start along (tx, ty), or an arc about
// (cu, cv) of radius rad.
struct NextPath
{
  bool arc = false;
  double cu = 0.0, cv = 0.0, rad = 0.0;
  Point start{0.0, 0.0};
  Point tangent{0.0, 0.0};
};

// Inside corner: where the offset paths cross, the crossing nearest the corner's offset points.
// A held line's offset path is the programmed line moved by the radius: through its offset end
// along the programmed direction. For the entry move that is not the way the tool goes (from the
// uncompensated start), and rs274 intersects the offset line all the same.
Point insideCrossing(const Parser::Comp& comp, const NextPath& next, uint32_t line)
{
  const Point mid{(comp.end.x + next.start.x) / 2, (comp.end.y + next.start.y) / 2};
  Point candidates[2];
  int n = 0;
  const Point a0{comp.end.x, comp.end.y};
  const Point ad{comp.tx, comp.ty};
  if (!comp.held_arc && !next.arc)
  {
    n = lineLine(a0, ad, next.start, next.tangent, candidates[0]) ? 1 : 0;
  }
  else if (!comp.held_arc)
  {
    n = lineCircle(a0, ad, {next.cu, next.cv}, next.rad, candidates);
  }
  else if (!next.arc)
  {
    n = lineCircle(next.start, next.tangent, {comp.cu, comp.cv}, comp.rad, candidates);
  }
  else
  {
    n = circleCircle({comp.cu, comp.cv}, comp.rad, {next.cu, next.cv}, next.rad, candidates);
  }
  if (n == 0)
  {
    throw ParseError(line, 1,
                     "cutter compensation: the offset paths do not meet at the inside corner before this block (tool "
                     "radius " +
                         std::to_string(comp.radius) + " mm too large for the contour); use a smaller tool");
  }
  Point best = candidates[0];
  for (int k = 1; k < n; ++k)
  {
    if (std::hypot(candidates[k].x - mid.x, candidates[k].y - mid.y) < std::hypot(best.x - mid.x, best.y - mid.y))
    {
      best = candidates[k];
    }
  }
  return best;
}

// The held move, shortened to the crossing, must still go the way it went, not back behind its
// start (a gouge; rs274 checks the same, interp_queue.cc).
void checkNoGouge(const Parser::Comp& comp, const Point& crossing, uint32_t line)
{
  if (comp.held_arc)
  {
    return;
  }
  const double gx = comp.end.x - comp.start.x, gy = comp.end.y - comp.start.y;
  const double len2 = gx * gx + gy * gy;
  const double t = len2 > 0 ? ((crossing.x - comp.start.x) * gx + (crossing.y - comp.start.y) * gy) / len2 : 0.0;
  if (t < -1e-9)
  {
    throw ParseError(line, 1,
                     "cutter compensation: the tool (radius " + std::to_string(comp.radius) +
                         " mm) does not fit in the inside corner before this block (it would cut into the previous "
                         "move's contour); use a smaller tool");
  }
}
}  // namespace

void Parser::compensationOn(Step& st)
{
  // G41/G42 without an XY move: the next XY move is the entry move.
  if (st.comp.on && st.comp.has_held)
  {
    throw ParseError(st.line, st.motion_column ? st.motion_column : 1,
                     "G41/G42 while compensation is on: give G40 (and its exit move) first");
  }
}

void Parser::compensationOff(Step& st, bool program_end)
{
  Comp& comp = st.comp;
  if (!comp.on)
  {
    return;
  }
  if (comp.has_held)
  {
    emitHeld(st, comp);
    st.position.x = comp.end.x;  // the tool stays on the offset path
    st.position.y = comp.end.y;
  }
  comp = Comp();
  if (program_end)
  {
    st.next.cutter_comp = CutterComp::kOff;
  }
}

void Parser::emitHeld(Step& st, Comp& comp)
{
  Move m = comp.held;
  m.compensated = true;
  if (comp.held_arc)
  {
    Arc arc;
    arc.cu = comp.cu;
    arc.cv = comp.cv;
    arc.rs = arc.re = comp.rad;
    arc.cw = comp.held_cw;
    arc.start = comp.start;
    arc.end = comp.end;
    arc.a0 = std::atan2(comp.start.y - comp.cv, comp.start.x - comp.cu);
    const double a1 = std::atan2(comp.end.y - comp.cv, comp.end.x - comp.cu);
    const bool closed =
        comp.held_full && std::fabs(comp.start.x - comp.end.x) < kEps && std::fabs(comp.start.y - comp.end.y) < kEps;
    arc.sweep = sweepBetween(arc.a0, a1, comp.held_cw, closed);
    emitArc(st, m, arc);
  }
  else
  {
    m.start = comp.start;
    m.end = comp.end;
    if (m.start.x != m.end.x || m.start.y != m.end.y || m.start.z != m.end.z)
    {
      st.block.moves.push_back(m);
    }
  }
  for (Move q : comp.queued)
  {
    q.start = {comp.end.x, comp.end.y, q.start.z};
    q.end = {comp.end.x, comp.end.y, q.end.z};
    q.compensated = true;
    st.block.moves.push_back(q);
    comp.end.z = q.end.z;
  }
  comp.queued.clear();
  comp.has_held = false;
}

// Ends the held move at the corner with the next offset move (which starts at next_start, on the
// perpendicular of the programmed corner; moved to the crossing at an inside corner).
void Parser::joinHeld(Step& st, Comp& comp, bool next_arc, double ncu, double ncv, double nrad, bool ncw,
                      Vec3& next_start, double ntx, double nty, const Vec3& corner)
{
  const double r = comp.radius;
  const double cross = comp.tx * nty - comp.ty * ntx;
  const double dot = comp.tx * ntx + comp.ty * nty;
  const double gap = std::hypot(comp.end.x - next_start.x, comp.end.y - next_start.y);
  if (gap < 1e-7 || r <= 0.0)
  {
    next_start.x = comp.end.x;
    next_start.y = comp.end.y;
    emitHeld(st, comp);
    return;
  }
  // Turning away from the tool's side is an outside corner.
  const bool outside = comp.side * cross < 0 || (std::fabs(cross) < 1e-12 && dot < 0);
  if (outside)
  {
    const Vec3 corner_start = comp.end;
    Move round = comp.held;
    emitHeld(st, comp);
    const Arc arc = outsideCornerArc(corner, r, comp.side, corner_start, next_start);
    round.motion = arc.cw ? Motion::kArcCw : Motion::kArcCcw;
    round.line = st.line;
    round.block_number = st.block.block_number;
    round.feed_mm_per_min = st.next.feed_mm_per_min;
    round.compensated = true;
    emitArc(st, round, arc);
    next_start.z = corner_start.z;
    return;
  }
  // A nearly tangent inside corner (under 0.05 rad, LinuxCNC's TOLERANCE_CONCAVE_CORNER) is
  // joined as it is: the crossing would move the end by a fraction of a micrometre to a few.
  if (std::atan2(std::fabs(cross), dot) < 0.05)
  {
    next_start.x = comp.end.x;
    next_start.y = comp.end.y;
    next_start.z = comp.end.z;
    emitHeld(st, comp);
    return;
  }
  NextPath next;
  next.arc = next_arc;
  next.cu = ncu;
  next.cv = ncv;
  next.rad = nrad;
  next.start = {next_start.x, next_start.y};
  next.tangent = {ntx, nty};
  const Point best = insideCrossing(comp, next, st.line);
  checkNoGouge(comp, best, st.line);
  comp.end.x = best.x;
  comp.end.y = best.y;
  next_start.x = best.x;
  next_start.y = best.y;
  next_start.z = comp.end.z;
  emitHeld(st, comp);
  (void)ncw;
}

void Parser::compensationExit(Step& st, const Move& move)
{
  // G40: the exit move, straight from the offset path to the programmed point.
  Comp& comp = st.comp;
  Vec3 from = st.position;
  if (comp.on && comp.has_held)
  {
    emitHeld(st, comp);
    from = comp.end;
  }
  comp = Comp();
  Move m = move;
  m.start = from;
  if (m.start.x != m.end.x || m.start.y != m.end.y || m.start.z != m.end.z)
  {
    st.block.moves.push_back(m);
  }
  st.position = move.end;
}

void Parser::compensatedStraight(Step& st, const Move& move)
{
  Comp& comp = st.comp;
  const Vec3 target = move.end;
  const bool xy_moves = target.x != st.position.x || target.y != st.position.y;
  if (st.next.cutter_comp == CutterComp::kOff)
  {
    compensationExit(st, move);
    return;
  }
  if (!comp.on)
  {
    if (!xy_moves)
    {
      // Z before the entry move: not compensated yet.
      if (target.z != st.position.z)
      {
        st.block.moves.push_back(move);
      }
      st.position = target;
      return;
    }
    // The entry move: from the programmed point S straight to E offset by the radius square to
    // the entry move (LinuxCNC 2.9's rs274 and Fanuc's type A start-up end it there).
    comp.on = true;
    comp.side = st.next.cutter_comp == CutterComp::kLeft ? 1.0 : -1.0;
    comp.radius = st.next.comp_radius_mm;
    const double r = comp.radius;
    const Vec3 s = st.position;
    const double d = std::hypot(target.x - s.x, target.y - s.y);
    if (d <= r + 1e-9)
    {
      throw ParseError(st.line, st.motion_column ? st.motion_column : 1,
                       "cutter compensation entry move not longer than the tool radius (" + std::to_string(r) +
                           " mm): start the entry farther from the contour");
    }
    const double ux = (target.x - s.x) / d, uy = (target.y - s.y) / d;
    const Vec3 c{target.x - uy * comp.side * r, target.y + ux * comp.side * r, target.z};
    comp.has_held = true;
    comp.held = move;
    comp.held_arc = false;
    comp.start = s;
    comp.end = c;
    comp.programmed_end = target;
    comp.tx = ux;
    comp.ty = uy;
    st.position = target;
    return;
  }
  if (!xy_moves)
  {
    if (target.z != st.position.z)
    {
      if (comp.has_held)
      {
        comp.queued.push_back(move);
      }
      else
      {
        Move m = move;
        m.start = {comp.end.x, comp.end.y, st.position.z};
        m.end = {comp.end.x, comp.end.y, target.z};
        m.compensated = true;
        st.block.moves.push_back(m);
      }
    }
    st.position = target;
    return;
  }
  const double len = std::hypot(target.x - st.position.x, target.y - st.position.y);
  const double tx = (target.x - st.position.x) / len, ty = (target.y - st.position.y) / len;
  // Offset to the tool's side: the left normal of the direction (-ty, tx), times side.
  const double ox = -ty * comp.side * comp.radius, oy = tx * comp.side * comp.radius;
  Vec3 start{st.position.x + ox, st.position.y + oy, st.position.z};
  if (comp.has_held)
  {
    joinHeld(st, comp, false, 0, 0, 0, false, start, tx, ty, st.position);
  }
  comp.has_held = true;
  comp.held = move;
  comp.held_arc = false;
  comp.start = start;
  comp.end = {target.x + ox, target.y + oy, target.z};
  comp.programmed_end = target;
  comp.tx = tx;
  comp.ty = ty;
  st.position = target;
}

void Parser::compensatedArc(Step& st, const Move& move, const Arc& arc)
{
  Comp& comp = st.comp;
  const uint32_t column = st.motion_column ? st.motion_column : 1;
  if (st.next.cutter_comp == CutterComp::kOff)
  {
    throw ParseError(st.line, column, "the move after G40 (the exit from cutter compensation) must be a straight line");
  }
  if (!comp.on)
  {
    throw ParseError(st.line, column,
                     "the first move after G41/G42 (the entry into cutter compensation) must be a straight line");
  }
  if (arc.p.u != 0)
  {
    throw ParseError(st.line, column, "arc outside the XY plane with cutter compensation on");
  }
  // Offset radius: a counter-clockwise arc has its centre on the left, so G41 makes it smaller.
  const double grow = (arc.cw ? 1.0 : -1.0) * comp.side * comp.radius;
  const double rad = arc.rs + grow;
  if (rad <= 1e-9)
  {
    throw ParseError(st.line, column,
                     "cutter compensation: the tool radius (" + std::to_string(comp.radius) +
                         " mm) is larger than this arc's radius (" + std::to_string(arc.rs) +
                         " mm) on the inside; use a smaller tool");
  }
  const Point t0 = arcTangent(arc.cu, arc.cv, arc.start, arc.cw);
  const Point t1 = arcTangent(arc.cu, arc.cv, arc.end, arc.cw);
  auto offset_point = [&](const Vec3& p)
  {
    const double rx = p.x - arc.cu, ry = p.y - arc.cv;
    const double r = std::hypot(rx, ry);
    return Vec3{arc.cu + rx / r * rad, arc.cv + ry / r * rad, p.z};
  };
  Vec3 start = offset_point(arc.start);
  if (comp.has_held)
  {
    joinHeld(st, comp, true, arc.cu, arc.cv, rad, arc.cw, start, t0.x, t0.y, st.position);
  }
  comp.has_held = true;
  comp.held = move;
  comp.held_arc = true;
  comp.held_cw = arc.cw;
  comp.held_full = std::fabs(std::fabs(arc.sweep) - 2 * kPi) < 1e-9;
  comp.cu = arc.cu;
  comp.cv = arc.cv;
  comp.rad = rad;
  comp.start = start;
  comp.end = offset_point(arc.end);
  comp.programmed_end = arc.end;
  comp.tx = t1.x;
  comp.ty = t1.y;
  st.position = arc.end;
}

bool Parser::finish(Block& out)
{
  out.moves.clear();
  Step st{out, state_, position_, *comp_};
  st.line = line_;
  compensationOff(st, true);
  state_ = st.next;
  position_ = st.position;
  return !out.moves.empty();
}
}  // namespace gcode
}  // namespace cnc_bridge
