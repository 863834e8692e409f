// Writing one result file from all ranks, each rank its own rows, never a half-written file.
#pragma once

#include <string>
#include <vector>

#include "../comm.hpp"

namespace kdspace::mpi::cli {

/// An output file that all ranks write together: each rank's bytes at the offset the ranks before
/// it fill (rank order is row order), into a temporary file beside `path`; commit() renames it.
/// Until then `path` is untouched; the destructor removes an uncommitted temporary.
class SharedOutput {
 public:
  /// Collective: creates the temporary (rank 0) and writes every rank's bytes (MPI-IO, each rank on
  /// its own handle at its offset). Throws on every rank when any rank fails.
  SharedOutput(const detail::Comm& comm, const std::string& path, const std::vector<unsigned char>& bytes);
  ~SharedOutput();
  SharedOutput(const SharedOutput&) = delete;
  SharedOutput& operator=(const SharedOutput&) = delete;

  /// Collective: rank 0 renames the temporary to `path`. Throws on every rank when that fails.
  void commit();

 private:
  void write_part(const std::vector<unsigned char>& bytes, std::uint64_t offset) const;

  const detail::Comm& comm_;
  std::string path_, temp_;
  bool committed_ = false;
};

}  // namespace kdspace::mpi::cli
