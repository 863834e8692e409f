// kdspace-mpi-bench: strong and weak scaling of DistributedTree k-NN under mpirun, with the traffic
// between ranks (messages and bytes a query) that docs/mpi.md models for 1,000 ranks.
//
//   mpirun -np P kdspace-mpi-bench [--scaling strong|weak] [--points N] [--queries Q] [--dim D]
//                                  [--k K] [--shape uniform|clustered] [--threads T]
//
// strong: N points and Q queries in all, whatever P; weak: N points and Q queries a rank. The data
// is a function of the point's global number (a counter-based hash), so every rank makes its own
// share without reading a file, and the same N gives the same points for every P. Rank 0 prints
// one JSON line; `checksum` (a hash of every answer's indices and distances) must be the same for
// every P of a strong-scaling series: bench/mpi_scaling.sh checks it.
#include <mpi.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "kdspace/mpi/distributed_tree.hpp"

namespace {

struct Options {
  std::string scaling = "strong";
  std::uint64_t points = 1000000;
  std::uint64_t queries = 100000;
  std::size_t dim = 3;
  std::size_t k = 10;
  std::string shape = "clustered";
  unsigned threads = 1;
};

std::uint64_t mix(std::uint64_t x) {  // splitmix64
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

double unit(std::uint64_t key) {
  return static_cast<double>(mix(key) >> 11) * 0x1.0p-53;
}  // [0, 1)

// Point `i` of stream `stream` (0: base, 1: queries): uniform in [0,1)^dim, or one of 64 Gaussian
// clusters of widths 0.002..0.05 (a scan-like density: dense clumps and empty space).
void make_point(const Options& o, std::uint64_t stream, std::uint64_t i, float* out) {
  const std::uint64_t key = (stream << 60) ^ (i * 0x100000001b3ULL);
  if (o.shape == "uniform") {
    for (std::size_t a = 0; a < o.dim; ++a) out[a] = static_cast<float>(unit(key + a));
    return;
  }
  const std::uint64_t cluster = mix(key) % 64;
  const double width = 0.002 + 0.048 * unit(cluster * 7919 + 1);
  for (std::size_t a = 0; a < o.dim; a += 2) {
    // Box-Muller: two normal deviates from two uniform ones.
    const double u1 = 1.0 - unit(key + 2 * a + 11), u2 = unit(key + 2 * a + 12);
    const double r = std::sqrt(-2.0 * std::log(u1)), t = 6.283185307179586 * u2;
    out[a] = static_cast<float>(unit(cluster * 131 + a) + width * r * std::cos(t));
    if (a + 1 < o.dim) out[a + 1] = static_cast<float>(unit(cluster * 131 + a + 1) + width * r * std::sin(t));
  }
}

std::vector<float> make_rows(const Options& o, std::uint64_t stream, std::uint64_t first,
                             std::uint64_t count) {
  std::vector<float> rows(count * o.dim);
  for (std::uint64_t i = 0; i < count; ++i) make_point(o, stream, first + i, rows.data() + i * o.dim);
  return rows;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string name = argv[i], value = argv[i + 1];
    if (name == "--scaling")
      o.scaling = value;
    else if (name == "--points")
      o.points = std::strtoull(value.c_str(), nullptr, 10);
    else if (name == "--queries")
      o.queries = std::strtoull(value.c_str(), nullptr, 10);
    else if (name == "--dim")
      o.dim = std::strtoull(value.c_str(), nullptr, 10);
    else if (name == "--k")
      o.k = std::strtoull(value.c_str(), nullptr, 10);
    else if (name == "--shape")
      o.shape = value;
    else if (name == "--threads")
      o.threads = static_cast<unsigned>(std::strtoul(value.c_str(), nullptr, 10));
    else
      throw std::runtime_error("unknown option " + name);
  }
  if ((argc - 1) % 2 != 0) throw std::runtime_error("options come in pairs: --name value");
  if (o.scaling != "strong" && o.scaling != "weak") throw std::runtime_error("--scaling strong|weak");
  if (o.shape != "uniform" && o.shape != "clustered") throw std::runtime_error("--shape uniform|clustered");
  return o;
}

double slowest(double seconds) {
  MPI_Allreduce(MPI_IN_PLACE, &seconds, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  return seconds;
}

std::uint64_t sum(std::uint64_t v) {
  MPI_Allreduce(MPI_IN_PLACE, &v, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
  return v;
}

int run(const Options& o) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  const std::uint64_t p = static_cast<std::uint64_t>(ranks), r = static_cast<std::uint64_t>(rank);
  const std::uint64_t n = o.scaling == "strong" ? o.points : o.points * p;
  const std::uint64_t nq = o.scaling == "strong" ? o.queries : o.queries * p;
  const std::uint64_t first = n * r / p, count = n * (r + 1) / p - first;
  const std::uint64_t q_first = nq * r / p, q_count = nq * (r + 1) / p - q_first;
  std::vector<float> rows = make_rows(o, 0, first, count);
  const std::vector<float> queries = make_rows(o, 1, q_first, q_count);

  kdspace::mpi::DistributedParams params;
  params.build.threads = o.threads;
  MPI_Barrier(MPI_COMM_WORLD);
  double start = MPI_Wtime();
  const kdspace::mpi::DistributedTree<float> tree(MPI_COMM_WORLD, rows.data(), count, o.dim, params);
  const double build_s = slowest(MPI_Wtime() - start);
  rows = {};

  kdspace::mpi::DistributedStats stats;
  MPI_Barrier(MPI_COMM_WORLD);
  start = MPI_Wtime();
  const kdspace::NeighborLists<float> found = tree.knn_batch(queries.data(), q_count, o.k, o.threads, &stats);
  const double query_s = slowest(MPI_Wtime() - start);

  // A hash of the answers in global query order: the sum over queries of a hash of (query, row).
  std::uint64_t checksum = 0;
  for (std::size_t q = 0; q < found.rows(); ++q) {
    std::uint64_t h = q_first + q;
    for (const auto& nb : found.row(q)) {
      std::uint32_t bits = 0;
      std::memcpy(&bits, &nb.distance, sizeof bits);
      h = mix(h ^ (std::uint64_t{nb.index} << 32 | bits));
    }
    checksum += h;
  }
  checksum = sum(checksum);
  const std::uint64_t messages = sum(stats.traffic.messages), bytes = sum(stats.traffic.bytes);
  const std::uint64_t asked = sum(stats.ranks_asked), points_visited = sum(stats.search.points_visited);
  const std::uint64_t build_bytes = sum(tree.build_traffic().bytes), candidates = sum(stats.candidates);
  std::uint64_t most = tree.local_size(), fewest = ~std::uint64_t{tree.local_size()};
  MPI_Allreduce(MPI_IN_PLACE, &most, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
  MPI_Allreduce(MPI_IN_PLACE, &fewest, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
  if (rank != 0) return 0;
  const double dq = static_cast<double>(nq);
  std::printf(
      "{\"scaling\": \"%s\", \"shape\": \"%s\", \"ranks\": %d, \"points\": %llu, \"queries\": %llu, \"dim\": "
      "%zu, "
      "\"k\": %zu, \"build_s\": %.4f, \"query_s\": %.4f, \"queries_per_s\": %.0f, \"ranks_per_query\": %.4f, "
      "\"messages_per_query\": %.5f, \"bytes_per_query\": %.2f, \"candidates_per_query\": %.3f, "
      "\"exchanges\": %llu, \"rounds\": %llu, "
      "\"points_visited_per_query\": %.2f, \"build_bytes_per_point\": %.2f, \"points_per_rank_min\": %llu, "
      "\"points_per_rank_max\": %llu, \"checksum\": \"%016llx\"}\n",
      o.scaling.c_str(), o.shape.c_str(), ranks, static_cast<unsigned long long>(n),
      static_cast<unsigned long long>(nq), o.dim, o.k, build_s, query_s, dq / query_s,
      static_cast<double>(asked) / dq, static_cast<double>(messages) / dq, static_cast<double>(bytes) / dq,
      static_cast<double>(candidates) / dq, static_cast<unsigned long long>(stats.traffic.exchanges),
      static_cast<unsigned long long>(stats.rounds), static_cast<double>(points_visited) / dq,
      static_cast<double>(build_bytes) / static_cast<double>(n), static_cast<unsigned long long>(~fewest),
      static_cast<unsigned long long>(most), static_cast<unsigned long long>(checksum));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int code = 0;
  try {
    code = run(parse(argc, argv));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-mpi-bench: %s\n", e.what());
    code = 1;
  }
  MPI_Finalize();
  return code;
}
