#include "progress.hpp"

#include <unistd.h>

#include <cstdio>
#include <utility>

namespace kdspace::cli {

namespace {
constexpr double show_after_s = 1.0;  // a phase shorter than this shows nothing
}

bool stderr_is_terminal() {
  return isatty(STDERR_FILENO) != 0;
}

Progress::Progress(std::string label, Kind kind)
    : label_(std::move(label)), enabled_(stderr_is_terminal()), start_(Clock::now()) {
  if (!enabled_ || kind != Kind::elapsed) return;
  ticker_ = std::thread([this] {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!finished_) {
      wake_.wait_for(lock, std::chrono::milliseconds(250));
      if (!finished_ && elapsed() > show_after_s) draw(false);
    }
  });
}

Progress::~Progress() {
  finish();
}

double Progress::elapsed() const {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

void Progress::update(double fraction) {
  if (!enabled_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  fraction_ = fraction < 0 ? 0 : (fraction > 1 ? 1 : fraction);
  const int percent = static_cast<int>(fraction_ * 100);
  if (percent != percent_ && elapsed() > show_after_s) draw(false);
}

std::function<void(double)> Progress::callback() {
  return [this](double fraction) { update(fraction); };
}

void Progress::finish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (shown_) draw(true);
  }
  wake_.notify_all();
  if (ticker_.joinable()) ticker_.join();
}

void Progress::draw(bool final_line) {
  const double seconds = elapsed();
  if (fraction_ >= 0) {
    percent_ = static_cast<int>(fraction_ * 100);
    std::fprintf(stderr, "\r%s %3d%%", label_.c_str(), percent_);
    if (final_line) std::fprintf(stderr, " (%.1f s)", seconds);
  } else {
    std::fprintf(stderr, "\r%s %.1f s", label_.c_str(), seconds);
  }
  if (final_line) std::fputc('\n', stderr);
  std::fflush(stderr);
  shown_ = true;
}

}  // namespace kdspace::cli
