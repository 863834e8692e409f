// `kdspace demo`: a list of steps, each of which exercises one part of the library on generated
// data, checks its answers and adds its own markdown table to the report. A new part of the library
// joins the demo by adding one step to the list in demo_command.cpp.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace kdspace::cli::demo {

struct Settings {
  bool quick = false;    ///< a tenth of every data set (for tests)
  unsigned threads = 0;  ///< threads of the "all threads" runs; 0 = all hardware threads
  std::string out_dir;   ///< where data sets and results are written; empty = nowhere
};

/// What the steps share: the settings, the report they add to, and the failed checks.
class Context {
 public:
  explicit Context(Settings s) : settings(std::move(s)) {}

  const Settings settings;

  /// Adds text to the report and prints it on stdout at once.
  void report(const std::string& text);
  /// Records a failed check (printed on stderr now, and counted for the exit code).
  void fail(const std::string& what);
  /// Notes a file written to the output folder (listed at the end).
  void wrote(const std::string& path) { files_.push_back(path); }

  const std::string& report_text() const { return report_; }
  const std::vector<std::string>& failures() const { return failures_; }
  const std::vector<std::string>& files() const { return files_; }
  /// settings.out_dir + "/" + name.
  std::string out_path(const std::string& name) const { return settings.out_dir + "/" + name; }

 private:
  std::string report_;
  std::vector<std::string> failures_;
  std::vector<std::string> files_;
};

struct Step {
  const char* name;
  void (*run)(Context&);
};

/// 1234567 -> "1,234,567" (rounded to a whole number).
std::string with_commas(double value);
/// value with `decimals` digits after the point.
std::string fixed(double value, int decimals);

/// Exact k-NN and radius search with PointTree on three generated data sets (demo_points.cpp).
void point_search_step(Context& context);

/// BoxTree builds, closest-hit tracing checked against brute force, and a rendered picture
/// (demo_rays.cpp).
void ray_shooting_step(Context& context);

/// All overlapping pairs, moving boxes (MovingScene), overlap queries and first contacts checked
/// against brute force, and under --out a picture of colliding boxes (demo_collide.cpp).
void collision_step(Context& context);

}  // namespace kdspace::cli::demo
