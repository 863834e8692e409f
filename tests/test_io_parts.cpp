// Reading a point file in parts (io::plan_part, io::read_part; kdspace-mpi reads one part a rank):
// for every format and 1 to 9 parts, the parts put together are what read_points reads, and a bad
// file gives read_points' own error message (the first error of the first failing part).
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/io/vectors.hpp"
#include "read_in_parts.hpp"
#include "support.hpp"

namespace io = kdspace::io;

namespace {

void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Every part count from 1 to 9 reads `path` as read_points does (values bit for bit, or the error).
template <class T>
void check_parts(const std::string& path) {
  const std::string whole = kdspace_test::outcome<T>([&] { return io::read_points<T>(path); });
  for (std::size_t parts = 1; parts <= 9; ++parts) {
    INFO(path << " in " << parts << " parts");
    CHECK(kdspace_test::outcome<T>([&] { return kdspace_test::read_in_parts<T>(path, parts); }) == whole);
  }
}

}  // namespace

TEMPLATE_TEST_CASE("a file read in parts equals the file read whole, in every format", "[io]", float,
                   double) {
  const kdspace_test::ScratchDir dir("kdspace-io-parts-");
  for (const std::size_t n : {std::size_t{1}, std::size_t{5}, std::size_t{37}}) {
    io::Matrix<TestType> m{n, 3, kdspace_test::make_points<TestType>(kdspace_test::Shape::grid, n, 3, 7)};
    for (const char* ext : {".fvecs", ".ivecs", ".bvecs", ".npy", ".csv"}) {
      const std::string path = dir.file("points" + std::to_string(n) + ext);
      io::write_points(path, m);
      check_parts<TestType>(path);
    }
  }
}

TEST_CASE("csv in parts: header, CRLF, spaces, blank lines at the end, no final newline", "[io]") {
  const kdspace_test::ScratchDir dir("kdspace-io-parts-");
  const std::vector<std::string> files = {
      "x,y\n1,2\n3,4\n5,6\n",
      "x,y\r\n1,2\r\n3,4\r\n",
      " 1 , 2\n\t3,4 \n5,6",
      "1,2\n3,4\n\n  \n\t\n",
      "1,2\n",
      "a\n7\n8\n9\n10\n11\n12\n13\n14\n15\n16\n17\n18\n19\n20\n21\n22\n",
  };
  for (std::size_t i = 0; i < files.size(); ++i) {
    const std::string path = dir.file("good" + std::to_string(i) + ".csv");
    write_file(path, files[i]);
    check_parts<double>(path);
  }
}

TEST_CASE("a bad file in parts gives the error of the file read whole", "[io][errors]") {
  const kdspace_test::ScratchDir dir("kdspace-io-parts-");
  const std::vector<std::string> csv = {
      "",                                // empty
      "x,y\n",                           // a header only
      "\n\n",                            // blank lines only
      "1,2\n\n3,4\n",                    // a blank line before data
      "\n1,2\n",                         // a blank first line
      "x,y\n\n1,2\n",                    // a blank line after the header
      "1,2\n3,4\n5,x\n7,8\n",            // a field that is no number
      "1,2\n3,4,5\n6,7\n",               // a row of another length
      "1,2\n3,nan\n",                    // not finite
      "1,2\n3,1e300\n",                  // beyond float
      "1,2\r\r\n3,4\n",                  // a carriage return left in a field
      "a,b\n1,2\n3\n4,5\n\n6,7\n8,9\n",  // two problems: the first is reported
  };
  for (std::size_t i = 0; i < csv.size(); ++i) {
    const std::string path = dir.file("bad" + std::to_string(i) + ".csv");
    write_file(path, csv[i]);
    check_parts<float>(path);
    check_parts<double>(path);
  }

  // Binary files: cut, with a row of another length, or a non-finite value.
  io::Matrix<float> m{20, 2, kdspace_test::make_points<float>(kdspace_test::Shape::uniform, 20, 2, 3)};
  const std::string good = dir.file("good.fvecs");
  io::write_points(good, m);
  const std::string bytes = read_file(good);
  const std::size_t row = 4 + 2 * 4;
  std::string wrong_length = bytes;
  const std::int32_t three = 3;
  std::memcpy(&wrong_length[13 * row], &three, 4);
  std::string not_finite = bytes;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&not_finite[17 * row + 8], &nan, 4);
  const std::vector<std::string> fvecs = {bytes.substr(0, bytes.size() - 3), bytes.substr(0, 2), bytes + "xy",
                                          bytes + bytes.substr(0, 4),        wrong_length,       not_finite};
  for (std::size_t i = 0; i < fvecs.size(); ++i) {
    const std::string path = dir.file("bad" + std::to_string(i) + ".fvecs");
    write_file(path, fvecs[i]);
    check_parts<float>(path);
  }
  const std::string npy = dir.file("points.npy");
  io::write_points(npy, m);
  const std::string cut_npy = dir.file("cut.npy");
  write_file(cut_npy, read_file(npy).substr(0, read_file(npy).size() - 5));
  check_parts<float>(cut_npy);
}
