// Progress on stderr for long phases (reading a big file, building a tree), shown only to a person:
// when stderr is a terminal and the phase has already taken more than a second. Never anything when
// stderr is a file or a pipe, so scripts and tests see clean output.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace kdspace::cli {

/// Whether stderr is a terminal.
bool stderr_is_terminal();

class Progress {
 public:
  /// How the phase reports: with fractions through update() (a file read), or not at all, in which
  /// case a background ticker shows the time spent so far (a build).
  enum class Kind { fraction, elapsed };

  /// Starts the phase `label` ("reading base.fvecs").
  explicit Progress(std::string label, Kind kind = Kind::fraction);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// The fraction done, 0..1 (thread-safe).
  void update(double fraction);
  /// update() as a callback for io::read_points.
  std::function<void(double)> callback();
  /// Ends the phase; if anything was shown, leaves a final line. Called by the destructor too.
  void finish();

 private:
  using Clock = std::chrono::steady_clock;
  void draw(bool final_line);  // with mutex_ held
  double elapsed() const;

  std::string label_;
  bool enabled_;
  Clock::time_point start_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool finished_ = false;
  bool shown_ = false;
  int percent_ = -1;      // last percentage drawn; -1 none
  double fraction_ = -1;  // -1: not known
  std::thread ticker_;
};

}  // namespace kdspace::cli
