#include "kdspace/mpi/read_part.hpp"

#include <algorithm>

#include "comm.hpp"
#include "kdspace/io/vectors.hpp"

namespace kdspace::mpi {

template <class T>
FilePart<T> read_part(MPI_Comm mpi_comm, const std::string& path) {
  const detail::Comm comm(mpi_comm);
  io::PartPlan plan;
  comm.phase([&] {
    plan = io::plan_part(path, static_cast<std::size_t>(comm.rank()), static_cast<std::size_t>(comm.size()));
  });

  // Where this part's lines start in the file, and where the file's data ends (for .csv; for the
  // binary formats units are rows and the plan knows its first already).
  const std::vector<std::uint64_t> units = comm.gather_all(plan.units);
  std::uint64_t first_unit = 0;
  for (int r = 0; r < comm.rank(); ++r) first_unit += units[static_cast<std::size_t>(r)];
  const std::uint64_t last_data =
      plan.last_data_line == io::PartPlan::no_line ? 0 : first_unit + plan.last_data_line + 1;
  std::uint64_t data_end = 0;
  for (std::uint64_t end : comm.gather_all(last_data)) data_end = std::max(data_end, end);

  FilePart<T> part;
  comm.phase([&] { part.points = io::read_part<T>(plan, first_unit, data_end); });
  part.cols = plan.cols;
  const std::vector<std::uint64_t> rows = comm.gather_all(part.points.rows);
  for (int r = 0; r < comm.size(); ++r) {
    (r < comm.rank() ? part.first_row : part.total_rows) += rows[static_cast<std::size_t>(r)];
  }
  part.total_rows += part.first_row;
  io::check_total_rows(plan, part.total_rows);  // the same on every rank
  return part;
}

template FilePart<float> read_part<float>(MPI_Comm, const std::string&);
template FilePart<double> read_part<double>(MPI_Comm, const std::string&);

}  // namespace kdspace::mpi
