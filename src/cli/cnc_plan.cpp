// cnc_plan: dry-runs a path for the '@' controller without ROS or a controller. It reads a G-code
// program or a point list, plans it exactly as at_controller_node's follow_path does (the same
// planProgram, Trajectory and TrajectoryStream: a program is split into operations at its own
// M00, M01, G04, M02/M30 and, with --program-commands, at spindle, coolant and tool changes), and
// writes the 1 ms setpoints of every operation in order as CSV, optionally a PNG of position,
// velocity, acceleration and jerk per axis with the limits drawn, and prints the operations, the
// total time and the worst ratio to the limits. The CSV's time runs on through G04 dwells; a stop
// (M00, M01) adds no time, since it lasts until the operator resumes.
//
//   cnc_plan (--gcode FILE | --points FILE) [--profile trapezoid|scurve] [--max-speed X,Y,Z]
//            [--max-accel X,Y,Z] [--max-jerk X,Y,Z] [--path-tolerance MM] [--period S] [--corner-share F]
//            [--feed MM_S] [--start X,Y,Z] [--dialect haas|fanuc|linuxcnc] [--tool-table FILE]
//            [--program-commands true|false] [--csv FILE] [--png FILE]
// Units: mm, mm/s, mm/s^2, mm/s^3, s (the node's parameters are the same numbers in metres).
// A point list has one point a line, "x y z [feed]" in mm (feed in mm/s for the segment to it).
#include <unistd.h>
#include <array>

#include <algorithm>
#include <boost/program_options.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/program_path.h"
#include "cnc_bridge/common/error.h"

namespace po = boost::program_options;
namespace ap = cnc_bridge::at_protocol;
using cnc_bridge::ConfigError;

namespace
{
ap::Vec3 triple(const std::string& text, const char* name)
{
  ap::Vec3 v{};
  std::istringstream in(text);
  char comma = 0;
  if (!(in >> v[0] >> comma >> v[1] >> comma >> v[2]) || comma != ',')
  {
    throw ConfigError(std::string("--") + name + " takes three numbers X,Y,Z, not '" + text + "'");
  }
  return v;
}

void readPoints(const std::string& path, double fallback_feed, ap::OperationPlan& plan)
{
  std::ifstream in(path);
  if (!in)
  {
    throw ConfigError("cannot read " + path);
  }
  std::string line;
  int number = 0;
  while (std::getline(in, line))
  {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#')
    {
      continue;
    }
    std::istringstream words(line);
    double x, y, z, feed = fallback_feed;
    if (!(words >> x >> y >> z))
    {
      throw ConfigError(path + " line " + std::to_string(number) + ": needs x y z [feed] in mm (mm/s)");
    }
    words >> feed;
    plan.points.push_back({x * ap::kPulsesPerMm, y * ap::kPulsesPerMm, z * ap::kPulsesPerMm});
    plan.feeds.push_back(feed);
  }
}

// scripts/plot_plan.py: installed beside this program, or in the source tree of a build.
std::string plotScript()
{
  char self[4096];
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (n > 0)
  {
    std::string dir(self, static_cast<size_t>(n));
    dir.resize(dir.rfind('/') + 1);
    if (std::ifstream(dir + "plot_plan.py").good())
    {
      return dir + "plot_plan.py";
    }
  }
  return CNC_PLAN_PLOT_SCRIPT;
}

struct Limits
{
  double speed = 0, accel = 0, jerk = 0;
};

po::options_description commandLine()
{
  po::options_description options("cnc_plan: plan an '@' path into 1 ms setpoints (CSV, PNG)");
  options.add_options()("help,h", "this text")("gcode", po::value<std::string>(), "G-code program")(
      "points", po::value<std::string>(), "point list: x y z [feed] per line, mm (mm/s)")(
      "profile", po::value<std::string>()->default_value("trapezoid"), "trapezoid or scurve")(
      "max-speed", po::value<std::string>()->default_value("50,50,25"), "mm/s per axis")(
      "max-accel", po::value<std::string>()->default_value("500,500,250"), "mm/s^2 per axis")(
      "max-jerk", po::value<std::string>()->default_value("10000,10000,5000"), "mm/s^3 per axis")(
      "path-tolerance", po::value<double>()->default_value(0.01),
      "mm the scurve profile may pass from a corner (0: stop on every corner)")(
      "period", po::value<double>()->default_value(0.001), "s between setpoints")(
      "corner-share", po::value<double>()->default_value(0.2), "acceleration kept for corners")(
      "feed", po::value<double>()->default_value(10.0), "mm/s when the program gives no F")(
      "start", po::value<std::string>()->default_value("0,0,0"), "mm, where the path starts")(
      "dialect", po::value<std::string>()->default_value("haas"), "haas, fanuc or linuxcnc")(
      "tool-table", po::value<std::string>(), "LinuxCNC .tbl or .yaml for G41/G42")(
      "program-commands", po::value<bool>()->default_value(true),
      "the program's spindle, coolant and tool words become controller commands (as the node's "
      "~program_commands; false refuses such programs, as the node does by default)")(
      "csv", po::value<std::string>(), "write the setpoints here")("png", po::value<std::string>(),
                                                                   "write a plot here (python3-matplotlib)");
  return options;
}

ap::PlannerLimits readLimits(const po::variables_map& vm)
{
  ap::PlannerLimits limits;
  limits.max_speed = triple(vm["max-speed"].as<std::string>(), "max-speed");
  limits.max_accel = triple(vm["max-accel"].as<std::string>(), "max-accel");
  limits.max_jerk = triple(vm["max-jerk"].as<std::string>(), "max-jerk");
  limits.period = vm["period"].as<double>();
  limits.corner_share = vm["corner-share"].as<double>();
  limits.path_tolerance = vm["path-tolerance"].as<double>();
  const std::string profile = vm["profile"].as<std::string>();
  if (profile != "trapezoid" && profile != "scurve")
  {
    throw ConfigError("--profile must be trapezoid or scurve, not '" + profile + "'");
  }
  limits.profile = profile == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
  limits.validate();
  return limits;
}

// The operations of the program (split as the node splits them) or the one of the point list.
std::vector<ap::OperationPlan> readPlans(const po::variables_map& vm, const ap::Vec3& start)
{
  const double feed = vm["feed"].as<double>();
  std::vector<ap::OperationPlan> plans;
  if (vm.count("gcode"))
  {
    cnc_bridge::gcode::ParserOptions parser;
    parser.dialect = cnc_bridge::gcode::parseDialect(vm["dialect"].as<std::string>());
    if (vm.count("tool-table"))
    {
      parser.tool_table = std::make_shared<cnc_bridge::gcode::ToolTable>(
          cnc_bridge::gcode::ToolTable::load(vm["tool-table"].as<std::string>()));
    }
    const std::string path = vm["gcode"].as<std::string>();
    std::ifstream in(path);
    if (!in)
    {
      throw ConfigError("cannot read " + path);
    }
    // As follow_path with feed_rate 0: the program's F words, else the default feed.
    ap::ProgramPlanOptions options;
    options.fallback_feed = feed;
    options.program_commands = vm["program-commands"].as<bool>();
    options.program_commands_setting = "--program-commands";
    plans = ap::planProgram(in, parser, options, start);
  }
  else
  {
    plans.emplace_back().points.push_back(start);
    readPoints(vm["points"].as<std::string>(), feed, plans.back());
  }
  return plans;
}

// Streams the setpoints of every operation in order, as the node sends them, and keeps their
// velocity, acceleration and jerk (from the setpoints' exact positions: the controller gets whole
// pulses; these are what the planner asks of each axis) against the limits, writing them as CSV
// when asked. Every operation starts and ends at rest, so the differences run on from one
// operation into the next.
class SetpointWalk
{
 public:
  SetpointWalk(const ap::PlannerLimits& limits, const ap::Vec3& start) : limits_(limits), dt_(limits.period), p1_(start)
  {
    for (double& c : p1_)
    {
      c = std::round(c);
    }
  }

  void openCsv(const std::string& path)
  {
    csv_.open(path);
    if (!csv_)
    {
      throw ConfigError("cannot write " + path);
    }
    csv_ << "t_s,x_pulses,y_pulses,z_pulses,feed_x,feed_y,feed_z,x_mm,y_mm,z_mm,vx_mm_s,vy_mm_s,vz_mm_s,"
            "ax_mm_s2,ay_mm_s2,az_mm_s2,jx_mm_s3,jy_mm_s3,jz_mm_s3,operation\n";
    csv_.precision(10);
  }

  void closeCsv(const std::string& path)
  {
    if (csv_.is_open())
    {
      csv_.close();
      if (!csv_)
      {
        throw ConfigError("writing " + path + " failed");
      }
    }
  }

  // Streams every operation; prints the step each one ends with.
  void walk(std::vector<ap::OperationPlan>& plans, std::vector<ap::Trajectory>& trajectories)
  {
    for (operation_ = 0; operation_ < trajectories.size(); ++operation_)
    {
      const size_t operation_segments = trajectories[operation_].segments().size();
      segments_ += operation_segments;
      length_ += trajectories[operation_].length();
      if (plans[operation_].moves())  // as the node: an operation without moves sends nothing
      {
        streamOperation(std::move(trajectories[operation_]));
      }
      if (const auto& after = plans[operation_].after)
      {
        std::printf("operation %zu: %zu segments, then %s\n", operation_ + 1, operation_segments,
                    after->describe().c_str());
        if (after->kind == cnc_bridge::gcode::ProgramStep::Kind::kDwell)
        {
          dwell_s_ += after->dwell_s;
          t_ = static_cast<double>(k_) * dt_ + dwell_s_;
        }
      }
    }
  }

  const Limits& worst() const { return worst_; }
  size_t setpoints() const { return k_; }
  size_t segments() const { return segments_; }
  double length() const { return length_; }
  double time() const { return t_; }
  double dwellTime() const { return dwell_s_; }

 private:
  void streamOperation(ap::Trajectory trajectory)
  {
    ap::TrajectoryStream stream(std::move(trajectory));
    ap::Setpoint sp;
    while (stream.next(sp))
    {
      ++k_;
      t_ = static_cast<double>(k_) * dt_ + dwell_s_;
      account(stream.current().position, &sp);
    }
    // At rest after the last setpoint: the deceleration into rest counts too.
    account(p1_, nullptr);
    account(p1_, nullptr);
  }

  void account(const ap::Vec3& p, const ap::Setpoint* setpoint)
  {
    ap::Vec3 v, a, j;
    for (int i = 0; i < 3; ++i)
    {
      v[i] = (p[i] - p1_[i]) / dt_ / ap::kPulsesPerMm;
      a[i] = (v[i] - v1_[i]) / dt_;
      j[i] = (a[i] - a1_[i]) / dt_;
      worst_.speed = std::max(worst_.speed, std::fabs(v[i]) / limits_.max_speed[i]);
      worst_.accel = std::max(worst_.accel, std::fabs(a[i]) / limits_.max_accel[i]);
      worst_.jerk = std::max(worst_.jerk, std::fabs(j[i]) / limits_.max_jerk[i]);
    }
    if (csv_.is_open() && setpoint)
    {
      writeRow(p, *setpoint, {&v, &a, &j});
    }
    p1_ = p;
    v1_ = v;
    a1_ = a;
  }

  void writeRow(const ap::Vec3& p, const ap::Setpoint& setpoint, const std::array<const ap::Vec3*, 3>& derivatives)
  {
    csv_ << t_ << ',' << setpoint.position[0] << ',' << setpoint.position[1] << ',' << setpoint.position[2] << ','
         << setpoint.feed[0] << ',' << setpoint.feed[1] << ',' << setpoint.feed[2];
    for (int i = 0; i < 3; ++i)
    {
      csv_ << ',' << p[i] / ap::kPulsesPerMm;
    }
    for (const ap::Vec3* q : derivatives)
    {
      for (int i = 0; i < 3; ++i)
      {
        csv_ << ',' << (*q)[i];
      }
    }
    csv_ << ',' << operation_ << '\n';
  }

  const ap::PlannerLimits& limits_;
  const double dt_;
  std::ofstream csv_;
  ap::Vec3 p1_, v1_{}, a1_{};
  Limits worst_;
  size_t k_ = 0;
  double t_ = 0.0, dwell_s_ = 0.0;  // s: setpoints so far and G04 dwells between operations
  size_t operation_ = 0;
  size_t segments_ = 0;
  double length_ = 0.0;
};

void printSummary(const std::string& profile, const ap::PlannerLimits& limits,
                  const std::vector<ap::OperationPlan>& plans, const SetpointWalk& walk, double plan_s, double stream_s)
{
  const Limits& worst = walk.worst();
  const double worst_ratio =
      std::max({worst.speed, worst.accel, limits.profile == ap::Profile::kSCurve ? worst.jerk : 0.0});
  // Operations without moves (a spindle or coolant change after the last cut) send nothing.
  const auto operations_sent =
      static_cast<size_t>(std::count_if(plans.begin(), plans.end(), [](const auto& p) { return p.moves(); }));
  const size_t segments = walk.segments();
  const size_t k = walk.setpoints();
  std::printf(
      "%s: %zu operations, %zu segments, %.3f mm, %zu setpoints, total time %.3f s (%.3f s of it G04 "
      "dwells; stops not counted)\n",
      profile.c_str(), operations_sent, segments, walk.length() / ap::kPulsesPerMm, k, walk.time(), walk.dwellTime());
  std::printf("worst limit ratio %.4f (speed %.4f, acceleration %.4f, jerk %.4f%s)\n", worst_ratio, worst.speed,
              worst.accel, worst.jerk, limits.profile == ap::Profile::kSCurve ? "" : ", not limited by a trapezoid");
  std::printf("planning %.3f s (%.0f segments/s), setpoints %.3f s (%.0f setpoints/s)\n", plan_s,
              plan_s > 0 ? segments / plan_s : 0.0, stream_s, stream_s > 0 ? k / stream_s : 0.0);
}

void plot(const std::string& csv, const std::string& png, const ap::PlannerLimits& limits)
{
  std::ostringstream command;
  command << "/usr/bin/python3 '" << plotScript() << "' '" << csv << "' '" << png << "' " << limits.max_speed[0] << ','
          << limits.max_speed[1] << ',' << limits.max_speed[2] << ' ' << limits.max_accel[0] << ','
          << limits.max_accel[1] << ',' << limits.max_accel[2] << ' ' << limits.max_jerk[0] << ',' << limits.max_jerk[1]
          << ',' << limits.max_jerk[2];
  if (std::system(command.str().c_str()) != 0)
  {
    throw ConfigError("the plot failed (python3-matplotlib installed?): " + command.str());
  }
}

int run(int argc, char** argv)
{
  const po::options_description options = commandLine();
  po::variables_map vm;
  po::store(po::parse_command_line(argc, argv, options), vm);
  if (vm.count("help"))
  {
    std::cout << options << "\n";
    return 0;
  }
  po::notify(vm);
  if (vm.count("gcode") == vm.count("points"))
  {
    throw ConfigError("give exactly one of --gcode and --points");
  }
  const ap::PlannerLimits limits = readLimits(vm);

  const auto t0 = std::chrono::steady_clock::now();
  const ap::Vec3 mm = triple(vm["start"].as<std::string>(), "start");
  const ap::Vec3 start{mm[0] * ap::kPulsesPerMm, mm[1] * ap::kPulsesPerMm, mm[2] * ap::kPulsesPerMm};
  std::vector<ap::OperationPlan> plans = readPlans(vm, start);
  std::vector<ap::Trajectory> trajectories;
  for (ap::OperationPlan& plan : plans)
  {
    ap::roundToPulses(plan);
    trajectories.emplace_back(plan.points, plan.feeds, limits);
  }
  const auto t1 = std::chrono::steady_clock::now();

  SetpointWalk walk(limits, start);
  const std::string csv = vm.count("csv") ? vm["csv"].as<std::string>() : std::string();
  if (vm.count("csv"))
  {
    walk.openCsv(csv);
  }
  walk.walk(plans, trajectories);
  const auto t2 = std::chrono::steady_clock::now();
  walk.closeCsv(csv);

  printSummary(vm["profile"].as<std::string>(), limits, plans, walk, std::chrono::duration<double>(t1 - t0).count(),
               std::chrono::duration<double>(t2 - t1).count());
  if (vm.count("png"))
  {
    if (!vm.count("csv"))
    {
      throw ConfigError("--png needs --csv (the plot is drawn from it)");
    }
    plot(csv, vm["png"].as<std::string>(), limits);
  }
  return 0;
}
}  // namespace

int main(int argc, char** argv)
{
  try
  {
    return run(argc, argv);
  }
  catch (const std::exception& e)
  {
    std::fprintf(stderr, "cnc_plan: %s\n", e.what());
    return 1;
  }
}
