// kdspace-bench: the point workloads of kdspace side by side with FLANN (KDTreeSingleIndex, leaf 10),
// nanoflann (KDTreeSingleIndexAdaptor, leaf 10, run-time and compile-time dimension), CGAL's Kd_tree
// (3-D) and FAISS's IndexFlatL2 (a BLAS scan, from 32-D on) on identical data, in one process; with
// --python-peers, pykdtree and SciPy's cKDTree in a separate process (bench/python_peers.py).
//
// Data: synthetic (uniform and Gaussian blobs, 3-D to 128-D), MFCC frames of synthetic audio (13-D,
// 20-D), real 3-D scans and meshes (--real DIR, from bench/real_data/fetch.sh DIR: a random tenth of
// each set's points held out as the queries), dense SIFT-like descriptors of photographs (--images
// DIR: 128-D), and file pairs (--fvecs/--bvecs).
//
// For each workload every library builds its index and answers the same queries: exact 1-NN and
// 10-NN (one thread), radius search at two radii (mean count ~10 and ~100), box search (kdspace and
// CGAL; a plain scan is the reference), approximate 10-NN at eps 0.5 and 2 (recall@10 against the
// exact answers), and batched exact 10-NN on 1 and 2 threads. Repetitions are interleaved across
// libraries (repetition loop outside, libraries inside) so that a drift in machine speed hits all
// alike; within a repetition an operation repeats until it has run --min-time seconds (the small real
// sets answer all their queries in a millisecond), each pass answering the queries in a new seeded
// order (PassOrders), and the median over repetitions is reported. Every
// exact answer is cross-checked (10-NN and 1-NN distances at every rank within 1e-5 relative; radius
// counts equal; box counts and index lists equal) and kdspace's own 10-NN answers are checked against
// brute force on a sample; any disagreement makes the exit status 1 (FAISS's flat index is not exact
// by design: its disagreements are reported, not failed).
//
// usage: kdspace-bench [--workload NAME]... [--quick] [--reps R] [--queries Q] [--min-time S]
//                      [--real DIR] [--images DIR] [--python-peers SCRIPT]
//                      [--fvecs BASE QUERIES]... [--bvecs BASE QUERIES]... [--list]
//   --workload NAME   run this workload (repeatable); default: all built-in ones plus the real and
//                     image sets when their folders are given, or only the files when --fvecs/--bvecs
//                     are given
//   --quick           n and queries / 10, one repetition (for development)
//   --reps R          repetitions (default 3; 1 with --quick)
//   --queries Q       at most Q queries per workload
//   --min-time S      seconds each measurement runs at least (default 0.1)
//   --clock wall|cpu  wall time (default), or the process's CPU time, which other work on a busy
//                     machine does not inflate (no 2-thread figures then)
//   --real DIR        the real scans and meshes listed in DIR/real_data.txt (bench/real_data/fetch.sh)
//   --images DIR      the photographs for the images128d set (bench/run_all.sh fetches them)
//   --python-peers SCRIPT  run SCRIPT (bench/python_peers.py) with /usr/bin/python3 on every workload
//   --fvecs/--bvecs   a base and a query file (read with kdspace::io::read_points; the extension picks
//                     the format); the workload is named after the base file
//
// Output: per workload a markdown table (rows: libraries; columns: measurements; last row: kdspace ÷
// best peer), then one JSON line per measurement ({"bench":"points",...}; the Python peers print
// {"bench":"points-python",...}). Progress goes to stderr.
#include <dlfcn.h>
#include <flann/flann.hpp>
#include <nanoflann.hpp>
#ifdef KDSPACE_BENCH_CGAL
#include <CGAL/Fuzzy_iso_box.h>
#include <CGAL/Fuzzy_sphere.h>
#include <CGAL/Kd_tree.h>
#include <CGAL/Orthogonal_k_neighbor_search.h>
#include <CGAL/Search_traits_3.h>
#include <CGAL/Simple_cartesian.h>
#endif
#ifdef KDSPACE_BENCH_FAISS
#include <faiss/IndexFlat.h>
#endif
#ifdef _OPENMP
#include <omp.h>
#endif

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "synthetic_audio.hpp"
#include "image_features.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/kdspace.hpp"
#include "real_data/mesh_io.hpp"

namespace {

// The clock of every measurement: wall time (steady_clock), or with --clock cpu the CPU time of the
// whole process (every thread of every library counted), which a machine busy with other work
// cannot inflate by taking the processor away; the 2-thread measurements need the wall clock and are
// left out then.
bool g_cpu_clock = false;

double clock_now() {
  if (g_cpu_clock) {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double seconds_since(double start) { return clock_now() - start; }
double dbl(std::size_t x) { return static_cast<double>(x); }

// A measurement repeats its operation until the repetitions add up to this many seconds, and
// reports the mean time of one: the real scans answer all their held-out queries in about a
// millisecond, too short for one reading of the clock. --min-time sets it.
double g_min_seconds = 0.1;

// Calls `pass` (one pass of an operation, given its number 0, 1, ...: its seconds, or a negative
// number when the library has no such operation) until the passes add up to g_min_seconds; returns
// the mean seconds of a pass.
template <class Pass>
double timed(Pass&& pass) {
  double total = 0;
  std::size_t passes = 0;
  do {
    const double s = pass(passes);
    if (s < 0) return s;
    total += s;
    ++passes;
  } while (total < g_min_seconds);
  return total / dbl(passes);
}

// The thread counts of OpenMP (FLANN's and FAISS's loops) and of OpenBLAS (FAISS's sgemm). OpenBLAS
// is looked up at run time, so that the bench runs with whichever BLAS libblas.so.3 is.
void set_threads(unsigned threads) {
#ifdef _OPENMP
  omp_set_num_threads(static_cast<int>(threads));
#endif
  using SetThreads = void (*)(int);
  static const auto openblas = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (openblas) openblas(static_cast<int>(threads));
}

std::string blas_name() {
  using GetConfig = char* (*)();
  const auto config = reinterpret_cast<GetConfig>(dlsym(RTLD_DEFAULT, "openblas_get_config"));
  return config ? std::string("OpenBLAS (") + config() + ")" : "a BLAS other than OpenBLAS";
}

// ---- workloads ------------------------------------------------------------------------------------

struct WorkloadSpec {
  const char* name;
  const char* data;  // "uniform" or "clustered"
  std::size_t n, dim, queries;
};

// Query counts keep each measurement of one library to a few seconds at most on the project's
// 2-core machine (the slowest peer, nanoflann, answers ~50 10-NN queries a second on uniform 64-D
// data and ~250 on uniform 16-D, where every tree degrades towards a scan).
const WorkloadSpec kWorkloads[] = {
    {"uniform3d", "uniform", 1000000, 3, 100000},      {"clustered3d", "clustered", 1000000, 3, 100000},
    {"uniform8d", "uniform", 1000000, 8, 5000},        {"clustered8d", "clustered", 1000000, 8, 10000},
    {"clustered16d", "clustered", 100000, 16, 20000},  {"uniform16d", "uniform", 100000, 16, 1000},
    {"clustered64d", "clustered", 100000, 64, 2000},   {"uniform64d", "uniform", 100000, 64, 200},
    {"clustered128d", "clustered", 100000, 128, 2000},
    // MFCC frames of synthetic audio (synthetic_audio.hpp): the 13 or 20 static cepstral coefficients.
    {"mfcc13", "mfcc", 100000, 13, 20000},             {"mfcc20", "mfcc", 100000, 20, 20000},
};

// Uniform points in [0, 1)^dim, or Gaussian blobs: 64 centres uniform in [0, 1)^dim (the same for base
// and queries), standard deviation 0.03 on every axis.
std::vector<float> make_points(std::size_t n, std::size_t dim, bool clustered, std::uint32_t seed) {
  std::mt19937 centre_rng(12345);
  std::uniform_real_distribution<float> uniform(0.f, 1.f);
  std::vector<float> centres(64 * dim);
  for (auto& c : centres) c = uniform(centre_rng);
  std::mt19937 rng(seed);
  std::normal_distribution<float> spread(0.f, 0.03f);
  std::vector<float> points(n * dim);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t blob = rng() % 64;
    for (std::size_t a = 0; a < dim; ++a)
      points[i * dim + a] = clustered ? centres[blob * dim + a] + spread(rng) : uniform(rng);
  }
  return points;
}

/// One workload's data and the parameters derived from it before any timing.
struct Problem {
  std::string name, data;  // data: uniform, clustered or file
  std::size_t n = 0, dim = 0, nq = 0;
  std::vector<float> base, queries;  // row-major
  float radius[2] = {0, 0};          // radius10, radius100 (true distances)
  float half_width = 0;              // of the query boxes, on every axis
  std::vector<float> box_lo, box_hi;  // nq boxes centred on the queries
  std::size_t scan_boxes = 0;         // boxes the plain scan answers (the first ones)
  std::size_t brute_checks = 0;       // queries whose exact 10-NN are checked against brute force
};

// ---- answers and their comparison -----------------------------------------------------------------

struct KnnAnswers {
  std::size_t k = 0;
  std::vector<std::uint32_t> ids;
  std::vector<float> dists;  // true distances
  void reset(std::size_t nq, std::size_t kk) {
    k = kk;
    ids.assign(nq * kk, 0);
    dists.assign(nq * kk, 0.f);
  }
};

struct BoxAnswers {
  std::vector<std::uint32_t> counts;               // per box
  std::vector<std::vector<std::uint32_t>> lists;   // the first boxes' indices, ascending
};

bool close_enough(float d, float ref) { return d == ref || std::abs(d - ref) <= 1e-5f * ref; }

// Entries (query, rank) whose distance differs from the reference's beyond 1e-5 relative.
std::size_t knn_disagreements(const KnnAnswers& a, const KnnAnswers& ref) {
  std::size_t bad = 0;
  for (std::size_t i = 0; i < ref.dists.size(); ++i) bad += close_enough(a.dists[i], ref.dists[i]) ? 0 : 1;
  return bad;
}

// Share of the true 10 nearest found: returned neighbours (distinct points) no farther than the true
// 10th, within 1e-5 relative (so that a tie at the 10th place counts as found).
double recall_at_10(const KnnAnswers& a, const KnnAnswers& exact) {
  std::size_t found = 0;
  const std::size_t nq = exact.dists.size() / 10;
  for (std::size_t q = 0; q < nq; ++q) {
    const float limit = exact.dists[q * 10 + 9] * (1 + 1e-5f);
    for (std::size_t j = 0; j < 10; ++j) found += a.dists[q * 10 + j] <= limit ? 1 : 0;
  }
  return dbl(found) / dbl(nq * 10);
}

// Points of the base within 1e-5 relative of distance r from query q (in double): how many points a
// rounding difference between two libraries (or their < versus <= at the radius) could move.
std::size_t boundary_points(const Problem& p, std::size_t q, float r) {
  std::size_t count = 0;
  const float* x = p.queries.data() + q * p.dim;
  for (std::size_t i = 0; i < p.n; ++i) {
    double s = 0;
    for (std::size_t a = 0; a < p.dim; ++a) {
      const double d = static_cast<double>(p.base[i * p.dim + a]) - static_cast<double>(x[a]);
      s += d * d;
    }
    if (std::abs(std::sqrt(s) - static_cast<double>(r)) <= 1e-5 * static_cast<double>(r)) ++count;
  }
  return count;
}

// ---- the libraries --------------------------------------------------------------------------------

enum Op : int { kBuild, kKnn1, kKnn10, kKnn1Loop, kKnn10Loop, kRadius10, kRadius100, kBox, kApprox05, kApprox2, kBatch2, kOps };
const char* const kOpNames[kOps] = {"build",    "knn1",      "knn10", "knn1",          "knn10",       "radius10",
                                    "radius100", "box",      "approx_eps0.5", "approx_eps2", "batch10"};
const double kApproxEps[2] = {0.5, 2.0};

/// One library under test. Each query method answers the problem's queries on one thread (unless it
/// says otherwise) and returns the seconds its library's calls took, or a negative number when the
/// library has no such operation. Conversions (squared to true distances, index types) happen
/// after the clock stops.
class Library {
 public:
  Library(const Problem& problem, std::string library_key, std::string library_label, bool kdspace_library)
      : key(std::move(library_key)), label(std::move(library_label)), is_kdspace(kdspace_library), p(problem) {}
  virtual ~Library() = default;

  virtual double build() { return -1; }
  virtual void release() {}
  /// Bytes the index holds besides a copy of the points; negative when unknown.
  virtual double index_bytes() { return -1; }
  virtual double knn(std::size_t /*k*/, double /*eps*/, KnnAnswers& /*out*/) { return -1; }
  virtual double knn_loop(std::size_t /*k*/, KnnAnswers& /*out*/) { return -1; }
  virtual double radius(float /*r*/, std::vector<std::uint32_t>& /*counts*/) { return -1; }
  virtual double box(BoxAnswers& /*out*/) { return -1; }
  /// Exact k-NN of all queries, batched over `threads` threads.
  virtual double knn_threads(std::size_t /*k*/, unsigned /*threads*/, KnnAnswers& /*out*/) { return -1; }
  virtual bool is_peer() const { return !is_kdspace; }
  /// Whether its k-NN answers are exact (FAISS's flat index is not: see FaissFlatLibrary). The
  /// answers of an inexact library are compared and reported, but do not fail the run.
  virtual bool exact_answers() const { return true; }

  const std::string key, label;
  const bool is_kdspace;

  // Measurements, filled by the runner.
  std::vector<double> seconds[kOps];
  std::size_t queries[kOps] = {};
  double bytes_per_point = -1;
  double recall[2] = {-1, -1};
  std::size_t disagreements[kOps] = {};
  std::size_t boundary[kOps] = {};

 protected:
  const Problem& p;
};

template <int Dim>
class KdspaceLibrary : public Library {
 public:
  using Tree = kdspace::PointTree<float, Dim>;
  KdspaceLibrary(const Problem& problem, std::string library_key, std::string library_label)
      : Library(problem, std::move(library_key), std::move(library_label), true) {}

  double build() override {
    const double start = clock_now();
    tree_ = std::make_unique<Tree>(p.base.data(), p.n, p.dim);  // default BuildParams: leaf 16, 1 thread
    return seconds_since(start);
  }
  void release() override { tree_.reset(); }
  double index_bytes() override { return dbl(tree_->index_bytes()); }

  double knn(std::size_t k, double eps, KnnAnswers& out) override {
    kdspace::SearchParams params;
    params.eps = eps;
    const double start = clock_now();
    const auto lists = tree_->knn_batch(p.queries.data(), p.nq, k, params, 1);
    const double s = seconds_since(start);
    copy(lists, k, out);
    return s;
  }

  double knn_loop(std::size_t k, KnnAnswers& out) override {
    out.reset(p.nq, k);
    const double start = clock_now();
    for (std::size_t q = 0; q < p.nq; ++q) {
      const auto found = tree_->knn(p.queries.data() + q * p.dim, k);
      for (std::size_t j = 0; j < k; ++j) out.ids[q * k + j] = found[j].index, out.dists[q * k + j] = found[j].distance;
    }
    return seconds_since(start);
  }

  double radius(float r, std::vector<std::uint32_t>& counts) override {
    const double start = clock_now();
    const auto lists = tree_->radius_batch(p.queries.data(), p.nq, r, std::numeric_limits<std::size_t>::max(), 1);
    const double s = seconds_since(start);
    counts.resize(p.nq);
    for (std::size_t q = 0; q < p.nq; ++q) counts[q] = static_cast<std::uint32_t>(lists.row(q).size());
    return s;
  }

  double box(BoxAnswers& out) override {
    out.counts.assign(p.nq, 0);
    out.lists.assign(p.scan_boxes, {});
    const double start = clock_now();
    for (std::size_t b = 0; b < p.nq; ++b) {
      auto found = tree_->box(p.box_lo.data() + b * p.dim, p.box_hi.data() + b * p.dim);
      out.counts[b] = static_cast<std::uint32_t>(found.size());
      if (b < p.scan_boxes) out.lists[b] = std::move(found);
    }
    return seconds_since(start);
  }

  double knn_threads(std::size_t k, unsigned threads, KnnAnswers& out) override {
    const double start = clock_now();
    const auto lists = tree_->knn_batch(p.queries.data(), p.nq, k, {}, threads);
    const double s = seconds_since(start);
    copy(lists, k, out);
    return s;
  }

 private:
  void copy(const kdspace::NeighborLists<float>& lists, std::size_t k, KnnAnswers& out) const {
    out.reset(p.nq, k);
    for (std::size_t i = 0; i < p.nq * k; ++i) out.ids[i] = lists.neighbors[i].index, out.dists[i] = lists.neighbors[i].distance;
  }
  std::unique_ptr<Tree> tree_;
};

class FlannLibrary : public Library {
 public:
  explicit FlannLibrary(const Problem& problem) : Library(problem, "flann", "FLANN KDTreeSingleIndex (leaf 10)", false) {}

  double build() override {
    flann::Matrix<float> data(const_cast<float*>(p.base.data()), p.n, p.dim);
    const double start = clock_now();
    index_ = std::make_unique<Index>(data, flann::KDTreeSingleIndexParams(10));  // reorder = true: copies the points
    index_->buildIndex();
    return seconds_since(start);
  }
  void release() override { index_.reset(); }

  // FLANN's usedMemory() counts its node pool and its int index array; NNIndex also keeps a vector of
  // n row pointers (NNIndex::points_, flann/algorithms/nn_index.h) that it does not count, added here.
  // The reordered copy of the points (reorder = true) is the "copy of the points" and not counted.
  double index_bytes() override { return dbl(static_cast<std::size_t>(index_->usedMemory())) + dbl(p.n * sizeof(float*)); }

  double knn(std::size_t k, double eps, KnnAnswers& out) override { return search(k, eps, 1, out); }
  double knn_threads(std::size_t k, unsigned threads, KnnAnswers& out) override {
#ifdef _OPENMP
    return search(k, 0.0, threads, out);
#else
    // Without OpenMP FLANN ignores SearchParams::cores: the figure would be a 1-thread one.
    return threads == 1 ? search(k, 0.0, 1, out) : -1;
#endif
  }

  // FLANN's radiusSearch takes the squared radius for L2 and returns squared distances, and keeps
  // points with squared distance < radius (kdspace: distance <= r); the cross-check allows for that.
  double radius(float r, std::vector<std::uint32_t>& counts) override {
    flann::Matrix<float> q(const_cast<float*>(p.queries.data()), p.nq, p.dim);
    std::vector<std::vector<std::size_t>> ids;
    std::vector<std::vector<float>> dists;
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0.0f, true);  // sorted, like the others
    params.cores = 1;
    params.max_neighbors = -1;
    const double start = clock_now();
    index_->radiusSearch(q, ids, dists, r * r, params);
    const double s = seconds_since(start);
    counts.resize(p.nq);
    for (std::size_t i = 0; i < p.nq; ++i) counts[i] = static_cast<std::uint32_t>(ids[i].size());
    return s;
  }

 private:
  using Index = flann::Index<flann::L2_Simple<float>>;

  double search(std::size_t k, double eps, unsigned threads, KnnAnswers& out) {
    flann::Matrix<float> q(const_cast<float*>(p.queries.data()), p.nq, p.dim);
    std::vector<std::size_t> ids(p.nq * k);
    out.reset(p.nq, k);
    flann::Matrix<std::size_t> id_matrix(ids.data(), p.nq, k);
    flann::Matrix<float> dist_matrix(out.dists.data(), p.nq, k);
    // FLANN applies eps to squared distances: a result within (1 + eps) of the true squared distance.
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, static_cast<float>(eps), true);
    params.cores = static_cast<int>(threads);
    const double start = clock_now();
    index_->knnSearch(q, id_matrix, dist_matrix, k, params);
    const double s = seconds_since(start);
    for (std::size_t i = 0; i < p.nq * k; ++i) {
      out.ids[i] = static_cast<std::uint32_t>(ids[i]);
      out.dists[i] = std::sqrt(out.dists[i]);  // FLANN's L2 distances are squared
    }
    return s;
  }
  std::unique_ptr<Index> index_;
};

// nanoflann reads the points through an adaptor (no copy of them).
struct RowMajorCloud {
  const float* data;
  std::size_t n, dim;
  std::size_t kdtree_get_point_count() const { return n; }
  float kdtree_get_pt(std::size_t i, std::size_t a) const { return data[i * dim + a]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};

template <int Dim>
class NanoflannLibrary : public Library {
 public:
  NanoflannLibrary(const Problem& problem, std::string library_key, std::string library_label)
      : Library(problem, std::move(library_key), std::move(library_label), false),
        cloud_{problem.base.data(), problem.n, problem.dim} {}

  double build() override {
    const double start = clock_now();
    index_ = std::make_unique<Index>(static_cast<int>(p.dim), cloud_, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    return seconds_since(start);
  }
  void release() override { index_.reset(); }
  // nanoflann's usedMemory(): its node pool (used and wasted) and its uint32 index array.
  double index_bytes() override { return dbl(index_->usedMemory(*index_)); }

  // nanoflann applies eps to squared distances, as FLANN does.
  double knn(std::size_t k, double eps, KnnAnswers& out) override {
    out.reset(p.nq, k);
    const nanoflann::SearchParams params(32, static_cast<float>(eps));
    const double start = clock_now();
    for (std::size_t q = 0; q < p.nq; ++q) {
      nanoflann::KNNResultSet<float, std::uint32_t> results(k);
      results.init(out.ids.data() + q * k, out.dists.data() + q * k);
      index_->findNeighbors(results, p.queries.data() + q * p.dim, params);
    }
    const double s = seconds_since(start);
    for (auto& d : out.dists) d = std::sqrt(d);  // squared for L2
    return s;
  }

  // radiusSearch takes the squared radius for L2 (L2_Simple_Adaptor works on squared distances) and
  // keeps points with squared distance < radius.
  double radius(float r, std::vector<std::uint32_t>& counts) override {
    counts.resize(p.nq);
    std::vector<std::pair<std::uint32_t, float>> found;
    const nanoflann::SearchParams params(32, 0.f, true);  // sorted, like the others
    const float r2 = r * r;
    const double start = clock_now();
    for (std::size_t q = 0; q < p.nq; ++q)
      counts[q] = static_cast<std::uint32_t>(index_->radiusSearch(p.queries.data() + q * p.dim, r2, found, params));
    return seconds_since(start);
  }

 private:
  using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, RowMajorCloud>, RowMajorCloud,
                                                    Dim, std::uint32_t>;
  RowMajorCloud cloud_;
  std::unique_ptr<Index> index_;
};

/// The reference for box search: test every point.
class ScanLibrary : public Library {
 public:
  explicit ScanLibrary(const Problem& problem) : Library(problem, "scan", "plain scan (box reference)", false) {}
  bool is_peer() const override { return false; }
  double box(BoxAnswers& out) override {
    out.counts.assign(p.scan_boxes, 0);
    out.lists.assign(p.scan_boxes, {});
    const std::size_t d = p.dim;
    const double start = clock_now();
    for (std::size_t b = 0; b < p.scan_boxes; ++b) {
      const float* lo = p.box_lo.data() + b * d;
      const float* hi = p.box_hi.data() + b * d;
      auto& found = out.lists[b];
      const float* x = p.base.data();
      for (std::size_t i = 0; i < p.n; ++i, x += d) {
        std::size_t a = 0;
        while (a < d && lo[a] <= x[a] && x[a] <= hi[a]) ++a;
        if (a == d) found.push_back(static_cast<std::uint32_t>(i));
      }
      out.counts[b] = static_cast<std::uint32_t>(found.size());
    }
    return seconds_since(start);
  }
};

#ifdef KDSPACE_BENCH_CGAL
// CGAL's Kd_tree (Search_traits_3 over float points: 3-D only), with its default splitter (sliding
// midpoint, buckets of 10 points). The tree copies the points; the conversion of the rows to CGAL
// points happens before the clock starts, as nanoflann's adaptor does without a copy.
class CgalLibrary : public Library {
 public:
  explicit CgalLibrary(const Problem& problem)
      : Library(problem, "cgal", "CGAL Kd_tree (sliding midpoint, bucket 10)", false) {
    for (std::size_t i = 0; i < p.n; ++i) points_.push_back(point(p.base.data() + i * 3));
  }

  double build() override {
    const double start = clock_now();
    tree_ = std::make_unique<Tree>(points_.begin(), points_.end());
    tree_->build();  // CGAL builds lazily on the first query otherwise
    return seconds_since(start);
  }
  void release() override { tree_.reset(); }

  // Orthogonal_k_neighbor_search reports squared distances (Euclidean_distance's transformed ones).
  double knn(std::size_t k, double eps, KnnAnswers& out) override {
    if (eps != 0) return -1;
    out.reset(p.nq, k);
    const double start = clock_now();
    for (std::size_t q = 0; q < p.nq; ++q) {
      Search search(*tree_, point(p.queries.data() + q * 3), static_cast<unsigned>(k));
      std::size_t j = 0;
      for (auto it = search.begin(); it != search.end() && j < k; ++it, ++j) out.dists[q * k + j] = it->second;
    }
    const double s = seconds_since(start);
    for (auto& d : out.dists) d = std::sqrt(d);
    return s;
  }

  // Fuzzy_sphere with fuzziness 0 keeps the points at distance <= r; counted, not stored.
  double radius(float r, std::vector<std::uint32_t>& counts) override {
    counts.assign(p.nq, 0);
    const double start = clock_now();
    for (std::size_t q = 0; q < p.nq; ++q)
      tree_->search(Counter{&counts[q]}, CGAL::Fuzzy_sphere<Traits>(point(p.queries.data() + q * 3), r, 0.f));
    return seconds_since(start);
  }

  // Fuzzy_iso_box with fuzziness 0: the closed box. Counts only (CGAL's points carry no index).
  double box(BoxAnswers& out) override {
    out.counts.assign(p.nq, 0);
    out.lists.clear();
    const double start = clock_now();
    for (std::size_t b = 0; b < p.nq; ++b)
      tree_->search(Counter{&out.counts[b]}, CGAL::Fuzzy_iso_box<Traits>(point(p.box_lo.data() + b * 3),
                                                                         point(p.box_hi.data() + b * 3), 0.f));
    return seconds_since(start);
  }

 private:
  using Kernel = CGAL::Simple_cartesian<float>;
  using Traits = CGAL::Search_traits_3<Kernel>;
  using Search = CGAL::Orthogonal_k_neighbor_search<Traits>;
  using Tree = Search::Tree;

  /// An output iterator that only counts what is written to it.
  struct Counter {
    using iterator_category = std::output_iterator_tag;
    using value_type = void;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = void;
    std::uint32_t* count;
    Counter& operator*() { return *this; }
    Counter& operator++() { return *this; }
    Counter operator++(int) { return *this; }
    template <class V>
    Counter& operator=(const V&) {
      ++*count;
      return *this;
    }
  };

  static Kernel::Point_3 point(const float* x) { return Kernel::Point_3(x[0], x[1], x[2]); }

  std::vector<Kernel::Point_3> points_;
  std::unique_ptr<Tree> tree_;
};
#endif

#ifdef KDSPACE_BENCH_FAISS
// FAISS's IndexFlatL2: exact k-NN by scanning, |x|^2 + |q|^2 - 2 x.q with the dot products from BLAS
// sgemm (OpenBLAS where installed). Its distances come from that formula in float, so they are not
// exact (cancellation): its answers are reported against the exact ones but do not fail the run.
// One thread: OpenMP and OpenBLAS are both set to the thread count of the call.
class FaissFlatLibrary : public Library {
 public:
  explicit FaissFlatLibrary(const Problem& problem) : Library(problem, "faiss-flat", "FAISS IndexFlatL2 (BLAS scan)", false) {}
  bool exact_answers() const override { return false; }

  // A flat index only copies the points: no build time or index size to compare with a tree's, so
  // none is reported (negative).
  double build() override {
    index_ = std::make_unique<faiss::IndexFlatL2>(static_cast<faiss::Index::idx_t>(p.dim));
    index_->add(static_cast<faiss::Index::idx_t>(p.n), p.base.data());
    return -1;
  }
  void release() override { index_.reset(); }

  double knn(std::size_t k, double eps, KnnAnswers& out) override { return eps == 0 ? search(k, 1, out) : -1; }
  double knn_threads(std::size_t k, unsigned threads, KnnAnswers& out) override { return search(k, threads, out); }

 private:
  double search(std::size_t k, unsigned threads, KnnAnswers& out) {
    set_threads(threads);
    std::vector<faiss::Index::idx_t> ids(p.nq * k);
    out.reset(p.nq, k);
    const double start = clock_now();
    index_->search(static_cast<faiss::Index::idx_t>(p.nq), p.queries.data(), static_cast<faiss::Index::idx_t>(k),
                   out.dists.data(), ids.data());
    const double s = seconds_since(start);
    set_threads(1);
    for (std::size_t i = 0; i < p.nq * k; ++i) {
      out.ids[i] = static_cast<std::uint32_t>(ids[i]);
      out.dists[i] = std::sqrt(std::max(out.dists[i], 0.f));
    }
    return s;
  }
  std::unique_ptr<faiss::IndexFlatL2> index_;
};
#endif

// ---- setting a workload up ------------------------------------------------------------------------

// The value v among the candidates for which the mean over sample queries of #{d <= v} first reaches
// `target`, given each sample query's sorted distances (the K nearest; counts above K are capped, so
// the mean is a lower bound and v errs large). Returned halfway to the next candidate, so that no
// sample distance lies on it exactly.
float calibrate(const std::vector<std::vector<float>>& sorted_per_query, double target) {
  std::vector<float> all;
  for (const auto& row : sorted_per_query) all.insert(all.end(), row.begin(), row.end());
  std::sort(all.begin(), all.end());
  all.erase(std::unique(all.begin(), all.end()), all.end());
  auto mean_count = [&](float v) {
    std::size_t total = 0;
    for (const auto& row : sorted_per_query)
      total += static_cast<std::size_t>(std::upper_bound(row.begin(), row.end(), v) - row.begin());
    return dbl(total) / dbl(sorted_per_query.size());
  };
  std::size_t lo = 0, hi = all.size() - 1;  // smallest index whose mean count reaches the target
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (mean_count(all[mid]) >= target) hi = mid;
    else lo = mid + 1;
  }
  return lo + 1 < all.size() ? all[lo] + (all[lo + 1] - all[lo]) / 2 : all[lo];
}

void set_up(Problem& p, const std::vector<float>& sample, bool quick) {
  const std::size_t ns = sample.size() / p.dim;
  // Radii: from kdspace's exact k-NN distances on the sample (K = 8 x the target count).
  {
    kdspace::PointTree<float> tree(p.base.data(), p.n, p.dim);
    const double targets[2] = {10, 100};
    for (int i = 0; i < 2; ++i) {
      const std::size_t kk = std::min(p.n, static_cast<std::size_t>(8 * targets[i]));
      std::vector<std::vector<float>> rows(ns);
      for (std::size_t q = 0; q < ns; ++q)
        for (const auto& nb : tree.knn(sample.data() + q * p.dim, kk)) rows[q].push_back(nb.distance);
      p.radius[i] = calibrate(rows, targets[i]);
    }
  }
  // Box half-width: the same from L-infinity distances, for ~30 points a box (between 10 and 100).
  {
    kdspace::PointTree<float, kdspace::Dynamic, kdspace::Linf> tree(p.base.data(), p.n, p.dim);
    const std::size_t kk = std::min<std::size_t>(p.n, 240);
    std::vector<std::vector<float>> rows(ns);
    for (std::size_t q = 0; q < ns; ++q)
      for (const auto& nb : tree.knn(sample.data() + q * p.dim, kk)) rows[q].push_back(nb.distance);
    p.half_width = calibrate(rows, 30);
  }
  p.box_lo.resize(p.nq * p.dim);
  p.box_hi.resize(p.nq * p.dim);
  for (std::size_t i = 0; i < p.nq * p.dim; ++i) {
    p.box_lo[i] = p.queries[i] - p.half_width;
    p.box_hi[i] = p.queries[i] + p.half_width;
  }
  const double scan_budget = quick ? 5e6 : 5e7;  // points tested by the plain scan
  p.scan_boxes = std::clamp<std::size_t>(static_cast<std::size_t>(scan_budget / dbl(p.n)), 20, p.nq);
  p.brute_checks = std::clamp<std::size_t>(static_cast<std::size_t>(1e8 / dbl(p.n * p.dim)), 10, 100);
  p.brute_checks = std::min(p.brute_checks, p.nq);
}

// ---- running --------------------------------------------------------------------------------------

struct References {
  std::optional<KnnAnswers> knn[2];  // k = 1, 10 (exact)
  std::optional<std::vector<std::uint32_t>> radius[2];
  std::optional<BoxAnswers> box;
  std::size_t brute_disagreements = 0;  // kdspace's exact answers versus brute force
  double mean_count[3] = {0, 0, 0};     // radius10, radius100, box (kdspace's answers)
};

std::size_t radius_disagreements(const Problem& p, const std::vector<std::uint32_t>& counts,
                                 const std::vector<std::uint32_t>& ref, float r, std::size_t& boundary) {
  std::size_t bad = 0;
  for (std::size_t q = 0; q < ref.size(); ++q) {
    if (counts[q] == ref[q]) continue;
    const std::size_t diff = counts[q] > ref[q] ? counts[q] - ref[q] : ref[q] - counts[q];
    if (diff <= boundary_points(p, q, r)) ++boundary;
    else ++bad;
  }
  return bad;
}

std::size_t box_disagreements(const BoxAnswers& a, const BoxAnswers& ref) {
  std::size_t bad = 0;
  const std::size_t nc = std::min(a.counts.size(), ref.counts.size());
  const std::size_t nl = std::min(a.lists.size(), ref.lists.size());
  for (std::size_t b = 0; b < nc; ++b) {
    const bool same = a.counts[b] == ref.counts[b] && (b >= nl || a.lists[b] == ref.lists[b]);
    bad += same ? 0 : 1;
  }
  return bad;
}

void check_against_brute_force(const Problem& p, const KnnAnswers& ref10, const KnnAnswers& ref1, References& refs) {
  for (std::size_t q = 0; q < p.brute_checks; ++q) {
    const auto truth = kdspace::brute_force_knn(p.base.data(), p.n, p.dim, p.queries.data() + q * p.dim, 10);
    for (std::size_t j = 0; j < 10; ++j)
      if (truth[j].index != ref10.ids[q * 10 + j] || truth[j].distance != ref10.dists[q * 10 + j]) ++refs.brute_disagreements;
  }
  for (std::size_t q = 0; q < p.nq; ++q)  // the 1-NN is the first of the 10-NN, bit for bit
    if (ref1.ids[q] != ref10.ids[q * 10] || ref1.dists[q] != ref10.dists[q * 10]) ++refs.brute_disagreements;
}

void record(Library& lib, Op op, double s, std::size_t nq) {
  if (s < 0) return;
  lib.seconds[op].push_back(s);
  lib.queries[op] = nq;
}

void note_disagreements(Library& lib, Op op, std::size_t bad) { lib.disagreements[op] = std::max(lib.disagreements[op], bad); }

/// The order in which a pass answers the queries. A small query set answered in one order pass after
/// pass lets the branch predictor learn that sequence (kitten: 521 queries, some 2,000 passes a
/// measurement), which no user's queries would offer; so each pass of a query measurement answers
/// the same queries in a new order, drawn from a seed that depends only on (repetition, operation,
/// pass), hence the same sequence of orders for every library. The shuffling happens between passes,
/// off the clock; the answers of the last pass are put back in the problem's order for the checks.
/// (Box queries keep the problem's order: the plain scan's reference lists are of the first boxes.)
class PassOrders {
 public:
  explicit PassOrders(Problem& problem) : p_(problem), given_(problem.queries), rows_(problem.nq) {}
  ~PassOrders() { p_.queries = given_; }

  /// Puts p.queries in the order of pass `pass` of measurement `measurement`: row i is query rows_[i].
  void shuffle(std::uint64_t measurement, std::size_t pass) {
    for (std::size_t i = 0; i < rows_.size(); ++i) rows_[i] = static_cast<std::uint32_t>(i);
    std::mt19937_64 rng(measurement * 0x9E3779B97F4A7C15ull + pass);
    std::shuffle(rows_.begin(), rows_.end(), rng);
    const std::size_t d = p_.dim;
    for (std::size_t i = 0; i < rows_.size(); ++i)
      std::copy_n(given_.data() + rows_[i] * d, d, p_.queries.data() + i * d);
  }

  /// The last pass's answers (row i answers query rows_[i]) in the problem's order, and p.queries too.
  void put_back(KnnAnswers& answers) {
    const KnnAnswers shuffled = answers;
    const std::size_t k = answers.k;
    for (std::size_t i = 0; i < rows_.size(); ++i) {
      std::copy_n(shuffled.ids.data() + i * k, k, answers.ids.data() + rows_[i] * k);
      std::copy_n(shuffled.dists.data() + i * k, k, answers.dists.data() + rows_[i] * k);
    }
    p_.queries = given_;
  }
  void put_back(std::vector<std::uint32_t>& counts) {
    const std::vector<std::uint32_t> shuffled = counts;
    for (std::size_t i = 0; i < rows_.size(); ++i) counts[rows_[i]] = shuffled[i];
    p_.queries = given_;
  }

  /// Seconds of a pass of `pass` (which answers p.queries), each pass in a new order; then the last
  /// pass's answers put back in the problem's order.
  template <class Pass, class Answers>
  double timed_shuffled(std::uint64_t measurement, Answers& answers, Pass&& pass) {
    const double s = timed([&](std::size_t number) {
      shuffle(measurement, number);
      return pass();
    });
    if (s >= 0) put_back(answers);
    else p_.queries = given_;
    return s;
  }

 private:
  Problem& p_;
  const std::vector<float> given_;
  std::vector<std::uint32_t> rows_;
};

void run_library(const Problem& p, Library& lib, References& refs, PassOrders& orders, std::size_t rep) {
  const bool first_rep = rep == 0;
  // Each query measurement's number, for its orders: the same for every library.
  auto measurement = [&](Op op) { return static_cast<std::uint64_t>(rep * kOps + static_cast<std::size_t>(op)); };
  std::fprintf(stderr, "  %s\n", lib.label.c_str());
  if (const double s = timed([&](std::size_t) { return lib.build(); }); s >= 0) {  // the plain scan has no index
    record(lib, kBuild, s, p.n);
    const double bytes = lib.index_bytes();
    lib.bytes_per_point = bytes < 0 ? -1 : bytes / dbl(p.n);
  }
  KnnAnswers answers;
  const std::size_t ks[2] = {1, 10};
  for (int i = 0; i < 2; ++i) {
    const Op op = i == 0 ? kKnn1 : kKnn10;
    const double s = orders.timed_shuffled(measurement(op), answers, [&] { return lib.knn(ks[i], 0.0, answers); });
    if (s < 0) continue;
    record(lib, op, s, p.nq);
    if (!refs.knn[i]) refs.knn[i] = answers;
    else note_disagreements(lib, op, knn_disagreements(answers, *refs.knn[i]));
  }
  if (first_rep && refs.knn[0] && refs.knn[1] && lib.key == "kdspace-rt")
    check_against_brute_force(p, *refs.knn[1], *refs.knn[0], refs);
  for (int i = 0; i < 2; ++i) {
    const Op op = i == 0 ? kKnn1Loop : kKnn10Loop;
    const double s = orders.timed_shuffled(measurement(op), answers, [&] { return lib.knn_loop(ks[i], answers); });
    if (s < 0) continue;
    record(lib, op, s, p.nq);
    note_disagreements(lib, op, knn_disagreements(answers, *refs.knn[i]));
  }
  std::vector<std::uint32_t> counts;
  for (int i = 0; i < 2; ++i) {
    const Op op = i == 0 ? kRadius10 : kRadius100;
    const double s = orders.timed_shuffled(measurement(op), counts, [&] { return lib.radius(p.radius[i], counts); });
    if (s < 0) continue;
    record(lib, op, s, p.nq);
    if (!refs.radius[i]) {
      refs.radius[i] = counts;
      std::size_t total = 0;
      for (auto c : counts) total += c;
      refs.mean_count[i] = dbl(total) / dbl(p.nq);
    } else {
      std::size_t boundary = 0;
      note_disagreements(lib, op, radius_disagreements(p, counts, *refs.radius[i], p.radius[i], boundary));
      lib.boundary[op] = std::max(lib.boundary[op], boundary);
    }
  }
  BoxAnswers boxes;
  if (const double s = timed([&](std::size_t) { return lib.box(boxes); }); s >= 0) {
    record(lib, kBox, s, boxes.counts.size());
    if (!refs.box) {
      refs.box = boxes;
      std::size_t total = 0;
      for (auto c : boxes.counts) total += c;
      refs.mean_count[2] = dbl(total) / dbl(boxes.counts.size());
    } else {
      note_disagreements(lib, kBox, box_disagreements(boxes, *refs.box));
    }
  }
  for (int i = 0; i < 2; ++i) {
    const Op op = i == 0 ? kApprox05 : kApprox2;
    const double s =
        orders.timed_shuffled(measurement(op), answers, [&] { return lib.knn(10, kApproxEps[i], answers); });
    if (s < 0) continue;
    record(lib, op, s, p.nq);
    lib.recall[i] = recall_at_10(answers, *refs.knn[1]);
  }
  if (g_cpu_clock) {  // CPU time adds up both threads: no 2-thread figure
  } else if (const double s = orders.timed_shuffled(measurement(kBatch2), answers,
                                                    [&] { return lib.knn_threads(10, 2, answers); });
             s >= 0) {
    record(lib, kBatch2, s, p.nq);
    note_disagreements(lib, kBatch2, knn_disagreements(answers, *refs.knn[1]));
  }
  lib.release();
}

// ---- reporting ------------------------------------------------------------------------------------

double median(std::vector<double> v) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
}

// Median queries per second of an operation; negative when not measured.
double qps(const Library& lib, Op op) {
  const double s = median(lib.seconds[op]);
  return s > 0 ? dbl(lib.queries[op]) / s : -1;
}

std::string grouped(double x) {  // 1234567.8 -> "1,234,568"
  std::string digits = std::to_string(static_cast<long long>(std::llround(x)));
  std::string out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

std::string fixed(double x, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, x);
  return buf;
}

/// The value of one table column for one library (negative: not measured) and how it prints.
struct Column {
  const char* title;
  bool higher_is_better;
  std::function<double(const Library&)> value;
  std::function<std::string(const Library&, double)> text;
};

void print_table(const Problem& p, const std::vector<std::unique_ptr<Library>>& libs, const References& refs,
                 std::size_t reps) {
  auto q = [](Op op) { return [op](const Library& l) { return qps(l, op); }; };
  auto plain = [](const Library&, double v) { return grouped(v); };
  auto with_recall = [](int i) {
    return [i](const Library& l, double v) { return grouped(v) + " (" + fixed(l.recall[i], 3) + ")"; };
  };
  const std::vector<Column> columns = {
      {"build s", false, [](const Library& l) { return median(l.seconds[kBuild]); },
       [](const Library&, double v) { return fixed(v, 3); }},
      {"index B/pt", false, [](const Library& l) { return l.bytes_per_point; },
       [](const Library&, double v) { return fixed(v, 2); }},
      {"1-NN q/s", true, q(kKnn1), plain},
      {"10-NN q/s", true, q(kKnn10), plain},
      {"1-NN q/s, single-query loop", true, q(kKnn1Loop), plain},
      {"10-NN q/s, single-query loop", true, q(kKnn10Loop), plain},
      {"radius ~10 q/s", true, q(kRadius10), plain},
      {"radius ~100 q/s", true, q(kRadius100), plain},
      {"box q/s", true, q(kBox), plain},
      {"ε=0.5 q/s (recall@10)", true, q(kApprox05), with_recall(0)},
      {"ε=2 q/s (recall@10)", true, q(kApprox2), with_recall(1)},
      {"batch 10-NN 2 thr q/s", true, q(kBatch2), plain},
      {"2 thr ÷ 1 thr", true,
       [](const Library& l) {
         const double one = qps(l, kKnn10), two = qps(l, kBatch2);
         return one > 0 && two > 0 ? two / one : -1;
       },
       [](const Library&, double v) { return fixed(v, 2); }},
  };
  std::printf("\n### %s: %zu points, %zu-D %s, %zu queries, median of %zu interleaved repetition%s\n\n", p.name.c_str(), p.n,
              p.dim, p.data.c_str(), p.nq, reps, reps == 1 ? "" : "s");
  std::printf("| library |");
  for (const auto& c : columns) std::printf(" %s |", c.title);
  std::printf("\n|---|");
  for (std::size_t i = 0; i < columns.size(); ++i) std::printf("---:|");
  std::printf("\n");
  for (const auto& lib : libs) {
    std::printf("| %s |", lib->label.c_str());
    for (const auto& c : columns) {
      const double v = c.value(*lib);
      std::printf(" %s |", v >= 0 ? c.text(*lib, v).c_str() : "—");
    }
    std::printf("\n");
  }
  // kdspace (the better of its variants) ÷ the best peer; for the loop columns the peer's figure is
  // its 10-NN / 1-NN one (nanoflann answers one query at a time anyway), for box the plain scan.
  std::printf("| **kdspace ÷ best peer** |");
  for (std::size_t ci = 0; ci < columns.size(); ++ci) {
    const Column& c = columns[ci];
    std::size_t peer_col = ci;
    if (std::string(c.title).find("single-query loop") != std::string::npos) peer_col = ci - 2;
    double kd = -1, peer = -1, scan = -1;
    auto better = [&](double a, double b) { return b < 0 || (c.higher_is_better ? a > b : a < b); };
    for (const auto& lib : libs) {
      const double v = c.value(*lib), pv = columns[peer_col].value(*lib);
      if (lib->is_kdspace && v >= 0 && better(v, kd)) kd = v;
      if (lib->is_peer() && pv >= 0 && better(pv, peer)) peer = pv;
      if (lib->key == "scan" && v >= 0) scan = v;
    }
    if (kd >= 0 && peer > 0) std::printf(" %.2f |", kd / peer);
    else if (kd >= 0 && scan > 0) std::printf(" %.1f vs scan (no peer) |", kd / scan);
    else std::printf(" n/a |");
  }
  std::printf("\n\n");
  std::printf("- radius ~10: r = %.6g, mean count %.2f; radius ~100: r = %.6g, mean count %.2f (kdspace's answers to the "
              "%zu queries; radii calibrated on 256 other queries from kdspace's exact 80-NN / 800-NN distances)\n",
              static_cast<double>(p.radius[0]), refs.mean_count[0], static_cast<double>(p.radius[1]), refs.mean_count[1], p.nq);
  std::printf("- box: cubes of half-width %.6g centred on the queries, mean count %.2f (calibrated like the radii, on "
              "L∞ distances); kdspace answers all %zu, the plain scan the first %zu, CGAL all (3-D); FLANN, "
              "nanoflann and FAISS have no box search\n",
              static_cast<double>(p.half_width), refs.mean_count[2], p.nq, p.scan_boxes);
  std::size_t knn_bad = 0, radius_bad = 0, radius_boundary = 0, box_bad = 0;
  std::string details;  // which library and operation, where any count is not 0
  std::string inexact;  // libraries whose answers are not exact by design, and how far they were off
  for (const auto& lib : libs) {
    if (!lib->exact_answers()) {
      inexact += "; " + lib->key + " (not exact by design): k-NN distances differing beyond 1e-5 relative: " +
                 std::to_string(lib->disagreements[kKnn1] + lib->disagreements[kKnn10] + lib->disagreements[kBatch2]);
      continue;
    }
    knn_bad += lib->disagreements[kKnn1] + lib->disagreements[kKnn10] + lib->disagreements[kKnn1Loop] +
               lib->disagreements[kKnn10Loop] + lib->disagreements[kBatch2];
    radius_bad += lib->disagreements[kRadius10] + lib->disagreements[kRadius100];
    radius_boundary += lib->boundary[kRadius10] + lib->boundary[kRadius100];
    box_bad += lib->disagreements[kBox];
    for (int op = 0; op < kOps; ++op) {
      const std::string what = lib->key + " " + kOpNames[op] + (op == kKnn1Loop || op == kKnn10Loop ? " loop" : "") +
                               (op == kBatch2 ? " 2 threads" : "");
      if (lib->disagreements[op]) details += "; " + what + ": " + std::to_string(lib->disagreements[op]) + " disagreeing";
      if (lib->boundary[op]) details += "; " + what + ": " + std::to_string(lib->boundary[op]) + " at the radius";
    }
  }
  std::printf("- exact answers, checked in every repetition against kdspace (run-time dim)'s answers of the first "
              "(largest count over repetitions): k-NN distances differing beyond 1e-5 relative: %zu; radius counts "
              "differing: %zu (plus %zu explained by points within 1e-5 relative of the radius, where FLANN and "
              "nanoflann keep d² < r² and kdspace d <= r); box lists differing: %zu; kdspace's 10-NN versus brute "
              "force on %zu queries (bit for bit) and its 1-NN versus its 10-NN: %zu%s%s\n\n",
              knn_bad, radius_bad, radius_boundary, box_bad, p.brute_checks, refs.brute_disagreements, details.c_str(),
              inexact.c_str());
}

std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) >= 0x20) out += c;
  }
  return out + "\"";
}

void print_json(const Problem& p, const std::vector<std::unique_ptr<Library>>& libs, const References& refs,
                std::size_t reps) {
  for (const auto& lib : libs) {
    const std::string head = "{\"bench\":\"points\",\"workload\":" + json_string(p.name) + ",\"data\":" + json_string(p.data) +
                             ",\"dim\":" + std::to_string(p.dim) + ",\"n\":" + std::to_string(p.n) +
                             ",\"library\":" + json_string(lib->key) + ",\"reps\":" + std::to_string(reps);
    auto line = [&](Op op, const char* api, unsigned threads, const std::string& extra, const char* name = nullptr) {
      const double v = qps(*lib, op);
      if (v < 0) return;
      std::printf("%s,\"op\":\"%s\",\"api\":\"%s\",\"threads\":%u,\"queries\":%zu,\"qps\":%.1f%s}\n", head.c_str(),
                  name ? name : kOpNames[op], api, threads, lib->queries[op], v, extra.c_str());
    };
    if (!lib->seconds[kBuild].empty()) {
      std::printf("%s,\"op\":\"build\",\"threads\":1,\"build_s\":%.6f", head.c_str(), median(lib->seconds[kBuild]));
      if (lib->bytes_per_point >= 0) std::printf(",\"index_bytes_per_point\":%.3f", lib->bytes_per_point);
      std::printf("}\n");
    }
    const char* api = lib->key == "flann" || lib->is_kdspace ? "batch" : "loop";
    line(kKnn1, api, 1, "");
    line(kKnn10, api, 1, "");
    line(kKnn1Loop, "loop", 1, "");
    line(kKnn10Loop, "loop", 1, "");
    for (int i = 0; i < 2; ++i)
      line(i == 0 ? kRadius10 : kRadius100, api, 1,
           ",\"radius\":" + fixed(static_cast<double>(p.radius[i]), 9) + ",\"mean_count\":" + fixed(refs.mean_count[i], 3));
    line(kBox, "loop", 1, ",\"half_width\":" + fixed(static_cast<double>(p.half_width), 9) + ",\"mean_count\":" + fixed(refs.mean_count[2], 3));
    for (int i = 0; i < 2; ++i)
      line(i == 0 ? kApprox05 : kApprox2, api, 1,
           ",\"eps\":" + fixed(kApproxEps[i], 1) + ",\"recall10\":" + fixed(lib->recall[i], 5));
    // Batched exact 10-NN: on 1 thread it is the knn10 measurement (the very same call), repeated
    // under this name for libraries that were also measured on 2 threads.
    const double one = qps(*lib, kKnn10), two = qps(*lib, kBatch2);
    if (two > 0) {
      line(kKnn10, "batch", 1, ",\"same_as\":\"knn10\"", "batch10");
      line(kBatch2, "batch", 2, ",\"speedup_vs_1\":" + fixed(two / one, 3));
    }
  }
}

// ---- main -----------------------------------------------------------------------------------------

struct FilePair {
  std::string base, queries;
};

// ---- real data --------------------------------------------------------------------------------------

constexpr const char* kImagesWorkload = "images128d";

/// 256 query rows spread over the query set: the sample that calibrates radii and boxes.
std::vector<float> calibration_sample(const Problem& p) {
  std::vector<float> sample;
  const std::size_t ns = std::min<std::size_t>(256, p.nq);
  for (std::size_t i = 0; i < ns; ++i) {
    const float* row = p.queries.data() + (i * p.nq / ns) * p.dim;
    sample.insert(sample.end(), row, row + p.dim);
  }
  return sample;
}

/// A real scan or mesh as a workload: a random tenth of its points (fixed seed) held out as the
/// queries, the rest the base, so that no query is a point of the base.
Problem held_out_problem(const kdspace::bench::Mesh& mesh, std::size_t max_queries) {
  Problem p;
  p.name = mesh.name;
  p.data = mesh.triangles.empty() ? "scan" : "mesh";
  p.dim = 3;
  std::vector<std::size_t> order(mesh.vertices.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(7);
  std::shuffle(order.begin(), order.end(), rng);
  p.nq = std::max<std::size_t>(1, order.size() / 10);
  if (max_queries) p.nq = std::min(p.nq, max_queries);
  p.n = order.size() - std::max<std::size_t>(1, order.size() / 10);
  for (std::size_t i = 0; i < order.size(); ++i) {
    const auto& v = mesh.vertices[order[i]];
    if (i < p.nq) p.queries.insert(p.queries.end(), v.begin(), v.end());
    else if (i >= order.size() - p.n) p.base.insert(p.base.end(), v.begin(), v.end());
  }
  return p;
}

/// Dense SIFT-like 128-D descriptors (image_features.hpp) of 12 photographs as the base, 2000
/// queries from the other view of one of them (its even descriptors).
Problem image_problem(const std::string& folder, std::size_t divisor, std::size_t max_queries) {
  using namespace kdspace_bench;
  Problem p;
  p.name = kImagesWorkload;
  p.data = "sift-like";
  p.dim = image_descriptor_dim;
  std::fprintf(stderr, "%s: describing the photographs in %s\n", p.name.c_str(), folder.c_str());
  std::vector<float> all;
  for (const std::string& photo : base_photos()) {
    const std::vector<float> one = photo_descriptors(folder + "/" + photo + ".png");
    all.insert(all.end(), one.begin(), one.end());
  }
  p.base = evenly_spaced_rows(all, p.dim, all.size() / p.dim / divisor);
  p.n = p.base.size() / p.dim;
  const std::vector<float> view = photo_descriptors(folder + "/" + std::string(query_photo()) + ".png");
  std::vector<float> even;
  for (std::size_t r = 0; r < view.size() / p.dim; r += 2)
    even.insert(even.end(), view.begin() + static_cast<long>(r * p.dim), view.begin() + static_cast<long>((r + 1) * p.dim));
  p.queries = evenly_spaced_rows(even, p.dim, std::min<std::size_t>(max_queries ? max_queries : 2000, 2000) / divisor);
  p.nq = p.queries.size() / p.dim;
  return p;
}

// ---- the Python peers (a separate process: bench/python_peers.py) --------------------------------

/// Writes the workload to a scratch folder as .npy, runs the script with /usr/bin/python3 (Debian's
/// interpreter, which sees python3-scipy and python3-pykdtree) and prints its side table and JSON
/// lines. kdspace's exact distances go along, so that the script checks the peers' answers.
void run_python_peers(const std::string& script, const Problem& p, const std::vector<std::unique_ptr<Library>>& libs,
                      const References& refs, std::size_t reps) {
  char scratch[] = "/tmp/kdspace-bench-python-XXXXXX";
  if (!mkdtemp(scratch)) throw kdspace::Error(std::string("cannot make a scratch folder: ") + std::strerror(errno));
  const std::string dir = scratch;
  namespace io = kdspace::io;
  io::write_points(dir + "/base.npy", io::Matrix<float>{p.n, p.dim, p.base});
  io::write_points(dir + "/queries.npy", io::Matrix<float>{p.nq, p.dim, p.queries});
  io::write_points(dir + "/exact1.npy", io::Matrix<float>{p.nq, 1, refs.knn[0]->dists});
  io::write_points(dir + "/exact10.npy", io::Matrix<float>{p.nq, 10, refs.knn[1]->dists});
  // kdspace's best figures, for the ratios in the side table.
  double build = -1, knn1 = -1, knn10 = -1;
  for (const auto& lib : libs) {
    if (!lib->is_kdspace) continue;
    const double b = median(lib->seconds[kBuild]);
    if (b > 0 && (build < 0 || b < build)) build = b;
    knn1 = std::max(knn1, qps(*lib, kKnn1));
    knn10 = std::max(knn10, qps(*lib, kKnn10));
  }
  const std::string command = "/usr/bin/python3 '" + script + "' '" + dir + "' '" + p.name + "' --reps " +
                              std::to_string(reps) + " --min-time " + fixed(g_min_seconds, 3) +
                              (g_cpu_clock ? " --clock cpu" : "") + " --kdspace " +
                              fixed(build, 6) + " " + fixed(knn1, 1) + " " + fixed(knn10, 1);
  std::fprintf(stderr, "%s: python peers: %s\n", p.name.c_str(), command.c_str());
  std::fflush(stdout);
  const int status = std::system(command.c_str());
  std::filesystem::remove_all(dir);
  if (status != 0) std::printf("- the Python peers failed (status %d): see stderr\n\n", status);
}

int usage() {
  std::fprintf(stderr,
               "usage: kdspace-bench [--workload NAME]... [--quick] [--reps R] [--queries Q] [--min-time S]\n"
               "                     [--clock wall|cpu]\n"
               "                     [--real DIR] [--images DIR] [--python-peers SCRIPT]\n"
               "                     [--fvecs BASE QUERIES]... [--bvecs BASE QUERIES]... [--list]\n");
  return 2;
}

std::string workload_name_from(const std::string& path) {
  std::string name = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
  if (const auto dot = name.find('.'); dot != std::string::npos && dot > 0) name = name.substr(0, dot);
  for (auto& c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) c = '_';
  return name;
}

template <int Dim>
void add_fixed_dim(const Problem& p, std::vector<std::unique_ptr<Library>>& libs, bool nanoflann) {
  if (p.dim != static_cast<std::size_t>(Dim)) return;
  if (nanoflann)
    libs.push_back(std::make_unique<NanoflannLibrary<Dim>>(p, "nanoflann-ct", "nanoflann (compile-time dim, leaf 10)"));
  else
    libs.push_back(std::make_unique<KdspaceLibrary<Dim>>(p, "kdspace-ct", "kdspace (compile-time dim)"));
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> selected;
  std::vector<FilePair> files;
  std::string real_dir, images_dir, python_peers;
  bool quick = false;
  std::size_t reps = 0, max_queries = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (arg == "--quick") {
      quick = true;
    } else if (arg == "--workload") {
      const char* v = next();
      if (!v) return usage();
      selected.emplace_back(v);
    } else if (arg == "--reps" || arg == "--queries") {
      const char* v = next();
      if (!v || std::strtoull(v, nullptr, 10) == 0) return usage();
      (arg == "--reps" ? reps : max_queries) = std::strtoull(v, nullptr, 10);
    } else if (arg == "--clock") {
      const char* v = next();
      if (!v || (std::strcmp(v, "cpu") != 0 && std::strcmp(v, "wall") != 0)) return usage();
      g_cpu_clock = std::strcmp(v, "cpu") == 0;
    } else if (arg == "--min-time") {
      const char* v = next();
      if (!v || !(std::strtod(v, nullptr) >= 0)) return usage();
      g_min_seconds = std::strtod(v, nullptr);
    } else if (arg == "--fvecs" || arg == "--bvecs") {
      const char* b = next();
      const char* q = next();
      if (!b || !q) return usage();
      files.push_back({b, q});
    } else if (arg == "--real" || arg == "--images" || arg == "--python-peers") {
      const char* v = next();
      if (!v) return usage();
      (arg == "--real" ? real_dir : arg == "--images" ? images_dir : python_peers) = v;
    } else if (arg == "--list") {
      for (const auto& w : kWorkloads) std::printf("%s\n", w.name);
      std::printf("%s (with --images DIR)\nthe real sets' names (with --real DIR)\n", kImagesWorkload);
      return 0;
    } else {
      return usage();
    }
  }
  std::vector<kdspace::bench::Mesh> real_sets;
  try {
    if (!real_dir.empty()) real_sets = kdspace::bench::read_real_meshes(real_dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-bench: error: %s\n", e.what());
    return 1;
  }
  for (const auto& name : selected) {
    bool known = name == kImagesWorkload && !images_dir.empty();
    for (const auto& w : kWorkloads) known = known || name == w.name;
    for (const auto& m : real_sets) known = known || name == m.name;
    if (!known) {
      std::fprintf(stderr, "kdspace-bench: unknown workload '%s' (--list shows them)\n", name.c_str());
      return 2;
    }
  }
  auto wanted = [&](const std::string& name) {
    return (selected.empty() && files.empty()) || std::find(selected.begin(), selected.end(), name) != selected.end();
  };
  if (reps == 0) reps = quick ? 1 : 3;
  const std::size_t divisor = quick ? 10 : 1;

  // The workloads to run, in order: the built-in ones selected (all if none is named and no file is
  // given), the real sets, the image descriptors, then the files.
  std::vector<const WorkloadSpec*> specs;
  for (const auto& w : kWorkloads)
    if (wanted(w.name)) specs.push_back(&w);

  char date[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%d", std::localtime(&now));
  set_threads(1);
  std::printf("## kdspace-bench (points), %s, %u hardware threads%s\n\n", date, std::thread::hardware_concurrency(),
              quick ? ", --quick (n and queries / 10)" : "");
  std::printf("Libraries: kdspace %d.%d.%d PointTree<float> (default BuildParams), FLANN "
              "%s KDTreeSingleIndex (leaf 10, reordered), nanoflann 0x%x KDTreeSingleIndexAdaptor (leaf 10)%s%s; "
              "compile-time dimension variants where the dimension is 3, 8 or 16. One thread unless a column says "
              "otherwise; q/s = queries per second; builds on one thread; each figure is the mean over as many "
              "passes as take %.2f s (%s), each pass in a new order of the queries (the same orders for every "
              "library), median of the interleaved repetitions.\n",
              KDSPACE_VERSION_MAJOR, KDSPACE_VERSION_MINOR, KDSPACE_VERSION_PATCH, FLANN_VERSION_, NANOFLANN_VERSION,
#ifdef KDSPACE_BENCH_CGAL
              ", CGAL " CGAL_VERSION_STR " Kd_tree (3-D only; sliding midpoint, bucket 10)",
#else
              ", no CGAL (not found at build time)",
#endif
#ifdef KDSPACE_BENCH_FAISS
              (", FAISS IndexFlatL2 from 32-D on (its sgemm from " + blas_name() + ")").c_str(),
#else
              ", no FAISS (not found at build time)",
#endif
              g_min_seconds, g_cpu_clock ? "process CPU time: --clock cpu" : "wall time");
  std::printf("kdspace's 1-thread k-NN columns are knn_batch(..., threads = 1); the single-query-loop columns call "
              "knn() once per query. FLANN answers through its batch knnSearch (cores = 1), nanoflann one query at a "
              "time. index B/pt: bytes the index holds besides a copy of the points: kdspace index_bytes() / n; "
              "nanoflann usedMemory() (node pool + index array) / n; FLANN usedMemory() (node pool + index array) "
              "plus its array of n row pointers, / n. Approximate search: kdspace's eps bounds true distances "
              "(each within 1 + eps of the true one); FLANN's and nanoflann's eps bounds squared distances (so "
              "within sqrt(1 + eps)): at the same eps they search more exactly, compare recall too. FLANN batch "
              "on 2 threads = SearchParams::cores = 2 (OpenMP)%s. Ratio row: kdspace's better variant ÷ the best "
              "peer (FLANN, nanoflann, CGAL, FAISS); above 1 = kdspace higher (better for q/s, worse for build s and B/pt); in "
              "the single-query-loop columns the peers' figures are their 1-NN / 10-NN ones; in the box column the "
              "plain scan stands in where no peer has a box search.\n",
#ifdef _OPENMP
              ""
#else
              "; this build has no OpenMP, so FLANN's 2-thread figure is not measured"
#endif
  );
  std::fflush(stdout);

  std::size_t total_bad = 0;
  auto run_problem = [&](Problem& p, const std::vector<float>& sample) {
    std::fprintf(stderr, "%s: calibrating radii and boxes\n", p.name.c_str());
    set_up(p, sample, quick);
    std::vector<std::unique_ptr<Library>> libs;
    libs.push_back(std::make_unique<KdspaceLibrary<kdspace::Dynamic>>(p, "kdspace-rt", "kdspace (run-time dim)"));
    add_fixed_dim<3>(p, libs, false);
    add_fixed_dim<8>(p, libs, false);
    add_fixed_dim<16>(p, libs, false);
    libs.push_back(std::make_unique<FlannLibrary>(p));
    libs.push_back(std::make_unique<NanoflannLibrary<-1>>(p, "nanoflann-rt", "nanoflann (run-time dim, leaf 10)"));
    add_fixed_dim<3>(p, libs, true);
    add_fixed_dim<8>(p, libs, true);
    add_fixed_dim<16>(p, libs, true);
#ifdef KDSPACE_BENCH_CGAL
    if (p.dim == 3) libs.push_back(std::make_unique<CgalLibrary>(p));
#endif
#ifdef KDSPACE_BENCH_FAISS
    if (p.dim >= 32) libs.push_back(std::make_unique<FaissFlatLibrary>(p));
#endif
    libs.push_back(std::make_unique<ScanLibrary>(p));
    References refs;
    {
      PassOrders orders(p);
      for (std::size_t rep = 0; rep < reps; ++rep) {  // repetitions outside, libraries inside
        std::fprintf(stderr, "%s: repetition %zu of %zu\n", p.name.c_str(), rep + 1, reps);
        for (auto& lib : libs) run_library(p, *lib, refs, orders, rep);
      }
    }
    print_table(p, libs, refs, reps);
    print_json(p, libs, refs, reps);
    if (!python_peers.empty()) run_python_peers(python_peers, p, libs, refs, reps);
    std::fflush(stdout);
    std::size_t bad = refs.brute_disagreements;
    for (const auto& lib : libs)
      for (int op = 0; op < kOps; ++op) bad += lib->exact_answers() ? lib->disagreements[op] : 0;
    total_bad += bad;
  };

  try {
    for (const WorkloadSpec* w : specs) {
      Problem p;
      p.name = w->name;
      p.data = w->data;
      p.dim = w->dim;
      p.n = w->n / divisor;
      p.nq = w->queries / divisor;
      if (max_queries) p.nq = std::min(p.nq, max_queries);
      const bool clustered = p.data == "clustered";
      std::fprintf(stderr, "%s: generating %zu points, %zu queries\n", p.name.c_str(), p.n, p.nq);
      if (p.data == "mfcc") {  // base, queries and calibration sample from different audio
        p.base = kdspace_bench::mfcc_static(p.n, 1, p.dim);
        p.queries = kdspace_bench::mfcc_static(p.nq, 2, p.dim);
        run_problem(p, kdspace_bench::mfcc_static(256, 3, p.dim));
        continue;
      }
      p.base = make_points(p.n, p.dim, clustered, 1);
      p.queries = make_points(p.nq, p.dim, clustered, 2);
      run_problem(p, make_points(256, p.dim, clustered, 3));
    }
    for (const auto& mesh : real_sets) {
      if (!wanted(mesh.name)) continue;
      Problem p = held_out_problem(mesh, max_queries);
      std::fprintf(stderr, "%s: %zu points of a real %s, %zu held out as queries\n", p.name.c_str(), p.n,
                   p.data.c_str(), p.nq);
      run_problem(p, calibration_sample(p));
    }
    if (!images_dir.empty() && wanted(kImagesWorkload)) {
      Problem p = image_problem(images_dir, divisor, max_queries);
      run_problem(p, calibration_sample(p));
    }
    for (const auto& f : files) {
      Problem p;
      p.name = workload_name_from(f.base);
      p.data = "file";
      std::fprintf(stderr, "%s: reading %s and %s\n", p.name.c_str(), f.base.c_str(), f.queries.c_str());
      auto base = kdspace::io::read_points<float>(f.base);
      auto queries = kdspace::io::read_points<float>(f.queries);
      if (base.cols != queries.cols)
        throw kdspace::Error(f.queries + ": queries have dimension " + std::to_string(queries.cols) + ", the base " +
                             std::to_string(base.cols));
      p.dim = base.cols;
      p.n = base.rows / divisor;
      p.nq = queries.rows / divisor;
      if (max_queries) p.nq = std::min(p.nq, max_queries);
      if (p.n < 100 || p.nq == 0) throw kdspace::Error(f.base + ": too few points or queries for the benchmark");
      base.data.resize(p.n * p.dim);
      p.base = std::move(base.data);
      queries.data.resize(p.nq * p.dim);
      p.queries = std::move(queries.data);
      run_problem(p, calibration_sample(p));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-bench: error: %s\n", e.what());
    return 1;
  }
  std::printf("\nExact answers that disagree, all workloads: %zu\n", total_bad);
  return total_bad == 0 ? 0 : 1;
}
