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
