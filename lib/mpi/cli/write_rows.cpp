#include "write_rows.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

namespace kdspace::mpi::cli {

namespace {

// MPI counts are int: a rank's bytes go in pieces of at most 1 GiB.
constexpr std::uint64_t piece_bytes = std::uint64_t{1} << 30;

std::string system_error(const std::string& path, const std::string& what) {
  return path + ": " + what + ": " + std::strerror(errno);
}

}  // namespace

SharedOutput::SharedOutput(const detail::Comm& comm, const std::string& path,
                           const std::vector<unsigned char>& bytes)
    : comm_(comm), path_(path) {
  const std::uint64_t offset = comm_.sum_before(bytes.size());
  const std::uint64_t total = comm_.sum(bytes.size());
  // Rank 0 makes the temporary, of the final size, and tells the others its name (its process id).
  const std::uint64_t pid = static_cast<std::uint64_t>(::getpid());
  auto temp_name = [&](std::uint64_t id) { return path_ + ".kdspace-mpi-" + std::to_string(id) + ".tmp"; };
  const auto created = detail::Comm::run_catching([&] {
    if (comm_.rank() != 0) return;
    const std::string temp = temp_name(pid);
    const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0666);
    if (fd < 0) throw Error(system_error(path_, "cannot open for writing"));
    const bool sized = ::ftruncate(fd, static_cast<off_t>(total)) == 0;
    const int err = errno;
    ::close(fd);
    if (!sized) {
      ::unlink(temp.c_str());
      errno = err;
      throw Error(system_error(path_, "cannot make room for " + std::to_string(total) + " bytes"));
    }
  });
  temp_ = temp_name(comm_.agree(created, {comm_.rank() == 0 ? pid : 0}).front());

  try {
    write_part(bytes, offset);
  } catch (...) {
    if (comm_.rank() == 0) std::remove(temp_.c_str());
    throw;
  }
}

void SharedOutput::write_part(const std::vector<unsigned char>& bytes, std::uint64_t offset) const {
  comm_.phase([&] {
    MPI_File file;
    detail::check_mpi(MPI_File_open(MPI_COMM_SELF, temp_.c_str(), MPI_MODE_WRONLY, MPI_INFO_NULL, &file),
                      path_ + ": cannot open the temporary " + temp_);
    std::optional<std::string> failed;
    for (std::uint64_t done = 0; done < bytes.size() && !failed;) {
      const std::uint64_t n = std::min<std::uint64_t>(piece_bytes, bytes.size() - done);
      MPI_Status status;
      failed = detail::Comm::run_catching([&] {
        detail::check_mpi(MPI_File_write_at(file, static_cast<MPI_Offset>(offset + done), bytes.data() + done,
                                            static_cast<int>(n), MPI_BYTE, &status),
                          path_ + ": write failed");
      });
      done += n;
    }
    const int closed = MPI_File_close(&file);
    if (failed) throw Error(*failed);
    detail::check_mpi(closed, path_ + ": write failed");
  });
}

void SharedOutput::commit() {
  comm_.phase([&] {
    if (comm_.rank() == 0 && std::rename(temp_.c_str(), path_.c_str()) != 0)
      throw Error(system_error(path_, "cannot rename " + temp_ + " to it"));
  });
  committed_ = true;
}

SharedOutput::~SharedOutput() {
  if (!committed_ && comm_.rank() == 0 && !temp_.empty()) std::remove(temp_.c_str());
}

}  // namespace kdspace::mpi::cli
