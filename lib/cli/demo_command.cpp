// `kdspace demo [--out DIR] [--threads T] [--quick]`: runs the demo steps in order, prints their
// tables, writes the report (and the steps' data) under DIR, and exits 1 if any check failed.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "demo.hpp"
#include "guard.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/version.hpp"
#include "options.hpp"

namespace kdspace::cli::demo {

void Context::report(const std::string& text) {
  report_ += text;
  std::fputs(text.c_str(), stdout);
  std::fflush(stdout);
}

std::string with_commas(double value) {
  std::string digits = std::to_string(static_cast<std::uint64_t>(std::llround(value)));
  for (std::size_t i = digits.size(); i > 3; i -= 3) digits.insert(i - 3, ",");
  return digits;
}

std::string fixed(double value, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, value);
  return buf;
}

void Context::fail(const std::string& what) {
  failures_.push_back(what);
  std::fprintf(stderr, "kdspace: demo: check failed: %s\n", what.c_str());
}

namespace {

// The steps, in the order they run. Each adds its own section to the report.
const std::vector<Step>& steps() {
  static const std::vector<Step> list = {
      {"point search", point_search_step},
      {"ray shooting", ray_shooting_step},
      {"collisions", collision_step},
  };
  return list;
}

const char* const demo_usage = R"(usage: kdspace demo [--out DIR] [--threads T] [--quick]
Runs the library on built-in generated data (fixed seed), checks every answer it can against brute
force, and prints a table.
  --out DIR     also write the generated base/query sets as .fvecs (to try 'kdspace knn' on) and the
                report (results.md) into DIR, created if missing
  --threads T   threads of the 'all threads' runs; 0 (default) = all hardware threads
  --quick       a tenth of every data set (about a second instead of ten)
Exit codes: 0 all checks passed, 1 a check failed or a file could not be written, 2 usage error.
)";

void write_report(Context& context) {
  const std::string path = context.out_path("results.md");
  std::ofstream out(path, std::ios::binary);
  out << context.report_text();
  out.close();
  if (!out) throw Error(path + ": cannot write the report");
  context.wrote(path);
}

int run_demo(const std::vector<std::string>& args) {
  if (wants_help(args)) {
    std::fputs(demo_usage, stdout);
    return 0;
  }
  const Options o(args, {{"--out"}, {"--threads"}, {"--quick", false}});
  Settings settings;
  settings.out_dir = o.text("--out");
  settings.threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  settings.quick = o.has("--quick");
  if (!settings.out_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(settings.out_dir, ec);
    if (ec) throw Error(settings.out_dir + ": cannot create the folder: " + ec.message());
  }

  Context context(settings);
  context.report("# kdspace " + std::string(version) + " demo" + (settings.quick ? " (quick)" : "") + "\n\n");
  for (const Step& step : steps()) step.run(context);

  if (!settings.out_dir.empty()) {
    write_report(context);
    std::printf("files written:\n");
    for (const std::string& f : context.files()) std::printf("  %s\n", f.c_str());
  }
  if (!context.failures().empty()) {
    std::fprintf(stderr, "kdspace: error: demo: %zu check(s) failed\n", context.failures().size());
    return 1;
  }
  std::printf("all checks passed\n");
  return 0;
}

}  // namespace
}  // namespace kdspace::cli::demo

int run_demo_command(const std::vector<std::string>& args) {
  return kdspace::cli::run_guarded("demo", [&] { return kdspace::cli::demo::run_demo(args); });
}
