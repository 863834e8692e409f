#include "comm.hpp"

#include <algorithm>
#include <climits>
#include <new>

namespace kdspace::mpi::detail {

void check_mpi(int code, const std::string& what) {
  if (code == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  if (MPI_Error_string(code, text, &length) != MPI_SUCCESS) length = 0;
  throw Error(what + ": " + (length > 0 ? std::string(text, static_cast<std::size_t>(length)) : "MPI error"));
}

void BlockWriter::start() {
  blocks_.offsets.assign(sizes_.size() + 1, 0);
  for (std::size_t r = 0; r < sizes_.size(); ++r) blocks_.offsets[r + 1] = blocks_.offsets[r] + sizes_[r];
  blocks_.bytes.resize(blocks_.offsets.back());
  cursor_.assign(blocks_.offsets.begin(), blocks_.offsets.end() - 1);
}

Comm::Comm(MPI_Comm comm) : comm_(comm) {
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
}

std::string Comm::describe(std::exception_ptr e) {
  try {
    std::rethrow_exception(e);
  } catch (const std::bad_alloc&) {
    return "out of memory: this rank's share of the data or of the results does not fit";
  } catch (const std::exception& ex) {
    return ex.what();
  } catch (...) {
    return "unexpected internal error";
  }
}

std::vector<std::uint64_t> Comm::agree(const std::optional<std::string>& error,
                                       std::vector<std::uint64_t> values) const {
  // Slot 0 holds size - rank on a failing rank, so its maximum names the lowest failing rank.
  values.insert(values.begin(), error ? static_cast<std::uint64_t>(size_ - rank_) : 0);
  MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_UINT64_T, MPI_MAX, comm_);
  if (values[0] == 0) {
    values.erase(values.begin());
    return values;
  }
  // The failure path: the first failing rank's message to all, and the number of failing ranks.
  const int first = size_ - static_cast<int>(values[0]);
  std::string message = rank_ == first ? *error : std::string();
  std::uint64_t length = message.size();
  MPI_Bcast(&length, 1, MPI_UINT64_T, first, comm_);
  message.resize(static_cast<std::size_t>(std::min<std::uint64_t>(length, 4096)));
  MPI_Bcast(message.data(), static_cast<int>(message.size()), MPI_CHAR, first, comm_);
  int failed = error ? 1 : 0;
  MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_SUM, comm_);
  std::string what = "rank " + std::to_string(first) + " of " + std::to_string(size_) + ": " + message;
  if (failed > 1)
    what +=
        " (" + std::to_string(failed) + " of " + std::to_string(size_) + " ranks failed; the first is shown)";
  throw Error(what);
}

namespace {

// MPI counts and displacements are int: the smallest power-of-two unit (in bytes) in which this
// rank's blocks, each padded to whole units, fit.
std::uint64_t unit_needed(const std::vector<std::uint64_t>& sizes) {
  for (std::uint64_t unit = 1;; unit *= 2) {
    std::uint64_t units = 0;
    for (std::uint64_t s : sizes) units += (s + unit - 1) / unit;
    if (units <= static_cast<std::uint64_t>(INT_MAX)) return unit;
  }
}

}  // namespace

Blocks Comm::exchange(const Blocks& send, Traffic& traffic,
                      const std::optional<std::string>& error_before) const {
  const std::size_t ranks = static_cast<std::size_t>(size_);
  std::vector<std::uint64_t> send_sizes(ranks, 0), recv_sizes(ranks);
  const bool sending = !error_before && send.offsets.size() == ranks + 1;
  for (std::size_t r = 0; r < ranks && sending; ++r) send_sizes[r] = send.size(static_cast<int>(r));
  MPI_Alltoall(send_sizes.data(), 1, MPI_UINT64_T, recv_sizes.data(), 1, MPI_UINT64_T, comm_);

  Blocks received;
  std::vector<unsigned char> padded_send;
  std::optional<std::string> error = error_before;
  if (!error)
    error = run_catching([&] {
      received.offsets.assign(ranks + 1, 0);
      for (std::size_t r = 0; r < ranks; ++r) received.offsets[r + 1] = received.offsets[r] + recv_sizes[r];
      received.bytes.resize(received.offsets.back());
    });
  const std::uint64_t unit =
      agree(error, {std::max(unit_needed(send_sizes), unit_needed(recv_sizes))}).front();

  // Counts and displacements in units; blocks padded to whole units when a unit is more than a byte.
  auto layout = [&](const std::vector<std::uint64_t>& sizes, std::vector<int>& counts,
                    std::vector<int>& displs) {
    counts.resize(ranks);
    displs.resize(ranks);
    std::uint64_t at = 0;
    for (std::size_t r = 0; r < ranks; ++r) {
      counts[r] = static_cast<int>((sizes[r] + unit - 1) / unit);
      displs[r] = static_cast<int>(at);
      at += static_cast<std::uint64_t>(counts[r]);
    }
    return at * unit;
  };
  std::vector<int> send_counts, send_displs, recv_counts, recv_displs;
  const std::uint64_t send_bytes = layout(send_sizes, send_counts, send_displs);
  const std::uint64_t recv_bytes = layout(recv_sizes, recv_counts, recv_displs);
  const unsigned char* send_data = send.bytes.data();
  std::vector<unsigned char> padded_recv;
  if (unit > 1) {  // blocks of 2 GiB and more: rare enough for a copy
    phase([&] {
      padded_send.assign(send_bytes, 0);
      for (std::size_t r = 0; r < ranks; ++r)
        if (send_sizes[r] > 0)
          std::copy_n(send.data(static_cast<int>(r)), send_sizes[r],
                      padded_send.begin() +
                          static_cast<std::ptrdiff_t>(static_cast<std::uint64_t>(send_displs[r]) * unit));
      padded_recv.resize(recv_bytes);
    });
    send_data = padded_send.data();
  }
  MPI_Datatype unit_type = MPI_BYTE;
  if (unit > 1) {
    MPI_Type_contiguous(static_cast<int>(unit), MPI_BYTE, &unit_type);
    MPI_Type_commit(&unit_type);
  }
  unsigned char* recv_data = unit > 1 ? padded_recv.data() : received.bytes.data();
  MPI_Alltoallv(send_data, send_counts.data(), send_displs.data(), unit_type, recv_data, recv_counts.data(),
                recv_displs.data(), unit_type, comm_);
  if (unit > 1) {
    MPI_Type_free(&unit_type);
    for (std::size_t r = 0; r < ranks; ++r)
      std::copy_n(padded_recv.begin() +
                      static_cast<std::ptrdiff_t>(static_cast<std::uint64_t>(recv_displs[r]) * unit),
                  recv_sizes[r], received.bytes.begin() + static_cast<std::ptrdiff_t>(received.offsets[r]));
  }

  ++traffic.exchanges;
  for (std::size_t r = 0; r < ranks; ++r)
    if (static_cast<int>(r) != rank_ && send_sizes[r] > 0) {
      ++traffic.messages;
      traffic.bytes += send_sizes[r];
    }
  return received;
}

std::uint64_t Comm::sum_before(std::uint64_t value) const {
  std::uint64_t before = 0;
  MPI_Exscan(&value, &before, 1, MPI_UINT64_T, MPI_SUM, comm_);
  return rank_ == 0 ? 0 : before;  // MPI leaves rank 0's result undefined
}

std::uint64_t Comm::sum(std::uint64_t value) const {
  MPI_Allreduce(MPI_IN_PLACE, &value, 1, MPI_UINT64_T, MPI_SUM, comm_);
  return value;
}

std::vector<std::uint64_t> Comm::gather_all(std::uint64_t value) const {
  std::vector<std::uint64_t> all(static_cast<std::size_t>(size_));
  MPI_Allgather(&value, 1, MPI_UINT64_T, all.data(), 1, MPI_UINT64_T, comm_);
  return all;
}

}  // namespace kdspace::mpi::detail
