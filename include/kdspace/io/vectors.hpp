// Reading and writing vector files: .fvecs, .ivecs, .bvecs, .csv and .npy.
//
// Every problem with a file throws kdspace::Error whose message starts with the path and, where it
// applies, the 1-based data row: "data.fvecs: row 12: truncated: expected 512 bytes, file ends after 100".
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "kdspace/io/matrix.hpp"

namespace kdspace::io {

/// The file formats kdspace reads and writes; all binary formats are little-endian.
enum class Format {
  fvecs,  ///< per row: int32 d, then d float32
  ivecs,  ///< per row: int32 d, then d int32
  bvecs,  ///< per row: int32 d, then d uint8
  csv,    ///< one row per line, comma-separated numbers; an optional header line
  npy,    ///< NumPy array file (versions 1.0, 2.0, 3.0), 2-D (or 1-D = one column), C order
};

/// The format named by the extension of `path` (case-insensitive). Throws Error for any other extension.
Format format_from_path(const std::string& path);

/// Whether the file holds double precision: true for .csv and for .npy with dtype float64 (only the
/// .npy header is read), false for the other formats. Throws Error for an unknown extension or a bad
/// .npy header.
bool stores_double(const std::string& path);

/// Reads a point set, one point per row; the format is chosen by the extension. T is float, double
/// or std::uint8_t (the only instantiations compiled into the library). Every row must have the same
/// number of values, there must be at least one row, and every value must be finite (for float,
/// within float range; for std::uint8_t, an integer from 0 to 255: .bvecs files at a quarter of the
/// memory of float). Other element types of the file (.ivecs, .bvecs, .npy <i4 and |u1) are
/// converted. on_progress, when set, is called now and then with the fraction of the file read so
/// far (the last call passes 1).
template <class T>
Matrix<T> read_points(const std::string& path, const std::function<void(double)>& on_progress = {});

// ---- reading a point file in parts (kdspace-mpi: part r on process r) ------------------------------
//
// The parts cover the rows of the file in order, each a contiguous run, and no part reads the others:
//  - .fvecs .ivecs .bvecs .npy: rows have a fixed size once the header gives the dimension, so part p
//    of P seeks to its rows [p*n/P, (p+1)*n/P) (the shares differ by one row at most).
//  - .csv: rows have no fixed size. Part p holds the lines that start in its share of the bytes,
//    [p*S/P, (p+1)*S/P) of a file of S bytes (it reads its bytes and the rest of its last line).
//    Which row a line is depends on the lines before it, so reading takes two steps: plan_part counts
//    the part's lines; the caller adds up the counts of the parts before (an exclusive scan) and
//    passes the sum to read_part, with the end of the data (a blank line is allowed only after it).
// Errors name the file's rows (and lines) as read_points does, so that the first error of the first
// part that fails is the error read_points reports for the whole file.

/// Where one part of a point file lies; found by plan_part, read by read_part.
struct PartPlan {
  static constexpr std::uint64_t no_line = ~std::uint64_t{0};

  std::string path;
  Format format = Format::fvecs;
  std::size_t cols = 0;         ///< values a row (.csv: of the file's first data row; 0 without one)
  std::uint64_t units = 0;      ///< rows in the part (.csv: text lines, blank ones and the header included)
  std::uint64_t first_row = 0;  ///< binary formats: the 0-based file row of the part's first row
  std::uint64_t begin = 0;      ///< byte offset of the part's first row or line
  std::uint64_t row_bytes = 0;  ///< binary formats: bytes a row
  bool last_part = false;       ///< vecs: this part also checks the bytes after the last whole row
  bool header = false;          ///< .csv: line 1 of the file is a header
  /// .csv: the part's last line holding a data row (not blank, not the header), counted from the
  /// part's first line; no_line when it has none.
  std::uint64_t last_data_line = no_line;
};

/// Reads the header (and, for .csv, line 1 and the part's own bytes) of part `part` of `parts`.
PartPlan plan_part(const std::string& path, std::size_t part, std::size_t parts);

/// Reads and checks the rows of a planned part (T: float or double). For .csv, first_line is the
/// 0-based file line of the part's first line (the units of the parts before) and data_end one past
/// the file's last line holding data (0 when none): a blank line before it is an error.
template <class T>
Matrix<T> read_part(const PartPlan& plan, std::uint64_t first_line = 0, std::uint64_t data_end = 0);

/// The error read_points gives for a file without rows, if `rows` (all parts together) is 0.
void check_total_rows(const PartPlan& plan, std::uint64_t rows);

/// Rows of different lengths, stored back to back: row i is values[offsets[i] .. offsets[i + 1]).
/// The result files of radius search use this form.
template <class T>
struct RaggedRows {
  std::vector<std::size_t> offsets{0};
  std::vector<T> values;

  std::size_t rows() const { return offsets.size() - 1; }
};

/// Write ragged rows as .ivecs / .fvecs (each row with its own length; rows of length 0 allowed).
void write_ivecs(const std::string& path, const RaggedRows<std::int32_t>& rows);
void write_fvecs(const std::string& path, const RaggedRows<float>& rows);

/// The bytes write_ivecs / write_fvecs would write to `path` (named in errors), for writers that
/// place them themselves: kdspace-mpi writes each process's rows at its own offset of one file.
std::vector<unsigned char> ivecs_bytes(const std::string& path, const RaggedRows<std::int32_t>& rows);
std::vector<unsigned char> fvecs_bytes(const std::string& path, const RaggedRows<float>& rows);

/// Read ragged rows back. The values are not checked (NaN is kept); lengths and truncation are.
/// An empty file gives zero rows.
RaggedRows<std::int32_t> read_ivecs_rows(const std::string& path);
RaggedRows<float> read_fvecs_rows(const std::string& path);

/// Writes a point set in the format chosen by the extension: .fvecs (values must fit in float32),
/// .ivecs / .bvecs (values must be integers in int32 range / 0..255), .csv (shortest text that reads
/// back exactly), .npy (<f4 for float, <f8 for double). T is float or double. Non-finite values are
/// written as they are (where the format can hold them), so that tests can make bad files.
template <class T>
void write_points(const std::string& path, const Matrix<T>& m);

}  // namespace kdspace::io
