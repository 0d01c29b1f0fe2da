// cnc_plan: dry-runs a path for the '@' controller without ROS or a controller. It reads a G-code
// program or a point list, plans it exactly as at_controller_node's follow_path does (the same
// appendProgram, Trajectory and TrajectoryStream), and writes the 1 ms setpoints as CSV, optionally
// a PNG of position, velocity, acceleration and jerk per axis with the limits drawn, and prints the
// total time and the worst ratio to the limits.
//
//   cnc_plan (--gcode FILE | --points FILE) [--profile trapezoid|scurve] [--max-speed X,Y,Z]
//            [--max-accel X,Y,Z] [--max-jerk X,Y,Z] [--period S] [--corner-share F] [--feed MM_S]
//            [--start X,Y,Z] [--dialect haas|fanuc|linuxcnc] [--tool-table FILE]
//            [--csv FILE] [--png FILE]
// Units: mm, mm/s, mm/s^2, mm/s^3, s (the node's parameters are the same numbers in metres).
// A point list has one point a line, "x y z [feed]" in mm (feed in mm/s for the segment to it).
#include <unistd.h>
#include <array>

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

void readPoints(const std::string& path, double fallback_feed, ap::PathPlan& plan)
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

int run(int argc, char** argv)
{
  po::options_description options("cnc_plan: plan an '@' path into 1 ms setpoints (CSV, PNG)");
  options.add_options()("help,h", "this text")("gcode", po::value<std::string>(), "G-code program")(
      "points", po::value<std::string>(), "point list: x y z [feed] per line, mm (mm/s)")(
      "profile", po::value<std::string>()->default_value("trapezoid"), "trapezoid or scurve")(
      "max-speed", po::value<std::string>()->default_value("50,50,25"), "mm/s per axis")(
      "max-accel", po::value<std::string>()->default_value("500,500,250"), "mm/s^2 per axis")(
      "max-jerk", po::value<std::string>()->default_value("10000,10000,5000"), "mm/s^3 per axis")(
      "period", po::value<double>()->default_value(0.001), "s between setpoints")(
      "corner-share", po::value<double>()->default_value(0.2), "acceleration kept for corners")(
      "feed", po::value<double>()->default_value(10.0), "mm/s when the program gives no F")(
      "start", po::value<std::string>()->default_value("0,0,0"), "mm, where the path starts")(
      "dialect", po::value<std::string>()->default_value("haas"), "haas, fanuc or linuxcnc")(
      "tool-table", po::value<std::string>(), "LinuxCNC .tbl or .yaml for G41/G42")(
      "csv", po::value<std::string>(), "write the setpoints here")("png", po::value<std::string>(),
                                                                   "write a plot here (python3-matplotlib)");
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

  ap::PlannerLimits limits;
  limits.max_speed = triple(vm["max-speed"].as<std::string>(), "max-speed");
  limits.max_accel = triple(vm["max-accel"].as<std::string>(), "max-accel");
  limits.max_jerk = triple(vm["max-jerk"].as<std::string>(), "max-jerk");
  limits.period = vm["period"].as<double>();
  limits.corner_share = vm["corner-share"].as<double>();
  const std::string profile = vm["profile"].as<std::string>();
  if (profile != "trapezoid" && profile != "scurve")
  {
    throw ConfigError("--profile must be trapezoid or scurve, not '" + profile + "'");
  }
  limits.profile = profile == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
  limits.validate();

  const auto t0 = std::chrono::steady_clock::now();
  ap::PathPlan plan;
  const ap::Vec3 start = triple(vm["start"].as<std::string>(), "start");
  plan.points.push_back({start[0] * ap::kPulsesPerMm, start[1] * ap::kPulsesPerMm, start[2] * ap::kPulsesPerMm});
  const double feed = vm["feed"].as<double>();
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
    ap::appendProgram(in, parser, 0.0, feed, plan);
  }
  else
  {
    readPoints(vm["points"].as<std::string>(), feed, plan);
  }
  ap::roundToPulses(plan);
  const ap::Trajectory trajectory(plan.points, plan.feeds, limits);
  const auto t1 = std::chrono::steady_clock::now();

  std::ofstream csv;
  if (vm.count("csv"))
  {
    csv.open(vm["csv"].as<std::string>());
    if (!csv)
    {
      throw ConfigError("cannot write " + vm["csv"].as<std::string>());
    }
    csv << "t_s,x_pulses,y_pulses,z_pulses,feed_x,feed_y,feed_z,x_mm,y_mm,z_mm,vx_mm_s,vy_mm_s,vz_mm_s,"
           "ax_mm_s2,ay_mm_s2,az_mm_s2,jx_mm_s3,jy_mm_s3,jz_mm_s3\n";
    csv.precision(10);
  }
  // Velocity, acceleration and jerk from the setpoints' exact positions (the controller gets
  // whole pulses; these are what the planner asks of each axis).
  ap::TrajectoryStream stream(trajectory);
  const double dt = limits.period;
  ap::Vec3 p1 = stream.current().position, v1{}, a1{};
  Limits worst;
  ap::Setpoint sp;
  size_t k = 0;
  auto account = [&](const ap::Vec3& p, const ap::Setpoint* setpoint)
  {
    ap::Vec3 v, a, j;
    for (int i = 0; i < 3; ++i)
    {
      v[i] = (p[i] - p1[i]) / dt / ap::kPulsesPerMm;
      a[i] = (v[i] - v1[i]) / dt;
      j[i] = (a[i] - a1[i]) / dt;
      worst.speed = std::max(worst.speed, std::fabs(v[i]) / limits.max_speed[i]);
      worst.accel = std::max(worst.accel, std::fabs(a[i]) / limits.max_accel[i]);
      worst.jerk = std::max(worst.jerk, std::fabs(j[i]) / limits.max_jerk[i]);
    }
    if (csv.is_open() && setpoint)
    {
      csv << k * dt << ',' << setpoint->position[0] << ',' << setpoint->position[1] << ',' << setpoint->position[2]
          << ',' << setpoint->feed[0] << ',' << setpoint->feed[1] << ',' << setpoint->feed[2];
      for (int i = 0; i < 3; ++i)
      {
        csv << ',' << p[i] / ap::kPulsesPerMm;
      }
      for (const ap::Vec3* q : std::array<const ap::Vec3*, 3>{&v, &a, &j})
      {
        for (int i = 0; i < 3; ++i)
        {
          csv << ',' << (*q)[i];
        }
      }
      csv << '\n';
    }
    p1 = p;
    v1 = v;
    a1 = a;
  };
  while (stream.next(sp))
  {
    ++k;
    account(stream.current().position, &sp);
  }
  // At rest after the last setpoint: the deceleration into rest counts too.
  account(p1, nullptr);
  account(p1, nullptr);
  const auto t2 = std::chrono::steady_clock::now();
  if (csv.is_open())
  {
    csv.close();
    if (!csv)
    {
      throw ConfigError("writing " + vm["csv"].as<std::string>() + " failed");
    }
  }

  const double plan_s = std::chrono::duration<double>(t1 - t0).count();
  const double stream_s = std::chrono::duration<double>(t2 - t1).count();
  const size_t segments = trajectory.segments().size();
  const double worst_ratio =
      std::max({worst.speed, worst.accel, limits.profile == ap::Profile::kSCurve ? worst.jerk : 0.0});
  std::printf("%s: %zu segments, %.3f mm, %zu setpoints, total time %.3f s\n", profile.c_str(), segments,
              trajectory.length() / ap::kPulsesPerMm, k, static_cast<double>(k) * dt);
  std::printf("worst limit ratio %.4f (speed %.4f, acceleration %.4f, jerk %.4f%s)\n", worst_ratio, worst.speed,
              worst.accel, worst.jerk, limits.profile == ap::Profile::kSCurve ? "" : ", not limited by a trapezoid");
  std::printf("planning %.3f s (%.0f segments/s), setpoints %.3f s (%.0f setpoints/s)\n", plan_s,
              plan_s > 0 ? segments / plan_s : 0.0, stream_s, stream_s > 0 ? k / stream_s : 0.0);

  if (vm.count("png"))
  {
    if (!vm.count("csv"))
    {
      throw ConfigError("--png needs --csv (the plot is drawn from it)");
    }
    std::ostringstream command;
    command << "/usr/bin/python3 '" << plotScript() << "' '" << vm["csv"].as<std::string>() << "' '"
            << vm["png"].as<std::string>() << "' " << limits.max_speed[0] << ',' << limits.max_speed[1] << ','
            << limits.max_speed[2] << ' ' << limits.max_accel[0] << ',' << limits.max_accel[1] << ','
            << limits.max_accel[2] << ' ' << limits.max_jerk[0] << ',' << limits.max_jerk[1] << ','
            << limits.max_jerk[2];
    if (std::system(command.str().c_str()) != 0)
    {
      throw ConfigError("the plot failed (python3-matplotlib installed?): " + command.str());
    }
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
