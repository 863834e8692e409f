// Tests of the vector file formats (kdspace/io/vectors.hpp): round trips, and one test per error case
// checking that the message names the file, the row and the problem.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/vectors.hpp"
#include "catch_support.hpp"
#include "support.hpp"

namespace fs = std::filesystem;
using Catch::Contains;
using Catch::StartsWith;
using kdspace::io::Matrix;
using kdspace::io::RaggedRows;
using kdspace_test::error_message;
namespace io = kdspace::io;

namespace {

// A scratch directory for one test, removed afterwards.
class TempDir : public kdspace_test::ScratchDir {
 public:
  TempDir() : ScratchDir("kdspace-io-test-") {}
};

// Little-endian bytes for hand-made files.
class Bytes {
 public:
  template <class V>
  Bytes& add(V v) {
    char b[sizeof v];
    std::memcpy(b, &v, sizeof v);
    s_.append(b, sizeof v);
    return *this;
  }
  Bytes& text(const std::string& t) {
    s_ += t;
    return *this;
  }
  const std::string& str() const { return s_; }

 private:
  std::string s_;
};

void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// A .npy file with the given header version, header dict and data bytes.
std::string npy_bytes(int major, const std::string& dict, const std::string& data) {
  const std::string header = dict + "\n";
  Bytes b;
  b.text("\x93NUMPY").add(static_cast<std::uint8_t>(major)).add(std::uint8_t{0});
  if (major == 1) b.add(static_cast<std::uint16_t>(header.size()));
  else b.add(static_cast<std::uint32_t>(header.size()));
  return b.text(header).text(data).str();
}

std::string npy_dict(const std::string& descr, const std::string& shape, const std::string& fortran = "False") {
  return "{'descr': '" + descr + "', 'fortran_order': " + fortran + ", 'shape': " + shape + ", }";
}

template <class T>
Matrix<T> matrix(std::size_t rows, std::size_t cols, std::vector<T> data) {
  return Matrix<T>{rows, cols, std::move(data)};
}


// The start of a message about `where` ("row 3", "header") in `path`.
std::string at(const std::string& path, const std::string& where) { return path + ": " + where + ": "; }

template <class T>
void require_equal(const Matrix<T>& got, const Matrix<T>& want) {
  REQUIRE(got.rows == want.rows);
  REQUIRE(got.cols == want.cols);
  REQUIRE(got.data == want.data);
}

}  // namespace

// ---- round trips and reading ------------------------------------------------------------------------

TEMPLATE_TEST_CASE("points round-trip through every format", "[io]", float, double) {
  TempDir tmp;
  for (const std::string ext : {"fvecs", "ivecs", "bvecs", "csv", "npy"}) {
    CAPTURE(ext);
    const bool integers = ext == "ivecs" || ext == "bvecs";
    Matrix<TestType> m{5, 3, {}};
    for (std::size_t i = 0; i < m.rows * m.cols; ++i) {
      const double v = integers ? double((i * 37) % 256) : (double(i) - 4.0) / 7.0;
      // fvecs stores float32, so only float values come back exactly from it
      m.data.push_back(ext == "fvecs" ? TestType(float(v)) : TestType(v));
    }
    const std::string path = tmp.file("points." + ext);
    io::write_points(path, m);
    require_equal(io::read_points<TestType>(path), m);
  }
}

TEST_CASE("npy files store float32 for float and float64 for double", "[io]") {
  TempDir tmp;
  io::write_points(tmp.file("f.npy"), matrix<float>(1, 2, {1.5f, 2.5f}));
  io::write_points(tmp.file("d.npy"), matrix<double>(1, 2, {1.5, 2.5}));
  io::write_points(tmp.file("d.fvecs"), matrix<double>(1, 2, {1.5, 2.5}));
  io::write_points(tmp.file("f.csv"), matrix<float>(1, 2, {1.5f, 2.5f}));
  CHECK_FALSE(io::stores_double(tmp.file("f.npy")));
  CHECK(io::stores_double(tmp.file("d.npy")));
  CHECK_FALSE(io::stores_double(tmp.file("d.fvecs")));
  CHECK(io::stores_double(tmp.file("f.csv")));
  // written npy headers are padded so that the data starts 64-byte aligned
  CHECK((fs::file_size(tmp.file("d.npy")) - 2 * 8) % 64 == 0);
}

TEST_CASE("the format is chosen by the extension, ignoring case", "[io]") {
  CHECK(io::format_from_path("a/b.fvecs") == io::Format::fvecs);
  CHECK(io::format_from_path("B.IVECS") == io::Format::ivecs);
  CHECK(io::format_from_path("x.y.BVecs") == io::Format::bvecs);
  CHECK(io::format_from_path("points.CSV") == io::Format::csv);
  CHECK(io::format_from_path("p.npy") == io::Format::npy);
  CHECK(error_message([] { io::format_from_path("dir.npy/points.txt"); }) ==
        "dir.npy/points.txt: unknown file extension (expected .fvecs, .ivecs, .bvecs, .csv or .npy)");
  CHECK_THAT(error_message([] { io::read_points<float>("noext"); }), StartsWith("noext: unknown file extension"));
  CHECK_THAT(error_message([] { io::write_points("p.txt", matrix<float>(1, 1, {1})); }),
             StartsWith("p.txt: unknown file extension"));
}

TEST_CASE("ivecs and bvecs files are read as points, converting the values", "[io]") {
  TempDir tmp;
  const std::string iv = tmp.file("p.ivecs"), bv = tmp.file("p.bvecs");
  write_file(iv, Bytes().add(std::int32_t{2}).add(std::int32_t{-7}).add(std::int32_t{1 << 30}).str());
  write_file(bv, Bytes().add(std::int32_t{3}).add(std::uint8_t{0}).add(std::uint8_t{128}).add(std::uint8_t{255}).str());
  require_equal(io::read_points<double>(iv), matrix<double>(1, 2, {-7, 1 << 30}));
  require_equal(io::read_points<float>(bv), matrix<float>(1, 3, {0, 128, 255}));
}

TEST_CASE("points are read as bytes from any format whose values are integers from 0 to 255", "[io]") {
  TempDir tmp;
  const std::string bv = tmp.file("p.bvecs"), c = tmp.file("p.csv");
  write_file(bv, Bytes().add(std::int32_t{3}).add(std::uint8_t{0}).add(std::uint8_t{128}).add(std::uint8_t{255})
                     .add(std::int32_t{3}).add(std::uint8_t{7}).add(std::uint8_t{8}).add(std::uint8_t{9}).str());
  require_equal(io::read_points<std::uint8_t>(bv), matrix<std::uint8_t>(2, 3, {0, 128, 255, 7, 8, 9}));
  write_file(c, "x,y\n3,250\n");
  require_equal(io::read_points<std::uint8_t>(c), matrix<std::uint8_t>(1, 2, {3, 250}));
}

TEST_CASE("reading bytes, a value that is no byte names its row and column", "[io][errors]") {
  TempDir tmp;
  const std::string c = tmp.file("p.csv"), f = tmp.file("p.fvecs");
  write_file(c, "1,2\n3,256\n");
  CHECK(error_message([&] { io::read_points<std::uint8_t>(c); }) ==
        at(c, "row 2 (line 2)") + "column 2: value 256 is not an integer in 0..255");
  io::write_points(f, matrix<float>(2, 2, {1, 2, 0.5f, 4}));
  CHECK(error_message([&] { io::read_points<std::uint8_t>(f); }) ==
        at(f, "row 2") + "column 1: value 0.5 is not an integer in 0..255");
  io::write_points(f, matrix<float>(1, 2, {-1, 4}));
  CHECK(error_message([&] { io::read_points<std::uint8_t>(f); }) ==
        at(f, "row 1") + "column 1: value -1 is not an integer in 0..255");
  io::write_points(f, matrix<float>(1, 2, {std::numeric_limits<float>::quiet_NaN(), 4}));
  CHECK(error_message([&] { io::read_points<std::uint8_t>(f); }) == at(f, "row 1") + "column 1: value is not finite (nan)");
}

TEST_CASE("npy headers of versions 2.0 and 3.0 and dtypes <i4 and |u1 are read", "[io]") {
  TempDir tmp;
  const std::string p2 = tmp.file("v2.npy"), p3 = tmp.file("v3.npy"), pu = tmp.file("u1.npy");
  write_file(p2, npy_bytes(2, npy_dict("<f8", "(2, 1)"), Bytes().add(0.25).add(-8.0).str()));
  write_file(p3, npy_bytes(3, npy_dict("<i4", "(1, 2)"), Bytes().add(std::int32_t{-5}).add(std::int32_t{6}).str()));
  write_file(pu, npy_bytes(1, "{\"shape\": (1,2), \"fortran_order\": False, \"descr\": \"|u1\"}", "\x07\xff"));
  require_equal(io::read_points<double>(p2), matrix<double>(2, 1, {0.25, -8}));
  require_equal(io::read_points<float>(p3), matrix<float>(1, 2, {-5, 6}));
  require_equal(io::read_points<float>(pu), matrix<float>(1, 2, {7, 255}));
  CHECK(io::stores_double(p2));
  CHECK_FALSE(io::stores_double(p3));
}

TEST_CASE("a 1-D npy array is read as one column", "[io]") {
  TempDir tmp;
  const std::string p = tmp.file("col.npy");
  write_file(p, npy_bytes(1, npy_dict("<f4", "(3,)"), Bytes().add(1.0f).add(2.0f).add(3.0f).str()));
  require_equal(io::read_points<float>(p), matrix<float>(3, 1, {1, 2, 3}));
}

TEST_CASE("a csv first line with no number in it is a header and skipped", "[io]") {
  TempDir tmp;
  const std::string p = tmp.file("h.csv");
  write_file(p, "x,y,label 3\n1,2,3\n4.5,-6e2,0x10\n");
  require_equal(io::read_points<double>(p), matrix<double>(2, 3, {1, 2, 3, 4.5, -600, 16}));
}

TEST_CASE("a csv first line mixing numbers and text is a bad data row, not a header", "[io]") {
  TempDir tmp;
  const std::string p = tmp.file("m.csv");
  write_file(p, "1,2,3x\n4,5,6\n");  // a typo in the first row must not silently drop it
  REQUIRE_THROWS_WITH(io::read_points<double>(p),
                      Catch::Contains(p) && Catch::Contains("row 1") && Catch::Contains("'3x' is not a number"));
}

TEST_CASE("a csv first line of numbers is data, not a header", "[io]") {
  TempDir tmp;
  const std::string p = tmp.file("n.csv");
  write_file(p, "1,2\n3,4");  // no newline at the end
  require_equal(io::read_points<float>(p), matrix<float>(2, 2, {1, 2, 3, 4}));
}

TEST_CASE("csv allows spaces around numbers, CRLF line ends and blank lines at the end", "[io]") {
  TempDir tmp;
  const std::string p = tmp.file("s.csv");
  write_file(p, "a , b\r\n  1 ,\t2.5 \r\n+3,  -4\r\n\r\n  \n\n");
  require_equal(io::read_points<double>(p), matrix<double>(2, 2, {1, 2.5, 3, -4}));
}

TEST_CASE("ragged ivecs and fvecs rows round-trip, including a row of length 0", "[io]") {
  TempDir tmp;
  RaggedRows<std::int32_t> ints;
  ints.values = {1, 2, 3, -4, std::numeric_limits<std::int32_t>::max()};
  ints.offsets = {0, 3, 3, 5};  // rows of 3, 0 and 2 values
  io::write_ivecs(tmp.file("r.ivecs"), ints);
  const auto ints_back = io::read_ivecs_rows(tmp.file("r.ivecs"));
  CHECK(ints_back.rows() == 3);
  CHECK(ints_back.offsets == ints.offsets);
  CHECK(ints_back.values == ints.values);

  RaggedRows<float> floats;
  floats.values = {0.5f, std::numeric_limits<float>::quiet_NaN()};  // result files are not checked for NaN
  floats.offsets = {0, 0, 2};
  io::write_fvecs(tmp.file("r.fvecs"), floats);
  const auto floats_back = io::read_fvecs_rows(tmp.file("r.fvecs"));
  CHECK(floats_back.offsets == floats.offsets);
  REQUIRE(floats_back.values.size() == 2);
  CHECK(floats_back.values[0] == 0.5f);
  CHECK(std::isnan(floats_back.values[1]));
}

TEST_CASE("an empty ragged file reads as zero rows", "[io]") {
  TempDir tmp;
  io::write_ivecs(tmp.file("e.ivecs"), RaggedRows<std::int32_t>{});
  CHECK(fs::file_size(tmp.file("e.ivecs")) == 0);
  CHECK(io::read_ivecs_rows(tmp.file("e.ivecs")).rows() == 0);
  CHECK(io::read_fvecs_rows(tmp.file("e.ivecs")).rows() == 0);
}

TEST_CASE("read_points reports rising progress that ends at 1", "[io]") {
  TempDir tmp;
  for (const std::string ext : {"fvecs", "csv", "npy"}) {
    CAPTURE(ext);
    Matrix<float> m{4000, 16, std::vector<float>(4000 * 16, 0.25f)};
    const std::string p = tmp.file("big." + ext);
    io::write_points(p, m);
    std::vector<double> seen;
    io::read_points<float>(p, [&](double f) { seen.push_back(f); });
    REQUIRE(seen.size() >= 10);
    CHECK(seen.size() <= 101);
    CHECK(std::is_sorted(seen.begin(), seen.end()));
    CHECK(seen.front() > 0.0);
    CHECK(seen.back() == 1.0);
  }
}

// ---- errors: opening, emptiness ---------------------------------------------------------------------

TEST_CASE("a file that does not exist cannot be opened, and the reason is given", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("missing.fvecs");
  // (Catch2 v2 combined matchers must not outlive the statement, so each is spelled out)
  const auto reason = Contains("No such file or directory");
  CHECK_THAT(error_message([&] { io::read_points<float>(p); }), StartsWith(p + ": cannot open: ") && reason);
  CHECK_THAT(error_message([&] { io::read_ivecs_rows(p); }), StartsWith(p + ": cannot open: ") && reason);
  CHECK_THAT(error_message([&] { io::stores_double(tmp.file("missing.npy")); }), Contains("cannot open"));
}

TEST_CASE("an empty file has no rows, in every format", "[io][errors]") {
  TempDir tmp;
  for (const std::string ext : {"fvecs", "ivecs", "bvecs", "csv", "npy"}) {
    const std::string p = tmp.file("empty." + ext);
    write_file(p, "");
    CHECK(error_message([&] { io::read_points<double>(p); }) == p + ": empty file, no rows");
  }
  const std::string blank = tmp.file("blank.csv");
  write_file(blank, "\n \r\n\n");
  CHECK(error_message([&] { io::read_points<double>(blank); }) == blank + ": empty file, no rows");
}

TEST_CASE("a csv file with only a header has no rows", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("header.csv");
  write_file(p, "x,y\n\n");
  CHECK(error_message([&] { io::read_points<float>(p); }) == p + ": no rows after the header line");
}

// ---- errors: vecs files -----------------------------------------------------------------------------

TEST_CASE("a vecs row header with a dimension of 0, below 0 or above a million is rejected", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("dim.fvecs");
  for (const std::int32_t d : {0, -3, 1000001, std::numeric_limits<std::int32_t>::max()}) {
    CAPTURE(d);
    write_file(p, Bytes().add(d).add(1.0f).add(2.0f).str());
    CHECK_THAT(error_message([&] { io::read_points<float>(p); }),
               StartsWith(at(p, "row 1")) &&
                   Contains("dimension " + std::to_string(d) + " in the row header is not in 1..1000000"));
  }
  // and in a later row
  const std::string b = tmp.file("dim.bvecs");
  write_file(b, Bytes().add(std::int32_t{1}).add(std::uint8_t{9}).add(std::int32_t{-1}).add(std::uint8_t{9}).str());
  CHECK_THAT(error_message([&] { io::read_points<float>(b); }),
             StartsWith(at(b, "row 2")) && Contains("dimension -1"));
}

TEST_CASE("rows of different lengths in a vecs file name the first odd row", "[io][errors]") {
  TempDir tmp;
  RaggedRows<float> rows;
  const auto add_row = [&](std::size_t n) {
    rows.values.resize(rows.values.size() + n, 1.0f);
    rows.offsets.push_back(rows.values.size());
  };
  for (int r = 1; r <= 9; ++r) add_row(r == 7 ? 3 : 4);
  const std::string p = tmp.file("odd.fvecs");
  io::write_fvecs(p, rows);
  CHECK(error_message([&] { io::read_points<double>(p); }) == at(p, "row 7") + "has 3 values, expected 4 like row 1");

  // the odd row last, where the file size is no multiple of the row size
  RaggedRows<std::int32_t> ints;
  ints.values = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10};
  ints.offsets = {0, 4, 8, 10};
  const std::string q = tmp.file("odd.ivecs");
  io::write_ivecs(q, ints);
  CHECK(error_message([&] { io::read_points<float>(q); }) == at(q, "row 3") + "has 2 values, expected 4 like row 1");
}

TEST_CASE("a truncated fvecs file names the truncated row", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("cut.fvecs");
  io::write_points(p, Matrix<float>{12, 127, std::vector<float>(12 * 127, 1.0f)});  // 512 bytes a row
  fs::resize_file(p, 11 * 512 + 100);
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "row 12") + "truncated: expected 512 bytes, file ends after 100");
}

TEST_CASE("a vecs file cut inside a row header is truncated in that row", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("cut.bvecs");
  io::write_points(p, Matrix<float>{3, 2, {1, 2, 3, 4, 5, 6}});  // 6 bytes a row
  fs::resize_file(p, 2 * 6 + 2);
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "row 3") + "truncated: expected 6 bytes, file ends after 2");
  fs::resize_file(p, 3);
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "row 1") + "truncated: expected 4 bytes, file ends after 3");
}

TEST_CASE("a truncated ragged file names the truncated row", "[io][errors]") {
  TempDir tmp;
  RaggedRows<std::int32_t> rows;
  rows.values = {1, 2, 3, 4, 5, 6, 7, 8};
  rows.offsets = {0, 3, 8};
  const std::string p = tmp.file("cut.ivecs");
  io::write_ivecs(p, rows);
  fs::resize_file(p, fs::file_size(p) - 4);
  CHECK(error_message([&] { io::read_ivecs_rows(p); }) ==
        at(p, "row 2") + "truncated: expected 24 bytes, file ends after 20");
  fs::resize_file(p, 16 + 3);
  CHECK(error_message([&] { io::read_fvecs_rows(p); }) ==
        at(p, "row 2") + "truncated: expected 4 bytes, file ends after 3");
}

TEST_CASE("a ragged row header claiming more values than the file holds is truncation, not allocation",
          "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("huge.ivecs");
  write_file(p, Bytes().add(std::int32_t{2000000000}).add(std::int32_t{1}).str());
  CHECK(error_message([&] { io::read_ivecs_rows(p); }) ==
        at(p, "row 1") + "truncated: expected 8000000004 bytes, file ends after 8");
  write_file(p, Bytes().add(std::int32_t{1}).add(std::int32_t{1}).add(std::int32_t{-2}).str());
  CHECK(error_message([&] { io::read_ivecs_rows(p); }) == at(p, "row 2") + "length -2 in the row header is negative");
}

// ---- errors: values ---------------------------------------------------------------------------------

TEMPLATE_TEST_CASE("NaN and infinite values are rejected, naming row and column", "[io][errors]", float, double) {
  TempDir tmp;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (const std::string ext : {"fvecs", "npy", "csv"}) {
    CAPTURE(ext);
    const std::string p = tmp.file("bad." + ext);  // csv adds " (line L)" after the row
    io::write_points(p, Matrix<double>{3, 2, {1, 2, 3, 4, 5, nan}});
    CHECK_THAT(error_message([&] { io::read_points<TestType>(p); }),
               StartsWith(p + ": row 3") && Contains("column 2: value is not finite (nan)"));
    io::write_points(p, Matrix<double>{3, 2, {1, 2, -inf, 4, 5, 6}});
    CHECK_THAT(error_message([&] { io::read_points<TestType>(p); }),
               StartsWith(p + ": row 2") && Contains("column 1: value is not finite (-inf)"));
  }
  // csv text, as people write it
  const std::string c = tmp.file("text.csv");
  write_file(c, "x,y\n1,2\n3,NaN\n");
  CHECK(error_message([&] { io::read_points<TestType>(c); }) ==
        at(c, "row 2 (line 3)") + "column 2: value is not finite (nan)");
  write_file(c, "1,2\ninf,4\n");
  CHECK(error_message([&] { io::read_points<TestType>(c); }) ==
        at(c, "row 2 (line 2)") + "column 1: value is not finite (inf)");
  write_file(c, "1,1e999\n");  // overflows to infinity
  CHECK_THAT(error_message([&] { io::read_points<TestType>(c); }),
             StartsWith(at(c, "row 1 (line 1)")) && Contains("not finite"));
}

TEST_CASE("a value beyond float range is rejected when reading floats", "[io][errors]") {
  TempDir tmp;
  const std::string c = tmp.file("big.csv");
  write_file(c, "1\n-1e300\n");
  CHECK(error_message([&] { io::read_points<float>(c); }) ==
        at(c, "row 2 (line 2)") + "column 1: value -1e+300 does not fit in float");
  CHECK(io::read_points<double>(c).data[1] == -1e300);
  const std::string n = tmp.file("big.npy");
  io::write_points(n, Matrix<double>{1, 2, {1, 1e39}});
  CHECK(error_message([&] { io::read_points<float>(n); }) == at(n, "row 1") + "column 2: value 1e+39 does not fit in float");
}

TEST_CASE("a malformed csv field names the row, the column and the text", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("bad.csv");
  write_file(p, "1,2\n3,abc\n");
  CHECK(error_message([&] { io::read_points<float>(p); }) == at(p, "row 2 (line 2)") + "column 2: 'abc' is not a number");
  write_file(p, "a,b,c\n1,2,3\n1,,3\n");
  CHECK(error_message([&] { io::read_points<float>(p); }) == at(p, "row 2 (line 3)") + "column 2: '' is not a number");
  write_file(p, "1,2\n1 2,3\n");
  CHECK_THAT(error_message([&] { io::read_points<float>(p); }), Contains("column 1: '1 2' is not a number"));
  write_file(p, "1,2\n3,1.5x\n");
  CHECK_THAT(error_message([&] { io::read_points<float>(p); }), Contains("column 2: '1.5x' is not a number"));
}

TEST_CASE("rows of different lengths in a csv file name the row and line", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("ragged.csv");
  write_file(p, "x,y,z\n1,2,3\n4,5\n");
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "row 2 (line 3)") + "has 2 values, expected 3 like row 1");
}

TEST_CASE("a blank line inside csv data is rejected", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("gap.csv");
  write_file(p, "1,2\n\n3,4\n");
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "row 2 (line 2)") + "blank line (allowed only at the end of the file)");
}

// ---- errors: npy headers ----------------------------------------------------------------------------

TEST_CASE("npy files with a bad magic, version, dtype, order or shape are rejected", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("bad.npy");
  const std::string four = Bytes().add(1.0f).add(2.0f).add(3.0f).add(4.0f).str();
  const auto message = [&](const std::string& bytes) {
    write_file(p, bytes);
    return error_message([&] { io::read_points<float>(p); });
  };
  CHECK(message("PK\x03\x04 not numpy at all") == p + ": not a .npy file (bad magic bytes)");
  CHECK(message(std::string("\x93NUMPY\x04\x00", 8) + "xx") ==
        p + ": unsupported .npy version 4.0 (expected 1.0, 2.0 or 3.0)");
  CHECK(message(npy_bytes(1, npy_dict(">f4", "(2, 2)"), four)) ==
        p + ": unsupported dtype '>f4' (expected <f4, <f8, <i4 or |u1)");
  CHECK_THAT(message(npy_bytes(1, npy_dict("<c8", "(2, 1)"), four)), Contains("unsupported dtype '<c8'"));
  CHECK(message(npy_bytes(1, npy_dict("<f4", "(2, 2)", "True"), four)) ==
        p + ": fortran_order True is not supported (save the array in C order)");
  CHECK(message(npy_bytes(1, npy_dict("<f4", "(1, 2, 2)"), four)) == p + ": shape (1, 2, 2) is not 2-D");
  CHECK(message(npy_bytes(1, npy_dict("<f4", "()"), four)) == p + ": shape () is not 2-D");
  CHECK(message(npy_bytes(1, npy_dict("<f4", "(4, 0)"), "")) == p + ": shape (4, 0) has no columns");
  CHECK(message(npy_bytes(1, npy_dict("<f4", "(0, 4)"), "")) == p + ": no rows (shape (0, 4))");
}

TEST_CASE("a malformed npy header dict is rejected", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("dict.npy");
  const auto message = [&](const std::string& dict) {
    write_file(p, npy_bytes(1, dict, ""));
    return error_message([&] { io::read_points<float>(p); });
  };
  const auto malformed = StartsWith(p + ": malformed .npy header: ");
  CHECK_THAT(message("not a dict"), malformed && Contains("not a dict"));
  CHECK_THAT(message("{'descr': '<f4', 'shape': (1, 1), }"), malformed && Contains("all required"));
  CHECK_THAT(message("{'descr': '<f4', 'fortran_order': False, 'shape': (1, -1), }"),
             malformed && Contains("non-negative"));
  CHECK_THAT(message("{'descr': '<f4', 'fortran_order': No, 'shape': (1, 1), }"),
             malformed && Contains("True or False"));
  CHECK_THAT(message("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1) 'x'}"),
             malformed && Contains("expected ',' or '}'"));
  CHECK_THAT(message("{'descr': '<f4', 'fortran_order': False, 'shape': (1 1), }"),
             malformed && Contains("shape is not a tuple"));
  CHECK_THAT(message("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1), 'extra': 1}"),
             malformed && Contains("unknown key 'extra'"));
  CHECK_THAT(message(npy_dict("<f4", "(1, 1)") + " trailing"), malformed && Contains("text after the dict"));
}

TEST_CASE("an npy header longer than the file is truncated in the header", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("short.npy");
  write_file(p, Bytes().text("\x93NUMPY").add(std::uint8_t{2}).add(std::uint8_t{0}).add(std::uint32_t{4000000000u}).text("{}").str());
  CHECK(error_message([&] { io::read_points<float>(p); }) ==
        at(p, "header") + "truncated: expected 4000000000 bytes, file ends after 2");
  write_file(p, std::string("\x93NUMPY\x01", 7));
  CHECK(error_message([&] { io::read_points<float>(p); }) == at(p, "header") + "truncated: expected 8 bytes, file ends after 7");
}

TEST_CASE("npy data that does not match the shape is found before allocating", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("size.npy");
  const auto message = [&](const std::string& shape, std::size_t data_bytes) {
    write_file(p, npy_bytes(1, npy_dict("<f4", shape), std::string(data_bytes, '\0')));
    return error_message([&] { io::read_points<float>(p); });
  };
  CHECK(message("(4, 4)", 40) == at(p, "row 3") + "truncated: expected 16 bytes, file ends after 8");
  CHECK(message("(1000000000000, 3)", 8) == at(p, "row 1") + "truncated: expected 12 bytes, file ends after 8");
  CHECK(message("(2, 2)", 20) == p + ": data size does not match shape (2, 2): expected 16 bytes of data, file has 20");
  CHECK(message("(4611686018427387904, 4611686018427387904)", 0) ==
        p + ": shape (4611686018427387904, 4611686018427387904) is too large");
  CHECK_THAT(message("(99999999999999999999, 1)", 0), Contains("malformed .npy header"));
}

// ---- errors: writing --------------------------------------------------------------------------------

TEST_CASE("a file that cannot be created is reported with the reason", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("no-such-dir/p.fvecs");
  const auto start = StartsWith(p + ": cannot open for writing: ");
  const auto reason = Contains("No such file or directory");
  CHECK_THAT(error_message([&] { io::write_points(p, matrix<float>(1, 1, {1})); }), start && reason);
  CHECK_THAT(error_message([&] { io::write_ivecs(p, RaggedRows<std::int32_t>{}); }), start && reason);
}

TEST_CASE("a failed write is reported with the reason", "[io][errors]") {
  if (!fs::exists("/dev/full")) return;
  RaggedRows<std::int32_t> rows;
  rows.values = {1, 2, 3};
  rows.offsets = {0, 3};
  CHECK_THAT(error_message([&] { io::write_ivecs("/dev/full", rows); }),
             StartsWith("/dev/full: write failed: ") && Contains("No space left on device"));
}

TEST_CASE("bvecs and ivecs are written only from integers they can hold", "[io][errors]") {
  TempDir tmp;
  const std::string b = tmp.file("w.bvecs"), i = tmp.file("w.ivecs");
  CHECK(error_message([&] { io::write_points(b, matrix<float>(2, 2, {0, 255, 1, 256})); }) ==
        at(b, "row 2") + "column 2: value 256 is not an integer in 0..255");
  CHECK_THAT(error_message([&] { io::write_points(b, matrix<double>(1, 1, {0.5})); }),
             StartsWith(at(b, "row 1")) && Contains("value 0.5 is not an integer"));
  CHECK_THAT(error_message([&] { io::write_points(b, matrix<double>(1, 1, {-1})); }), Contains("not an integer in 0..255"));
  CHECK(error_message([&] { io::write_points(i, matrix<double>(1, 2, {1, 3e9})); }) ==
        at(i, "row 1") + "column 2: value 3e+09 is not an integer in -2147483648..2147483647");
}

TEST_CASE("fvecs is written only from values that fit in float32", "[io][errors]") {
  TempDir tmp;
  const std::string p = tmp.file("w.fvecs");
  CHECK(error_message([&] { io::write_points(p, matrix<double>(1, 2, {1, -1e300})); }) ==
        at(p, "row 1") + "column 2: value -1e+300 does not fit in float32");
}

TEST_CASE("inconsistent ragged rows or matrices are not written", "[io][errors]") {
  TempDir tmp;
  RaggedRows<float> rows;
  rows.values = {1, 2};
  rows.offsets = {0, 5};
  CHECK_THAT(error_message([&] { io::write_fvecs(tmp.file("r.fvecs"), rows); }), Contains("ragged rows are inconsistent"));
  CHECK_THAT(error_message([&] { io::write_points(tmp.file("m.npy"), matrix<float>(2, 2, {1, 2, 3})); }),
             Contains("matrix data size does not match rows x cols"));
}
