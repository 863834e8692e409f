// Tests of .pairs files (kdspace/io/pairs.hpp): round trips, one test per malformed file checking that
// the message names the file, the record and the problem, and atomic writing.
#include <catch2/catch.hpp>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/pairs.hpp"
#include "support.hpp"

namespace fs = std::filesystem;
using Catch::StartsWith;
using kdspace::IndexPair;
namespace io = kdspace::io;

namespace {

class TempDir : public kdspace_test::ScratchDir {
 public:
  TempDir() : ScratchDir("kdspace-pairs-io-test-") {}
};

/// Writes a hand-made file: a uint64 header, then uint32 values, then `extra` zero bytes.
void write_raw(const std::string& path, std::uint64_t header, const std::vector<std::uint32_t>& values,
               std::size_t extra = 0) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(&header), sizeof header);
  out.write(reinterpret_cast<const char*>(values.data()),
            static_cast<std::streamsize>(values.size() * sizeof(std::uint32_t)));
  for (std::size_t i = 0; i < extra; ++i) out.put('\0');
}

/// Files in the folder (to see that no temporary was left behind).
std::vector<std::string> listing(const std::string& folder) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder)) names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

TEST_CASE("pairs io: pairs round-trip, including the largest ids", "[io][pairs]") {
  TempDir dir;
  const std::vector<IndexPair> pairs = {{0, 1}, {0, 7}, {3, 4}, {3, 4294967295u}, {4294967294u, 4294967295u}};
  const std::string path = dir.file("a.pairs");
  io::write_pairs(path, pairs);
  CHECK(io::read_pairs(path) == pairs);
  CHECK(fs::file_size(path) == 8 + 8 * pairs.size());
  io::write_pairs(path, std::vector<IndexPair>{});
  CHECK(io::read_pairs(path).empty());
  CHECK(fs::file_size(path) == 8);
}

TEST_CASE("pairs io: the file is little-endian uint64 M, then (uint32 a, uint32 b) records", "[io][pairs]") {
  TempDir dir;
  const std::string path = dir.file("hand.pairs");
  write_raw(path, 2, {1, 2, 1, 3});
  CHECK(io::read_pairs(path) == std::vector<IndexPair>{{1, 2}, {1, 3}});
}

TEST_CASE("pairs io: empty, cut and oversized files are errors naming the sizes", "[io][pairs][errors]") {
  TempDir dir;
  const std::string path = dir.file("bad.pairs");
  { std::ofstream(path, std::ios::binary); }
  CHECK_THROWS_WITH(io::read_pairs(path), path + ": empty file: expected a uint64 count of pairs");
  {
    std::ofstream out(path, std::ios::binary);
    out.write("\x01\x00\x00", 3);
  }
  CHECK_THROWS_WITH(io::read_pairs(path), path + ": truncated header: 3 bytes, expected 8");
  write_raw(path, 3, {0, 1, 0, 2});
  CHECK_THROWS_WITH(io::read_pairs(path),
                    path + ": truncated: header says 3 pairs (32 bytes), file has 24 bytes");
  write_raw(path, 1, {0, 1}, 5);
  CHECK_THROWS_WITH(
      io::read_pairs(path),
      path + ": oversized: header says 1 pairs (16 bytes), file has 21 bytes (5 bytes too many)");
  write_raw(path, std::numeric_limits<std::uint64_t>::max(), {0, 1});
  CHECK_THROWS_WITH(io::read_pairs(path),
                    StartsWith(path + ": truncated: header says 18446744073709551615 pairs"));
}

TEST_CASE("pairs io: pairs out of order or repeated name the pair, 1-based", "[io][pairs][errors]") {
  TempDir dir;
  const std::string path = dir.file("order.pairs");
  io::write_pairs(path, std::vector<IndexPair>{{0, 1}, {5, 7}, {5, 3}});
  CHECK_THROWS_WITH(
      io::read_pairs(path),
      path + ": pair 3: (5, 3) is not after (5, 7) (pairs must be sorted by (a, b), each once)");
  io::write_pairs(path, std::vector<IndexPair>{{2, 4}, {2, 4}});
  CHECK_THROWS_WITH(io::read_pairs(path), StartsWith(path + ": pair 2: (2, 4) is not after (2, 4)"));
}

TEST_CASE("pairs io: missing files and folders are errors naming the path", "[io][pairs][errors]") {
  TempDir dir;
  const std::string missing = dir.file("missing.pairs");
  CHECK_THROWS_WITH(io::read_pairs(missing), StartsWith(missing + ": cannot open"));
  fs::create_directories(dir.file("folder.pairs"));
  CHECK_THROWS_WITH(io::read_pairs(dir.file("folder.pairs")), dir.file("folder.pairs") + ": is a directory");
  const std::string unwritable = dir.file("no/such/folder/out.pairs");
  CHECK_THROWS_WITH(io::write_pairs(unwritable, std::vector<IndexPair>{{0, 1}}),
                    StartsWith(unwritable + ": cannot open for writing"));
}

TEST_CASE("pairs io: writing is atomic: no temporary is left, an old file is replaced whole", "[io][pairs]") {
  TempDir dir;
  const std::string path = dir.file("out.pairs");
  io::write_pairs(path, std::vector<IndexPair>{{0, 1}, {1, 2}});
  io::write_pairs(path, std::vector<IndexPair>{{4, 5}});
  CHECK(io::read_pairs(path) == std::vector<IndexPair>{{4, 5}});
  CHECK(listing(dir.file("")) == std::vector<std::string>{"out.pairs"});
  // A folder where the file should go: the rename fails, the temporary is removed, the folder stays.
  fs::create_directories(dir.file("taken.pairs/inside"));
  CHECK_THROWS_WITH(io::write_pairs(dir.file("taken.pairs"), std::vector<IndexPair>{{0, 1}}),
                    StartsWith(dir.file("taken.pairs") + ": write error"));
  CHECK(listing(dir.file("")) == std::vector<std::string>{"out.pairs", "taken.pairs"});
}
