#include "kdspace/io/pairs.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "kdspace/error.hpp"

namespace kdspace::io {
namespace {

void put_le(unsigned char* out, std::uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out[i] = static_cast<unsigned char>(value >> (8 * i));
}

// A temporary file next to `path`, removed unless committed by renaming it to `path`.
class TemporaryFile {
 public:
  // Created like any new file (mode 0666 less the umask), under a name no other writer uses.
  explicit TemporaryFile(const std::string& path) : path_(path) {
    static std::atomic<unsigned> counter{0};
    int fd = -1;
    for (int attempt = 0; attempt < 100 && fd < 0; ++attempt) {
      temp_ = path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
      fd = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
      if (fd < 0 && errno != EEXIST) break;
    }
    if (fd < 0) throw Error(path + ": cannot create a temporary file next to it: " + std::strerror(errno));
    file_ = ::fdopen(fd, "wb");
    if (!file_) {
      ::close(fd);
      ::unlink(temp_.c_str());
      throw Error(path + ": cannot open for writing: " + std::strerror(errno));
    }
  }
  ~TemporaryFile() {
    if (file_) std::fclose(file_);
    if (!committed_) ::unlink(temp_.c_str());
  }
  TemporaryFile(const TemporaryFile&) = delete;
  TemporaryFile& operator=(const TemporaryFile&) = delete;

  void write(const unsigned char* data, std::size_t n) {
    if (n > 0 && std::fwrite(data, 1, n, file_) != n) fail("write failed");
  }

  void commit() {
    const bool flushed = std::fflush(file_) == 0;
    const int error = errno;
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    if (!flushed || !closed) fail("write failed", flushed ? errno : error);
    if (std::rename(temp_.c_str(), path_.c_str()) != 0) fail("cannot replace the file");
    committed_ = true;
  }

 private:
  [[noreturn]] void fail(const std::string& what, int error = errno) const {
    throw Error(path_ + ": " + what + ": " + std::strerror(error));
  }

  std::string path_, temp_;
  std::FILE* file_ = nullptr;
  bool committed_ = false;
};

}  // namespace

void write_pairs(const std::string& path, const std::vector<IndexPair>& pairs) {
  TemporaryFile file(path);
  unsigned char header[8];
  put_le(header, pairs.size(), 8);
  file.write(header, sizeof header);
  constexpr std::size_t records_per_chunk = 8192;
  std::vector<unsigned char> chunk(records_per_chunk * 8);
  for (std::size_t first = 0; first < pairs.size(); first += records_per_chunk) {
    const std::size_t count = std::min(records_per_chunk, pairs.size() - first);
    for (std::size_t i = 0; i < count; ++i) {
      put_le(chunk.data() + i * 8, pairs[first + i].a, 4);
      put_le(chunk.data() + i * 8 + 4, pairs[first + i].b, 4);
    }
    file.write(chunk.data(), count * 8);
  }
  file.commit();
}

}  // namespace kdspace::io
