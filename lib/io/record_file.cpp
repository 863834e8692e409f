#include "record_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <limits>
#include <system_error>

namespace kdspace::io::detail {

namespace {

constexpr std::uint64_t header_bytes = 8;

}  // namespace

std::uint64_t open_and_count(const std::string& path, File& file, std::uint64_t record_bytes,
                             const char* noun) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory");
  file.reset(std::fopen(path.c_str(), "rb"));
  if (!file) fail(path, std::string("cannot open: ") + std::strerror(errno));
  if (std::fseek(file.get(), 0, SEEK_END) != 0) fail(path, "cannot seek (not a regular file?)");
  const long end = std::ftell(file.get());
  if (end < 0) fail(path, "cannot tell the file size (not a regular file?)");
  std::rewind(file.get());
  const auto size = static_cast<std::uint64_t>(end);
  if (size == 0) fail(path, std::string("empty file: expected a uint64 count of ") + noun);
  if (size < header_bytes)
    fail(path,
         "truncated header: " + std::to_string(size) + " bytes, expected " + std::to_string(header_bytes));
  unsigned char head[header_bytes];
  if (std::fread(head, 1, header_bytes, file.get()) != header_bytes) fail(path, "read error in the header");
  std::uint64_t count = 0;
  std::memcpy(&count, head, sizeof count);
  const std::uint64_t payload = size - header_bytes;
  // Compare by division first: count * record_bytes may overflow for a corrupt header.
  if (count > payload / record_bytes || count * record_bytes != payload) {
    const bool fits = count <= (std::numeric_limits<std::uint64_t>::max() - header_bytes) / record_bytes;
    const std::string expected = fits ? " (" + std::to_string(header_bytes + count * record_bytes) + " bytes)"
                                      : std::string(" (too many)");
    const std::string says = "header says " + std::to_string(count) + " " + noun + expected + ", file has " +
                             std::to_string(size) + " bytes";
    if (count > payload / record_bytes) fail(path, "truncated: " + says);
    fail(path,
         "oversized: " + says + " (" + std::to_string(payload - count * record_bytes) + " bytes too many)");
  }
  if (count > std::numeric_limits<std::size_t>::max() / record_bytes) fail(path, "file too large");
  return count;
}

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  // A name no other writer uses: the process id and a counter ("x" makes fopen refuse an existing
  // file rather than share it).
  static std::atomic<unsigned> counter{0};
  temporary_ = path_ + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  file_ = std::fopen(temporary_.c_str(), "wbx");
  if (!file_) fail(path_, std::string("cannot open for writing: ") + std::strerror(errno));
}

AtomicFile::~AtomicFile() {
  if (file_) {
    std::fclose(file_);
    std::remove(temporary_.c_str());
  }
}

void AtomicFile::write(const void* data, std::size_t bytes) {
  if (std::fwrite(data, 1, bytes, file_) != bytes)
    fail(path_, std::string("write error: ") + std::strerror(errno));
}

void AtomicFile::commit() {
  std::FILE* f = file_;
  file_ = nullptr;
  const bool closed = std::fclose(f) == 0;
  const int close_errno = errno;
  if (!closed || std::rename(temporary_.c_str(), path_.c_str()) != 0) {
    const int error = closed ? errno : close_errno;
    std::remove(temporary_.c_str());
    fail(path_, std::string("write error: ") + std::strerror(error));
  }
}

}  // namespace kdspace::io::detail
