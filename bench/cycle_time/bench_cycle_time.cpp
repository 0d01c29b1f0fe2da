// bench_cycle_time: the time to cycle end that cell_monitor predicts (cnc_bridge/cell/cycle_time.h,
// a cycle profile of scalar limits) against the cycle the simulated '@' controller runs for the
// same program: the setpoints at_controller_node streams to sim_at_controller (planProgram, one
// Trajectory per operation, TrajectoryStream: one setpoint per period, the S-curve's window
// included) plus the program's dwells, with the machine's own per-axis limits. Prints one line per
// program (predicted, machine, |error| / machine cycle) and the median and p90 of that ratio; a
// program either side cannot plan is listed with the reason, not counted.
//
//   bench_cycle_time [--machine-speed X,Y,Z] [--machine-accel X,Y,Z] [--machine-profile trapezoid|scurve]
//                    [--rapid-rate MM_S] [--max-feed MM_S] [--acceleration MM_S2] PROGRAM...
// Dialect per file: "fanuc" in its name: fanuc; .ngc: linuxcnc; else haas. A tool table beside it
// (same name, .tbl) is used by both sides.
#include <algorithm>
#include <boost/program_options.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/program_path.h"
#include "cnc_bridge/cell/cycle_time.h"
#include "cnc_bridge/common/error.h"

namespace po = boost::program_options;
namespace ap = cnc_bridge::at_protocol;
namespace gc = cnc_bridge::gcode;
using cnc_bridge::ConfigError;

namespace
{
ap::Vec3 triple(const std::string& text)
{
  ap::Vec3 v{};
  char comma = 0;
  std::istringstream in(text);
  if (!(in >> v[0] >> comma >> v[1] >> comma >> v[2]))
    throw ConfigError("three numbers X,Y,Z expected, not '" + text + "'");
  return v;
}

gc::ParserOptions parserFor(const std::string& path)
{
  gc::ParserOptions options;
  const std::string base = path.substr(path.rfind('/') + 1);
  options.dialect = base.find("fanuc") != std::string::npos                     ? gc::Dialect::kFanuc
                    : base.size() > 4 && base.substr(base.size() - 4) == ".ngc" ? gc::Dialect::kLinuxCnc
                                                                                : gc::Dialect::kHaas;
  const std::string table = path.substr(0, path.rfind('.')) + ".tbl";
  if (std::ifstream(table).good())
    options.tool_table = std::make_shared<gc::ToolTable>(gc::ToolTable::load(table));
  return options;
}

// The simulated '@' controller's cycle: every setpoint it is streamed, one per period, and the dwells.
double machineCycle(const std::string& path, const gc::ParserOptions& parser, const ap::PlannerLimits& limits)
{
  std::ifstream in(path);
  ap::ProgramPlanOptions options;
  options.program_commands = true;
  std::vector<ap::OperationPlan> plans = ap::planProgram(in, parser, options, ap::Vec3{});
  double seconds = 0.0;
  for (ap::OperationPlan& plan : plans)
  {
    ap::roundToPulses(plan);
    if (plan.moves())
    {
      const ap::TrajectoryStream stream(ap::Trajectory(plan.points, plan.feeds, limits));
      seconds += static_cast<double>(stream.total()) * limits.period;
    }
    if (plan.after && plan.after->kind == gc::ProgramStep::Kind::kDwell)
      seconds += plan.after->dwell_s;
  }
  return seconds;
}

double predicted(const std::string& path, const gc::ParserOptions& parser, cnc_bridge::cell::CycleProfile profile)
{
  std::ifstream in(path);
  profile.dialect = parser.dialect;
  profile.tool_table = parser.tool_table;
  return cnc_bridge::cell::CyclePlan::plan(in, profile, path).total();
}

double quantile(std::vector<double> values, double q)
{
  std::sort(values.begin(), values.end());
  const double position = q * static_cast<double>(values.size() - 1);  // linear between neighbours
  const size_t below = static_cast<size_t>(std::floor(position));
  const size_t above = std::min(values.size() - 1, below + 1);
  return values[below] + (position - static_cast<double>(below)) * (values[above] - values[below]);
}

int run(int argc, char** argv)
{
  po::options_description description("bench_cycle_time options");
  description.add_options()("help,h", "this text")("machine-speed", po::value<std::string>()->default_value("50,50,25"),
                                                   "mm/s per axis of the '@' machine")(
      "machine-accel", po::value<std::string>()->default_value("500,500,250"), "mm/s^2 per axis of the machine")(
      "machine-profile", po::value<std::string>()->default_value("trapezoid"), "trapezoid or scurve")(
      "rapid-rate", po::value<double>()->default_value(50.0), "mm/s per axis, the prediction's profile")(
      "max-feed", po::value<double>()->default_value(50.0), "mm/s, the prediction's profile")(
      "acceleration", po::value<double>()->default_value(500.0), "mm/s^2 per axis, the prediction's profile")(
      "programs", po::value<std::vector<std::string>>()->default_value({}, ""), "programs");
  po::positional_options_description positional;
  positional.add("programs", -1);
  po::variables_map vm;
  po::store(po::command_line_parser(argc, argv).options(description).positional(positional).run(), vm);
  if (vm.count("help"))
  {
    std::ostringstream text;
    text << description;
    std::printf("%s\n", text.str().c_str());
    return 0;
  }
  po::notify(vm);
  ap::PlannerLimits limits;
  limits.max_speed = triple(vm["machine-speed"].as<std::string>());
  limits.max_accel = triple(vm["machine-accel"].as<std::string>());
  limits.profile = vm["machine-profile"].as<std::string>() == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
  limits.validate();
  cnc_bridge::cell::CycleProfile profile;
  profile.rapid_rate = vm["rapid-rate"].as<double>();
  profile.max_feed = vm["max-feed"].as<double>();
  profile.acceleration = vm["acceleration"].as<double>();
  profile.corner_share = limits.corner_share;

  std::vector<double> errors;
  for (const std::string& path : vm["programs"].as<std::vector<std::string>>())
  {
    const std::string name = path.substr(path.rfind('/') + 1);
    try
    {
      const gc::ParserOptions parser = parserFor(path);
      const double machine = machineCycle(path, parser, limits);
      const double prediction = predicted(path, parser, profile);
      const double error = machine > 0.0 ? std::fabs(prediction - machine) / machine : 0.0;
      errors.push_back(error);
      std::printf("%-44s predicted %10.3f s  machine %10.3f s  |error|/cycle %.4f\n", name.c_str(), prediction, machine,
                  error);
    }
    catch (const std::exception& e)
    {
      std::printf("%-44s not planned: %s\n", name.c_str(), e.what());
    }
  }
  if (errors.empty())
  {
    std::printf("no program planned on both sides\n");
    return 1;
  }
  std::printf("%zu programs: |error| / machine cycle median %.4f, p90 %.4f, worst %.4f\n", errors.size(),
              quantile(errors, 0.5), quantile(errors, 0.9), *std::max_element(errors.begin(), errors.end()));
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
    std::fprintf(stderr, "bench_cycle_time: %s\n", e.what());
    return 2;
  }
}
