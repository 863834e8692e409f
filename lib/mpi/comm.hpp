// The two things kdspace_mpi asks of MPI: agreement on errors, and all-to-all exchanges of bytes.
//
// Agreement. A rank that fails (bad data in its part of a file, out of memory) must not leave the
// others waiting in a collective call it will never make. So the work between two collective calls
// runs as a phase: each rank catches whatever its own work throws, then every rank calls agree(),
// one MPI_Allreduce; if any rank failed, all of them throw the same Error, which names the first
// failing rank and its message, and all leave the collective protocol at the same point. Nothing
// is collective inside a phase. (A rank that dies outright, killed or crashed, ends the whole job:
// mpirun's default.)
//
// Exchanges. Queries and answers travel in rounds: in each, every rank sends one block of bytes to
// each other rank (maybe empty) with one MPI_Alltoallv, not one message a query. Block sizes first
// go round with MPI_Alltoall. MPI counts are int; blocks larger than 2 GiB in all go in units of 2^u
// bytes (padded), u agreed by all ranks.
#pragma once

#include <mpi.h>

#include <cstddef>
#include <cstdint>
#include <exception>
#include <optional>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/mpi/distributed_tree.hpp"

namespace kdspace::mpi::detail {

using kdspace::mpi::Traffic;

/// One block of bytes for each rank, back to back: block r is bytes[offsets[r] .. offsets[r + 1]).
struct Blocks {
  std::vector<std::uint64_t> offsets;
  std::vector<unsigned char> bytes;

  std::uint64_t size(int r) const { return offsets[r + 1] - offsets[r]; }
  const unsigned char* data(int r) const { return bytes.data() + offsets[r]; }
};

/// Fills Blocks in two passes over the same items: count() the bytes for each destination, then
/// start() allocates and put() appends them in the same order.
class BlockWriter {
 public:
  explicit BlockWriter(int ranks) : sizes_(static_cast<std::size_t>(ranks), 0) {}

  void count(int to, std::size_t n) { sizes_[static_cast<std::size_t>(to)] += n; }
  void start();
  unsigned char* put(int to, std::size_t n) {
    unsigned char* p = blocks_.bytes.data() + cursor_[static_cast<std::size_t>(to)];
    cursor_[static_cast<std::size_t>(to)] += n;
    return p;
  }
  Blocks finish() { return std::move(blocks_); }

 private:
  std::vector<std::uint64_t> sizes_, cursor_;
  Blocks blocks_;
};

class Comm {
 public:
  explicit Comm(MPI_Comm comm);

  MPI_Comm get() const { return comm_; }
  int rank() const { return rank_; }
  int size() const { return size_; }

  /// Every rank calls this at the same point, with its own error (none when its work succeeded) and
  /// values to combine. Returns the maxima of `values` over all ranks. When any rank brings an
  /// error, every rank throws Error("rank R of P: MESSAGE"): R the lowest failing rank, MESSAGE its
  /// message, followed by how many ranks failed when more than one did.
  std::vector<std::uint64_t> agree(const std::optional<std::string>& error,
                                   std::vector<std::uint64_t> values = {}) const;

  /// Runs work() on this rank, then agree()s: returns on every rank or throws on every rank.
  template <class Work>
  void phase(Work&& work) const {
    agree(run_catching(work));
  }

  /// Sends block r of `send` to rank r and returns the blocks received, block s from rank s. Every
  /// rank calls it at the same point. Throws (on every rank) if any rank brings an error or cannot
  /// have its receive buffer.
  /// `error`: what the work that made `send` threw on this rank (then send may be empty); the
  /// exchange agrees on it first, so that work needs no phase of its own.
  Blocks exchange(const Blocks& send, Traffic& traffic, const std::optional<std::string>& error = {}) const;

  /// The sum over ranks before this one (MPI_Exscan; 0 on rank 0), and over all ranks.
  std::uint64_t sum_before(std::uint64_t value) const;
  std::uint64_t sum(std::uint64_t value) const;
  /// value of every rank, in rank order.
  std::vector<std::uint64_t> gather_all(std::uint64_t value) const;

  /// The message of whatever work() throws; none when it returns.
  template <class Work>
  static std::optional<std::string> run_catching(Work&& work) {
    try {
      work();
      return std::nullopt;
    } catch (...) {
      return describe(std::current_exception());
    }
  }

  /// A message for an exception: its what(), or what running out of memory means here.
  static std::string describe(std::exception_ptr e);

 private:
  MPI_Comm comm_;
  int rank_ = 0;
  int size_ = 1;
};

/// Throws Error(what) when an MPI call returned an error code (calls on files return them; the
/// others abort the job by MPI's default error handler).
void check_mpi(int code, const std::string& what);

}  // namespace kdspace::mpi::detail
