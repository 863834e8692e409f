// The vector file formats: .fvecs, .ivecs, .bvecs, .csv and .npy (see kdspace/io/vectors.hpp).
#include "kdspace/io/vectors.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>

#include <sys/types.h>

#include "kdspace/error.hpp"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "kdspace's vector file I/O copies little-endian file data straight into memory"
#endif

namespace kdspace::io {
namespace {

static_assert(std::numeric_limits<float>::is_iec559 && sizeof(float) == 4, "float must be IEEE float32");
static_assert(std::numeric_limits<double>::is_iec559 && sizeof(double) == 8, "double must be IEEE float64");
static_assert(sizeof(std::size_t) == sizeof(std::uint64_t), "file sizes are counted in size_t");

// A vecs row header is an int32 dimension; read_points accepts 1..this.
constexpr std::int64_t max_dimension = 1'000'000;

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw Error(path + ": " + what); }

// Where in a file a problem is: a 1-based data row (0 = the file header), and for csv the text line.
struct RowRef {
  const std::string& path;
  std::size_t row;
  std::size_t line = 0;

  [[noreturn]] void fail(const std::string& what) const {
    std::string where = row ? "row " + std::to_string(row) : std::string("header");
    if (line) where += " (line " + std::to_string(line) + ")";
    io::fail(path, where + ": " + what);
  }
};

std::string column(std::size_t c) { return "column " + std::to_string(c + 1) + ": "; }

// Shortest text that reads back as v ("nan", "-inf" included).
template <class T>
std::string show(T v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

std::string truncated(std::uint64_t expected, std::uint64_t got) {
  return "truncated: expected " + std::to_string(expected) + " bytes, file ends after " + std::to_string(got);
}

// ---- element types of binary files -------------------------------------------------------------

enum class Elem { f32, f64, i32, u8 };

std::size_t elem_bytes(Elem e) {
  switch (e) {
    case Elem::f32: return 4;
    case Elem::f64: return 8;
    case Elem::i32: return 4;
    case Elem::u8: return 1;
  }
  return 0;
}

Elem vecs_elem(Format f) { return f == Format::fvecs ? Elem::f32 : f == Format::ivecs ? Elem::i32 : Elem::u8; }

template <class V>
V load_as(const unsigned char* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// The element at p, exactly, as a double.
double load(const unsigned char* p, Elem e) {
  switch (e) {
    case Elem::f32: return load_as<float>(p);
    case Elem::f64: return load_as<double>(p);
    case Elem::i32: return load_as<std::int32_t>(p);
    case Elem::u8: return *p;
  }
  return 0;
}

// Checks an integer value for an integer file format.
void check_integer(double v, double lo, double hi, const RowRef& at, std::size_t c) {
  if (!(v >= lo && v <= hi && v == std::floor(v)))
    at.fail(column(c) + "value " + show(v) + " is not an integer in " + show(lo) + ".." + show(hi));
}

// Stores v at p as element type e; says why when the type cannot hold it.
void store(double v, Elem e, unsigned char* p, const RowRef& at, std::size_t c) {
  switch (e) {
    case Elem::f32: {
      if (std::isfinite(v) && std::fabs(v) > std::numeric_limits<float>::max())
        at.fail(column(c) + "value " + show(v) + " does not fit in float32");
      const auto f = static_cast<float>(v);
      std::memcpy(p, &f, sizeof f);
      return;
    }
    case Elem::f64: std::memcpy(p, &v, sizeof v); return;
    case Elem::i32: {
      check_integer(v, std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max(), at, c);
      const auto i = static_cast<std::int32_t>(v);
      std::memcpy(p, &i, sizeof i);
      return;
    }
    case Elem::u8: check_integer(v, 0, 255, at, c); *p = static_cast<unsigned char>(v); return;
  }
}

// A point coordinate read from a file: finite, and within range of T (for bytes: an integer in 0..255).
template <class T>
T checked_value(double v, const RowRef& at, std::size_t c) {
  if (!std::isfinite(v)) at.fail(column(c) + "value is not finite (" + show(v) + ")");
  if constexpr (std::is_same_v<T, std::uint8_t>) check_integer(v, 0, 255, at, c);
  if constexpr (std::is_same_v<T, float>) {
    if (std::fabs(v) > std::numeric_limits<float>::max())
      at.fail(column(c) + "value " + show(v) + " does not fit in float");
  }
  return static_cast<T>(v);
}

// ---- files ---------------------------------------------------------------------------------------

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

// A file open for reading: knows its size and how far it has been read, and reports progress.
class InFile {
 public:
  InFile(const std::string& path, const std::function<void(double)>& on_progress = {})
      : path_(path), f_(std::fopen(path.c_str(), "rb")), on_progress_(on_progress ? &on_progress : nullptr) {
    if (!f_) fail(path, std::string("cannot open: ") + std::strerror(errno));
    std::error_code ec;
    size_ = std::filesystem::file_size(path, ec);
    if (ec) fail(path, "cannot open: " + ec.message());
  }

  const std::string& path() const { return path_; }
  std::uint64_t size() const { return size_; }
  std::uint64_t left() const { return offset_ < size_ ? size_ - offset_ : 0; }
  // A good amount to read at a time: small enough for progress in steps of about 1%.
  std::size_t chunk_bytes() const {
    return static_cast<std::size_t>(std::clamp<std::uint64_t>(size_ / 128, 4096, std::uint64_t{1} << 20));
  }

  // Throws "truncated" unless n more bytes are left; `already` bytes of the same row were read before.
  void expect(std::uint64_t n, const RowRef& at, std::uint64_t already = 0) const {
    if (n > left()) at.fail(truncated(already + n, already + left()));
  }

  // Reads exactly n bytes or throws "truncated".
  void read_exact(void* dst, std::size_t n, const RowRef& at, std::uint64_t already = 0) {
    expect(n, at, already);
    if (n == 0) return;
    const std::size_t got = std::fread(dst, 1, n, f_.get());
    if (got < n) {
      if (std::ferror(f_.get())) fail(path_, std::string("read error: ") + std::strerror(errno));
      at.fail(truncated(already + n, already + got));  // the file shrank while being read
    }
    advance(n);
  }

  // Reads up to n bytes; 0 at the end of the file.
  std::size_t read_some(char* dst, std::size_t n) {
    const std::size_t got = std::fread(dst, 1, n, f_.get());
    if (got < n && std::ferror(f_.get())) fail(path_, std::string("read error: ") + std::strerror(errno));
    advance(got);
    return got;
  }

  void rewind() {
    std::rewind(f_.get());
    offset_ = 0;
  }

  // Moves to byte `offset` of the file (at most its size).
  void seek(std::uint64_t offset) {
    if (offset > size_ || fseeko(f_.get(), static_cast<off_t>(offset), SEEK_SET) != 0)
      fail(path_, "cannot seek to byte " + std::to_string(offset) + ": " + std::strerror(errno));
    offset_ = offset;
  }

 private:
  void advance(std::size_t n) {
    offset_ += n;
    if (!on_progress_ || size_ == 0) return;
    const std::uint64_t percent = std::min<std::uint64_t>(offset_, size_) * 100 / size_;
    if (percent > reported_percent_) {
      reported_percent_ = percent;
      (*on_progress_)(percent == 100 ? 1.0 : static_cast<double>(offset_) / static_cast<double>(size_));
    }
  }

  std::string path_;
  std::unique_ptr<std::FILE, FileCloser> f_;
  const std::function<void(double)>* on_progress_;  // null when not set
  std::uint64_t size_ = 0;
  std::uint64_t offset_ = 0;
  std::uint64_t reported_percent_ = 0;
};

// A file open for writing; any failure throws with the path and the reason.
class OutFile {
 public:
  explicit OutFile(const std::string& path) : path_(path), f_(std::fopen(path.c_str(), "wb")) {
    if (!f_) fail(path, std::string("cannot open for writing: ") + std::strerror(errno));
  }

  const std::string& path() const { return path_; }

  void write(const void* src, std::size_t n) {
    if (n && std::fwrite(src, 1, n, f_.get()) != n) fail(path_, std::string("write failed: ") + std::strerror(errno));
  }

  // Flushes and closes; must be called for the data to be known written.
  void close() {
    const bool ok = std::fflush(f_.get()) == 0;
    const int err = errno;
    const bool closed = std::fclose(f_.release()) == 0;
    if (!ok || !closed) fail(path_, std::string("write failed: ") + std::strerror(ok ? errno : err));
  }

 private:
  std::string path_;
  std::unique_ptr<std::FILE, FileCloser> f_;
};

// ---- binary rows (vecs and npy) -----------------------------------------------------------------

// Checks the int32 length at the start of a vecs row of a point file: in range, and equal to row 1's
// `cols` (0 while checking row 1 itself).
void check_vecs_dimension(std::int32_t d, std::size_t cols, const RowRef& at) {
  if (d <= 0 || d > max_dimension)
    at.fail("dimension " + std::to_string(d) + " in the row header is not in 1.." + std::to_string(max_dimension));
  if (cols && static_cast<std::size_t>(d) != cols)
    at.fail("has " + std::to_string(d) + " values, expected " + std::to_string(cols) + " like row 1");
}

// Reads m.rows rows of m.cols elements of type e (each after an int32 length when `vecs`) into m,
// which is already sized; a block of rows at a time. The first is the file's row first_row + 1.
template <class T>
void read_binary_rows(InFile& in, Elem e, bool vecs, Matrix<T>& m, std::size_t first_row = 0) {
  const std::size_t eb = elem_bytes(e);
  const std::size_t row_bytes = (vecs ? 4 : 0) + m.cols * eb;
  const std::size_t block_rows = std::max<std::size_t>(1, in.chunk_bytes() / row_bytes);
  std::vector<unsigned char> block;
  for (std::size_t r0 = 0; r0 < m.rows; r0 += block_rows) {
    const std::size_t n = std::min(block_rows, m.rows - r0);
    block.resize(n * row_bytes);
    in.read_exact(block.data(), block.size(), RowRef{in.path(), first_row + r0 + 1});
    for (std::size_t i = 0; i < n; ++i) {
      const RowRef at{in.path(), first_row + r0 + i + 1};
      const unsigned char* p = block.data() + i * row_bytes;
      if (vecs) {
        check_vecs_dimension(load_as<std::int32_t>(p), m.cols, at);
        p += 4;
      }
      T* out = m.row(r0 + i);
      for (std::size_t c = 0; c < m.cols; ++c) out[c] = checked_value<T>(load(p + c * eb, e), at, c);
    }
  }
}

template <class T>
Matrix<T> read_vecs_points(InFile& in, Elem e) {
  std::int32_t d = 0;
  in.read_exact(&d, 4, RowRef{in.path(), 1});
  check_vecs_dimension(d, 0, RowRef{in.path(), 1});
  in.rewind();

  Matrix<T> m;
  m.cols = static_cast<std::size_t>(d);
  const std::uint64_t row_bytes = 4 + m.cols * elem_bytes(e);
  m.rows = static_cast<std::size_t>(in.size() / row_bytes);  // bounded by the file size
  m.data.resize(m.rows * m.cols);
  read_binary_rows(in, e, true, m);

  if (in.left() > 0) {  // a partial row at the end: wrong length, or cut off
    const RowRef at{in.path(), m.rows + 1};
    const std::uint64_t got = in.left();
    if (got >= 4) {
      in.read_exact(&d, 4, at);
      check_vecs_dimension(d, m.cols, at);
    }
    at.fail(truncated(row_bytes, got));
  }
  return m;
}

// ---- npy ----------------------------------------------------------------------------------------

struct NpyHeader {
  Elem elem = Elem::f32;
  std::size_t rows = 0;
  std::size_t cols = 0;
  std::string shape;  // as text, for messages: "(3, 4)"
};

// Reads the pieces of the Python dict literal in a .npy header; nullopt / false where it does not match.
class DictCursor {
 public:
  explicit DictCursor(std::string_view s) : s_(s) {}

  bool eat(char c) {
    skip_space();
    if (i_ == s_.size() || s_[i_] != c) return false;
    ++i_;
    return true;
  }
  bool word(std::string_view w) {
    skip_space();
    if (s_.substr(i_, w.size()) != w) return false;
    i_ += w.size();
    return true;
  }
  std::optional<std::string> quoted() {
    skip_space();
    if (i_ >= s_.size() || (s_[i_] != '\'' && s_[i_] != '"')) return std::nullopt;
    const std::size_t end = s_.find(s_[i_], i_ + 1);
    if (end == std::string_view::npos) return std::nullopt;
    std::string text(s_.substr(i_ + 1, end - i_ - 1));
    i_ = end + 1;
    return text;
  }
  std::optional<std::uint64_t> integer() {
    skip_space();
    std::uint64_t v = 0;
    const auto res = std::from_chars(s_.data() + i_, s_.data() + s_.size(), v);
    if (res.ec != std::errc()) return std::nullopt;
    i_ = static_cast<std::size_t>(res.ptr - s_.data());
    return v;
  }
  bool at_end() {
    skip_space();
    return i_ == s_.size();
  }

 private:
  void skip_space() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  std::string_view s_;
  std::size_t i_ = 0;
};

// Reads and checks the header of a .npy file, leaving `in` at the start of the data. Checks the data
// size against the file size, so that nothing is allocated for what a corrupt header claims.
NpyHeader read_npy_header(InFile& in) {
  const std::string& path = in.path();
  const RowRef at{path, 0};
  if (in.size() == 0) fail(path, "empty file, no rows");
  unsigned char pre[12] = {};  // magic, version, header length (2 or 4 bytes)
  in.read_exact(pre, 8, at);
  if (std::memcmp(pre, "\x93NUMPY", 6) != 0) fail(path, "not a .npy file (bad magic bytes)");
  const int major = pre[6];
  if (major < 1 || major > 3 || pre[7] != 0)
    fail(path, "unsupported .npy version " + std::to_string(major) + "." + std::to_string(pre[7]) +
                   " (expected 1.0, 2.0 or 3.0)");
  const std::size_t len_bytes = major == 1 ? 2 : 4;
  in.read_exact(pre + 8, len_bytes, at);
  std::size_t len = 0;
  for (std::size_t i = 0; i < len_bytes; ++i) len |= std::size_t{pre[8 + i]} << (8 * i);
  in.expect(len, at);
  std::string text(len, '\0');
  in.read_exact(text.data(), len, at);

  // {'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), }
  const auto bad = [&](const std::string& what) { fail(path, "malformed .npy header: " + what); };
  std::optional<std::string> descr;
  std::optional<bool> fortran;
  std::optional<std::vector<std::uint64_t>> shape;
  DictCursor c(text);
  if (!c.eat('{')) bad("not a dict");
  while (!c.eat('}')) {
    const auto key = c.quoted();
    if (!key || !c.eat(':')) bad("expected 'key': value");
    if (*key == "descr") {
      if (!(descr = c.quoted())) bad("descr is not a string");
    } else if (*key == "fortran_order") {
      if (c.word("True")) fortran = true;
      else if (c.word("False")) fortran = false;
      else bad("fortran_order is not True or False");
    } else if (*key == "shape") {
      if (!c.eat('(')) bad("shape is not a tuple");
      shape.emplace();
      while (!c.eat(')')) {
        const auto n = c.integer();
        if (!n) bad("shape is not a tuple of non-negative 64-bit integers");
        shape->push_back(*n);
        if (c.eat(',')) continue;
        if (!c.eat(')')) bad("shape is not a tuple");
        break;
      }
    } else {
      bad("unknown key '" + *key + "'");
    }
    if (c.eat(',')) continue;
    if (!c.eat('}')) bad("expected ',' or '}'");
    break;
  }
  if (!c.at_end()) bad("text after the dict");
  if (!descr || !fortran || !shape) bad("descr, fortran_order and shape are all required");

  NpyHeader h;
  if (*descr == "<f4") h.elem = Elem::f32;
  else if (*descr == "<f8") h.elem = Elem::f64;
  else if (*descr == "<i4") h.elem = Elem::i32;
  else if (*descr == "|u1" || *descr == "<u1") h.elem = Elem::u8;
  else fail(path, "unsupported dtype '" + *descr + "' (expected <f4, <f8, <i4 or |u1)");
  if (*fortran) fail(path, "fortran_order True is not supported (save the array in C order)");

  h.shape = "(";
  for (std::size_t i = 0; i < shape->size(); ++i) h.shape += (i ? ", " : "") + std::to_string((*shape)[i]);
  h.shape += shape->size() == 1 ? ",)" : ")";
  if (shape->size() != 1 && shape->size() != 2) fail(path, "shape " + h.shape + " is not 2-D");
  const std::uint64_t rows = (*shape)[0];
  const std::uint64_t cols = shape->size() == 2 ? (*shape)[1] : 1;
  if (cols == 0) fail(path, "shape " + h.shape + " has no columns");
  const std::uint64_t eb = elem_bytes(h.elem);
  const std::uint64_t max = std::numeric_limits<std::uint64_t>::max();
  if (cols > max / eb || rows > max / (cols * eb))
    fail(path, "shape " + h.shape + " is too large");
  const std::uint64_t row_bytes = cols * eb;
  if (rows * row_bytes > in.left())  // name the first row that is not all there
    RowRef{path, static_cast<std::size_t>(in.left() / row_bytes) + 1}.fail(
        truncated(row_bytes, in.left() % row_bytes));
  if (rows * row_bytes < in.left())
    fail(path, "data size does not match shape " + h.shape + ": expected " + std::to_string(rows * row_bytes) +
                   " bytes of data, file has " + std::to_string(in.left()));
  h.rows = static_cast<std::size_t>(rows);
  h.cols = static_cast<std::size_t>(cols);
  return h;
}

template <class T>
Matrix<T> read_npy_points(InFile& in) {
  const NpyHeader h = read_npy_header(in);
  if (h.rows == 0) fail(in.path(), "no rows (shape " + h.shape + ")");
  Matrix<T> m;
  m.rows = h.rows;
  m.cols = h.cols;
  m.data.resize(m.rows * m.cols);
  read_binary_rows(in, h.elem, false, m);
  return m;
}

// ---- csv ----------------------------------------------------------------------------------------

// Splits a file into lines, without the "\n" or "\r\n".
class LineReader {
 public:
  explicit LineReader(InFile& in) : in_(in), buf_(in.chunk_bytes()) {}

  bool next(std::string& line) {
    line.clear();
    for (;;) {
      if (pos_ == len_) {
        pos_ = 0;
        len_ = in_.read_some(buf_.data(), buf_.size());
        if (len_ == 0) {
          if (line.empty()) return false;
          break;
        }
      }
      const char* start = buf_.data() + pos_;
      const auto* nl = static_cast<const char*>(std::memchr(start, '\n', len_ - pos_));
      const std::size_t n = nl ? static_cast<std::size_t>(nl - start) : len_ - pos_;
      line.append(start, n);
      pos_ += n;
      if (nl) {
        ++pos_;
        break;
      }
    }
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }

 private:
  InFile& in_;
  std::vector<char> buf_;
  std::size_t pos_ = 0;
  std::size_t len_ = 0;
};

bool is_blank(char ch) { return ch == ' ' || ch == '\t'; }

// The comma-separated fields of a line, spaces and tabs around each trimmed.
void split_fields(std::string_view line, std::vector<std::string_view>& fields) {
  fields.clear();
  for (;;) {
    const std::size_t comma = line.find(',');
    std::string_view f = line.substr(0, comma);
    while (!f.empty() && is_blank(f.front())) f.remove_prefix(1);
    while (!f.empty() && is_blank(f.back())) f.remove_suffix(1);
    fields.push_back(f);
    if (comma == std::string_view::npos) return;
    line.remove_prefix(comma + 1);
  }
}

// Parses a whole field as a number (nan and inf included); false when it is not one.
bool parse_number(std::string_view field, std::string& scratch, double& v) {
  scratch.assign(field);  // strtod needs the terminating NUL
  char* end = nullptr;
  v = std::strtod(scratch.c_str(), &end);
  return !field.empty() && end == scratch.c_str() + scratch.size();
}

// Field text for a message, cut short when long.
std::string quote(std::string_view field) {
  return "'" + std::string(field.substr(0, 40)) + (field.size() > 40 ? "...'" : "'");
}

bool is_blank_line(const std::string& line) { return std::all_of(line.begin(), line.end(), is_blank); }

// Line 1 is a header when none of its fields is a number; a mix is a data row with a bad field.
bool is_header_line(const std::vector<std::string_view>& fields, std::string& scratch) {
  double v = 0;
  return std::none_of(fields.begin(), fields.end(), [&](std::string_view f) { return parse_number(f, scratch, v); });
}

// Appends the fields of one data row to m (m.cols set from the first row when still 0).
template <class T>
void append_csv_row(const std::vector<std::string_view>& fields, std::string& scratch, const RowRef& at,
                    Matrix<T>& m) {
  if (m.cols == 0) m.cols = fields.size();
  if (fields.size() != m.cols)
    at.fail("has " + std::to_string(fields.size()) + " values, expected " + std::to_string(m.cols) + " like row 1");
  double v = 0;
  for (std::size_t c = 0; c < fields.size(); ++c) {
    if (!parse_number(fields[c], scratch, v)) at.fail(column(c) + quote(fields[c]) + " is not a number");
    m.data.push_back(checked_value<T>(v, at, c));
  }
  ++m.rows;
}

void check_row_count(const std::string& path, std::uint64_t rows, bool header) {
  if (rows == 0) fail(path, header ? "no rows after the header line" : "empty file, no rows");
}

template <class T>
Matrix<T> read_csv_points(InFile& in) {
  const std::string& path = in.path();
  LineReader lines(in);
  Matrix<T> m;
  std::string line, scratch;
  std::vector<std::string_view> fields;
  std::size_t line_no = 0, blank_line = 0;
  bool header = false;
  while (lines.next(line)) {
    ++line_no;
    if (is_blank_line(line)) {  // allowed at the end only
      if (!blank_line) blank_line = line_no;
      continue;
    }
    if (blank_line) RowRef{path, m.rows + 1, blank_line}.fail("blank line (allowed only at the end of the file)");
    split_fields(line, fields);
    if (line_no == 1 && is_header_line(fields, scratch)) {
      header = true;
      continue;
    }
    append_csv_row(fields, scratch, RowRef{path, m.rows + 1, line_no}, m);
  }
  check_row_count(path, m.rows, header);
  return m;
}

// ---- parts of a file (kdspace-mpi) ---------------------------------------------------------------

// Part `part` of `parts` equal shares of `total` items: [begin, end), sizes differing by one at most.
std::pair<std::uint64_t, std::uint64_t> share(std::uint64_t total, std::size_t part, std::size_t parts) {
  const std::uint64_t each = total / parts, extra = total % parts;
  auto start = [&](std::uint64_t p) { return p * each + std::min<std::uint64_t>(p, extra); };
  return {start(part), start(part + 1)};
}

// The first byte at or after `offset` that starts a line (0, or just after a newline); the file size
// when there is none.
std::uint64_t line_start_from(InFile& in, std::uint64_t offset) {
  if (offset == 0 || offset >= in.size()) return std::min(offset, in.size());
  in.seek(offset - 1);
  std::vector<char> buf(in.chunk_bytes());
  std::uint64_t at = offset - 1;
  while (const std::size_t got = in.read_some(buf.data(), buf.size())) {
    if (const void* nl = std::memchr(buf.data(), '\n', got))
      return at + static_cast<std::uint64_t>(static_cast<const char*>(nl) - buf.data()) + 1;
    at += got;
  }
  return in.size();
}

// Lines of [plan.begin, end): how many, and the last that holds data (the header line does not).
void scan_csv_lines(InFile& in, std::uint64_t end, PartPlan& plan) {
  in.seek(plan.begin);
  std::vector<char> buf(in.chunk_bytes());
  std::uint64_t left = end - plan.begin;
  std::uint64_t other = 0;  // bytes of the current line other than spaces and tabs
  char last = '\n';         // the line's last byte so far
  bool open = false;        // a line has started and not ended
  auto end_line = [&] {
    // Blank: only spaces and tabs, but for a final '\r' (the reader drops it).
    const bool blank = other == 0 || (other == 1 && last == '\r');
    const bool header = plan.header && plan.begin == 0 && plan.units == 0;
    if (!blank && !header) plan.last_data_line = plan.units;
    ++plan.units;
    other = 0;
    open = false;
  };
  while (left > 0) {
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(left, buf.size()));
    const std::size_t got = in.read_some(buf.data(), want);
    if (got == 0) fail(in.path(), "the file shrank while being read");
    left -= got;
    for (std::size_t i = 0; i < got; ++i) {
      const char ch = buf[i];
      if (ch == '\n') {
        end_line();
        continue;
      }
      open = true;
      if (!is_blank(ch)) ++other;
      last = ch;
    }
  }
  if (open) end_line();  // the file's last line, without a newline
}

PartPlan plan_csv_part(InFile& in, std::size_t part, std::size_t parts) {
  PartPlan plan;
  plan.path = in.path();
  plan.format = Format::csv;
  // Line 1 (and 2, after a header) tell every part whether there is a header and how wide rows are.
  {
    LineReader lines(in);
    std::string line, scratch;
    std::vector<std::string_view> fields;
    if (lines.next(line) && !is_blank_line(line)) {
      split_fields(line, fields);
      plan.header = is_header_line(fields, scratch);
      if (plan.header && lines.next(line) && !is_blank_line(line)) split_fields(line, fields);
      if (!plan.header || !is_blank_line(line)) plan.cols = fields.size();
    }
  }
  const auto [first_byte, end_byte] = share(in.size(), part, parts);
  plan.begin = line_start_from(in, first_byte);
  const std::uint64_t end = std::max(plan.begin, line_start_from(in, end_byte));
  scan_csv_lines(in, end, plan);
  return plan;
}

template <class T>
Matrix<T> read_csv_part(const PartPlan& plan, std::uint64_t first_line, std::uint64_t data_end) {
  InFile in(plan.path);
  in.seek(plan.begin);
  LineReader lines(in);
  Matrix<T> m;
  m.cols = plan.cols;
  std::string line, scratch;
  std::vector<std::string_view> fields;
  const std::uint64_t header_lines = plan.header ? 1 : 0;
  for (std::uint64_t j = 0; j < plan.units; ++j) {
    if (!lines.next(line)) fail(plan.path, "the file changed while being read");
    const std::uint64_t index = first_line + j;  // 0-based line of the file
    if (index < header_lines) continue;
    // With no blank line before (it would have been reported first), the rows before are the lines.
    const RowRef at{plan.path, static_cast<std::size_t>(index - header_lines + 1), static_cast<std::size_t>(index + 1)};
    if (is_blank_line(line)) {
      if (index < data_end) at.fail("blank line (allowed only at the end of the file)");
      continue;
    }
    split_fields(line, fields);
    append_csv_row(fields, scratch, at, m);
  }
  return m;
}

PartPlan plan_binary_part(InFile& in, Format format, std::size_t part, std::size_t parts) {
  PartPlan plan;
  plan.path = in.path();
  plan.format = format;
  std::uint64_t total_rows = 0, data_offset = 0;
  if (format == Format::npy) {
    const NpyHeader h = read_npy_header(in);
    if (h.rows == 0) fail(in.path(), "no rows (shape " + h.shape + ")");
    plan.cols = h.cols;
    plan.row_bytes = h.cols * elem_bytes(h.elem);
    data_offset = in.size() - h.rows * plan.row_bytes;
    total_rows = h.rows;
  } else {
    std::int32_t d = 0;
    in.read_exact(&d, 4, RowRef{in.path(), 1});
    check_vecs_dimension(d, 0, RowRef{in.path(), 1});
    plan.cols = static_cast<std::size_t>(d);
    plan.row_bytes = 4 + plan.cols * elem_bytes(vecs_elem(format));
    total_rows = in.size() / plan.row_bytes;
    plan.last_part = part + 1 == parts;  // it also checks what follows the last whole row
  }
  const auto [first, end] = share(total_rows, part, parts);
  plan.first_row = first;
  plan.units = end - first;
  plan.begin = data_offset + first * plan.row_bytes;
  return plan;
}

template <class T>
Matrix<T> read_binary_part(const PartPlan& plan) {
  InFile in(plan.path);
  Elem e = vecs_elem(plan.format);
  if (plan.format == Format::npy) e = read_npy_header(in).elem;
  Matrix<T> m;
  m.rows = static_cast<std::size_t>(plan.units);
  m.cols = plan.cols;
  m.data.resize(m.rows * m.cols);
  in.seek(plan.begin);
  const bool vecs = plan.format != Format::npy;
  read_binary_rows(in, e, vecs, m, static_cast<std::size_t>(plan.first_row));
  if (vecs && plan.last_part && in.left() > 0) {  // a partial row at the end: wrong length, or cut off
    const RowRef at{in.path(), static_cast<std::size_t>(plan.first_row + m.rows + 1)};
    const std::uint64_t got = in.left();
    if (got >= 4) {
      std::int32_t d = 0;
      in.read_exact(&d, 4, at);
      check_vecs_dimension(d, m.cols, at);
    }
    at.fail(truncated(plan.row_bytes, got));
  }
  return m;
}

// ---- ragged rows ----------------------------------------------------------------------------------

template <class T>
RaggedRows<T> read_ragged(const std::string& path) {
  InFile in(path);
  RaggedRows<T> out;
  while (in.left() > 0) {
    const RowRef at{path, out.rows() + 1};
    std::int32_t d = 0;
    in.read_exact(&d, 4, at);
    if (d < 0) at.fail("length " + std::to_string(d) + " in the row header is negative");
    const std::size_t n = static_cast<std::size_t>(d);
    in.expect(n * sizeof(T), at, 4);  // before allocating
    out.values.resize(out.values.size() + n);
    in.read_exact(out.values.data() + out.values.size() - n, n * sizeof(T), at, 4);
    out.offsets.push_back(out.values.size());
  }
  return out;
}

// The int32 length at the start of a vecs row; says so when it does not fit.
std::int32_t row_length(const std::string& path, std::size_t n, std::size_t row) {
  if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    RowRef{path, row}.fail(std::to_string(n) + " values do not fit in a vecs row");
  return static_cast<std::int32_t>(n);
}

void write_length(OutFile& out, std::size_t n, std::size_t row) {
  const std::int32_t d = row_length(out.path(), n, row);
  out.write(&d, 4);
}

template <class T>
void check_ragged(const std::string& path, const RaggedRows<T>& rows) {
  const auto& o = rows.offsets;
  if (o.empty() || o.front() != 0 || o.back() != rows.values.size() || !std::is_sorted(o.begin(), o.end()))
    fail(path, "ragged rows are inconsistent: offsets must rise from 0 to the number of values");
}

template <class T>
std::vector<unsigned char> ragged_bytes(const std::string& path, const RaggedRows<T>& rows) {
  check_ragged(path, rows);
  const auto& o = rows.offsets;
  std::vector<unsigned char> bytes(4 * rows.rows() + rows.values.size() * sizeof(T));
  unsigned char* p = bytes.data();
  for (std::size_t r = 0; r < rows.rows(); ++r) {
    const std::int32_t d = row_length(path, o[r + 1] - o[r], r + 1);
    std::memcpy(p, &d, 4);
    if (d > 0) std::memcpy(p + 4, rows.values.data() + o[r], (o[r + 1] - o[r]) * sizeof(T));
    p += 4 + (o[r + 1] - o[r]) * sizeof(T);
  }
  return bytes;
}

template <class T>
void write_ragged(const std::string& path, const RaggedRows<T>& rows) {
  check_ragged(path, rows);
  const auto& o = rows.offsets;
  OutFile out(path);
  for (std::size_t r = 0; r < rows.rows(); ++r) {
    write_length(out, o[r + 1] - o[r], r + 1);
    out.write(rows.values.data() + o[r], (o[r + 1] - o[r]) * sizeof(T));
  }
  out.close();
}

// ---- writing points -------------------------------------------------------------------------------

template <class T>
void write_binary_points(OutFile& out, const Matrix<T>& m, Elem e, bool vecs) {
  const std::size_t eb = elem_bytes(e);
  std::vector<unsigned char> row(m.cols * eb);
  for (std::size_t r = 0; r < m.rows; ++r) {
    const RowRef at{out.path(), r + 1};
    for (std::size_t c = 0; c < m.cols; ++c) store(m.row(r)[c], e, row.data() + c * eb, at, c);
    if (vecs) write_length(out, m.cols, r + 1);
    out.write(row.data(), row.size());
  }
}

template <class T>
void write_npy_header(OutFile& out, const Matrix<T>& m) {
  std::string dict = std::string("{'descr': '") + (std::is_same_v<T, float> ? "<f4" : "<f8") +
                     "', 'fortran_order': False, 'shape': (" + std::to_string(m.rows) + ", " +
                     std::to_string(m.cols) + "), }";
  const std::size_t pre = 10;                          // magic, version 1.0, uint16 header length
  dict.append(63 - (pre + dict.size()) % 64, ' ');     // the data starts 64-byte aligned
  dict += '\n';
  if (dict.size() > 65535) fail(out.path(), "npy header too long");
  const unsigned char start[pre] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<unsigned char>(dict.size() & 0xff),
                                    static_cast<unsigned char>(dict.size() >> 8)};
  out.write(start, pre);
  out.write(dict.data(), dict.size());
}

template <class T>
void write_csv_points(OutFile& out, const Matrix<T>& m) {
  std::string line;
  for (std::size_t r = 0; r < m.rows; ++r) {
    line.clear();
    for (std::size_t c = 0; c < m.cols; ++c) line += (c ? "," : "") + show(m.row(r)[c]);
    line += '\n';
    out.write(line.data(), line.size());
  }
}

}  // namespace

// ---- public functions -------------------------------------------------------------------------------

Format format_from_path(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
  if (ext == ".fvecs") return Format::fvecs;
  if (ext == ".ivecs") return Format::ivecs;
  if (ext == ".bvecs") return Format::bvecs;
  if (ext == ".csv") return Format::csv;
  if (ext == ".npy") return Format::npy;
  fail(path, "unknown file extension (expected .fvecs, .ivecs, .bvecs, .csv or .npy)");
}

bool stores_double(const std::string& path) {
  const Format f = format_from_path(path);
  if (f != Format::npy) return f == Format::csv;
  InFile in(path);
  return read_npy_header(in).elem == Elem::f64;
}

template <class T>
Matrix<T> read_points(const std::string& path, const std::function<void(double)>& on_progress) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double> || std::is_same_v<T, std::uint8_t>,
                "points are float, double or bytes");
  const Format f = format_from_path(path);
  InFile in(path, on_progress);
  if (in.size() == 0) fail(path, "empty file, no rows");
  switch (f) {
    case Format::csv: return read_csv_points<T>(in);
    case Format::npy: return read_npy_points<T>(in);
    default: return read_vecs_points<T>(in, vecs_elem(f));
  }
}

PartPlan plan_part(const std::string& path, std::size_t part, std::size_t parts) {
  if (parts == 0 || part >= parts) fail(path, "part " + std::to_string(part) + " of " + std::to_string(parts) + " does not exist");
  const Format f = format_from_path(path);
  InFile in(path);
  if (in.size() == 0) fail(path, "empty file, no rows");
  return f == Format::csv ? plan_csv_part(in, part, parts) : plan_binary_part(in, f, part, parts);
}

template <class T>
Matrix<T> read_part(const PartPlan& plan, std::uint64_t first_line, std::uint64_t data_end) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "points are float or double");
  return plan.format == Format::csv ? read_csv_part<T>(plan, first_line, data_end) : read_binary_part<T>(plan);
}

void check_total_rows(const PartPlan& plan, std::uint64_t rows) { check_row_count(plan.path, rows, plan.header); }

RaggedRows<std::int32_t> read_ivecs_rows(const std::string& path) { return read_ragged<std::int32_t>(path); }
RaggedRows<float> read_fvecs_rows(const std::string& path) { return read_ragged<float>(path); }
void write_ivecs(const std::string& path, const RaggedRows<std::int32_t>& rows) { write_ragged(path, rows); }
void write_fvecs(const std::string& path, const RaggedRows<float>& rows) { write_ragged(path, rows); }
std::vector<unsigned char> ivecs_bytes(const std::string& path, const RaggedRows<std::int32_t>& rows) {
  return ragged_bytes(path, rows);
}
std::vector<unsigned char> fvecs_bytes(const std::string& path, const RaggedRows<float>& rows) {
  return ragged_bytes(path, rows);
}

template <class T>
void write_points(const std::string& path, const Matrix<T>& m) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "points are float or double");
  const Format f = format_from_path(path);
  if (m.data.size() != m.rows * m.cols) fail(path, "matrix data size does not match rows x cols");
  OutFile out(path);
  switch (f) {
    case Format::csv: write_csv_points(out, m); break;
    case Format::npy:
      write_npy_header(out, m);
      write_binary_points(out, m, std::is_same_v<T, float> ? Elem::f32 : Elem::f64, false);
      break;
    default: write_binary_points(out, m, vecs_elem(f), true); break;
  }
  out.close();
}

template Matrix<float> read_points<float>(const std::string&, const std::function<void(double)>&);
template Matrix<double> read_points<double>(const std::string&, const std::function<void(double)>&);
template Matrix<std::uint8_t> read_points<std::uint8_t>(const std::string&, const std::function<void(double)>&);
template Matrix<float> read_part<float>(const PartPlan&, std::uint64_t, std::uint64_t);
template Matrix<double> read_part<double>(const PartPlan&, std::uint64_t, std::uint64_t);
template void write_points<float>(const std::string&, const Matrix<float>&);
template void write_points<double>(const std::string&, const Matrix<double>&);

}  // namespace kdspace::io
