// Files of fixed-size little-endian records after a uint64 count (.boxes, .rays, .hits, .pairs):
// reading with the count checked against the file's size before anything is allocated, and writing
// atomically.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "kdspace/error.hpp"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "kdspace's record files are copied straight between little-endian files and memory"
#endif

namespace kdspace::io::detail {

[[noreturn]] inline void fail(const std::string& path, const std::string& what) {
  throw Error(path + ": " + what);
}

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

/// Opens `path` and returns its record count, checked against the file's size ("truncated: header
/// says 100 boxes (2408 bytes), file has 1000 bytes"); `noun` names a record in messages. A file of
/// zero bytes is an error; a count of 0 is a valid, empty file.
std::uint64_t open_and_count(const std::string& path, File& file, std::uint64_t record_bytes,
                             const char* noun);

/// A file written under a temporary name in the same folder and renamed over `path` by commit(), so
/// that `path` is never seen half written and an old file of that name survives a failed write.
/// Without commit() the temporary is removed.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  /// Writes bytes; throws Error "PATH: write error: ..." on failure.
  void write(const void* data, std::size_t bytes);
  /// Closes and renames; throws Error on failure (and removes the temporary).
  void commit();

 private:
  std::string path_, temporary_;
  std::FILE* file_ = nullptr;
};

template <class Record>
std::vector<Record> read_records(const std::string& path, const char* noun) {
  File file;
  const std::uint64_t count = open_and_count(path, file, sizeof(Record), noun);
  std::vector<Record> records(static_cast<std::size_t>(count));
  if (count > 0 && std::fread(records.data(), sizeof(Record), records.size(), file.get()) != records.size())
    fail(path, "read error");
  return records;
}

template <class Record>
void write_records(const std::string& path, const Record* records, std::size_t n) {
  if (n > 0 && records == nullptr) fail(path, "nothing to write: null pointer");
  AtomicFile out(path);
  const std::uint64_t count = n;
  out.write(&count, sizeof count);
  if (n > 0) out.write(records, n * sizeof(Record));
  out.commit();
}

}  // namespace kdspace::io::detail
