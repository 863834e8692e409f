// kdspace-index-bench: saved and updatable indexes.
//
//  1. Load against build. For 1e6 uniform 3-D float points (PointTree), 1e6 x 128-D byte descriptors
//     (PointForest, kept as bytes) and 1e6 boxes (BoxTree, SAH): the build, the save, and loading the
//     saved file by memory-mapping and by reading it (each load checks every checksum and the whole
//     structure). The loaded index must answer exactly as the built one (k-NN ids and distances, or
//     hits), else the exit status is 1. Loads read a file that was just written, so from the page
//     cache (warm), as an index kept on a server is. Then where a mapped load's time goes, each part
//     alone (min of the repetitions): opening and mapping, every checksum (one thread), the
//     structural checks of the kind's loader (two threads for a large point tree or box tree, one
//     for a forest), and reading the mapped bytes once (the floor, on one thread and on two), with
//     the minor page faults of a mapped load and the cost of starting a thread. The builds above run
//     on one thread (BuildParams::threads, 1 by default), each the first of its kind in this process,
//     the large point tree's and box tree's loads on two; so last, the point tree's build and mapped
//     load each on one thread, on two and (where the machine has more) on all hardware threads, like
//     with like, each in a fresh process (as a program that
//     builds or loads once pays them, page faults of its new memory included), with the same repeated
//     in this process beside them; and the same file's mapped load after the page cache dropped it
//     (posix_fadvise DONTNEED), from storage and then again, beside a plain read of every byte of a
//     mapping without and with the huge-page advice the loads give.
//  2. Updates. 1e6 uniform 3-D points, then churn: 500,000 random points removed one at a time and
//     500,000 new ones inserted, half one at a time and half in batches of 1,000, interleaved across
//     libraries in rounds of 50,000 operations: kdspace's DynamicPointTree, nanoflann's
//     KDTreeSingleIndexDynamicAdaptor (leaf 10; removal marks, never compacts) and hnswlib's
//     HierarchicalNSW (M 16, ef_construction 100; addPoint, markDelete). Throughputs in operations
//     per second.
//  3. Queries after the churn (50% of the points replaced): exact 10-NN, one thread, for the
//     DynamicPointTree as the churn left it, the same after compact(), a PointTree built afresh over
//     the points held, nanoflann's dynamic index, and hnswlib (ef 64; recall@10 beside it). The
//     DynamicPointTree's answers must equal the fresh tree's bit for bit (ids mapped), nanoflann's
//     distances must agree within 1e-5 relative; else the exit status is 1.
//
// usage: kdspace-index-bench [--quick] [--reps R] [--dir DIR] [--only load|updates|process]
//   --quick   sizes / 10 (for development)
//   --reps R  repetitions of the timed loads and queries, interleaved, median reported (default 5)
//   --dir D   where the index files go (default: the temporary folder)
//   --only process   only the point tree's build and load as a process pays them, and its load after
//                    the page cache dropped the file (the last two tables of 1.)
// Output: markdown tables, then one JSON line per measurement ({"bench":"index",...}).
#include <fcntl.h>
#include <hnswlib/hnswlib.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <nanoflann.hpp>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "kdspace/io/index.hpp"
#include "kdspace/kdspace.hpp"
#include "kdspace/rays/scene_gen.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}
double dbl(std::size_t x) {
  return static_cast<double>(x);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

std::vector<std::string> json_lines;
bool all_agree = true;

void json(const std::string& fields) {
  json_lines.push_back("{\"bench\": \"index\", " + fields + "}");
}
std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::vector<float> uniform_points(std::size_t n, std::size_t dim, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> p(n * dim);
  for (auto& v : p) v = u(rng);
  return p;
}

// SIFT-like byte descriptors: 256 cluster centres, each coordinate a centre's plus noise, clipped to
// 0..255.
std::vector<std::uint8_t> byte_descriptors(std::size_t n, std::size_t dim, std::uint32_t seed) {
  std::mt19937 centre_rng(99);
  std::uniform_int_distribution<int> level(0, 160);
  std::vector<int> centres(256 * dim);
  for (auto& c : centres) c = level(centre_rng);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 18);
  std::vector<std::uint8_t> p(n * dim);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t c = rng() % 256;
    for (std::size_t a = 0; a < dim; ++a)
      p[i * dim + a] =
          static_cast<std::uint8_t>(std::clamp(centres[c * dim + a] + std::lround(noise(rng)), 0L, 255L));
  }
  return p;
}

// ---- 1. load against build -----------------------------------------------------------------------------

struct LoadRow {
  std::string what;
  std::size_t n = 0;
  double build_s = 0, save_s = 0, file_mb = 0, map_s = 0, read_s = 0;
  double open_s = 0, checksums_s = 0, structure_s = 0, touch_s = 0, touch2_s = 0;  // the parts, alone, min
  double faults = 0;        // minor page faults of a whole mapped load (mean)
  double build_faults = 0;  // minor page faults of the build (the first of its kind in this process)
  bool same = false;
};

double minimum(const std::vector<double>& v) {
  return *std::min_element(v.begin(), v.end());
}

// Minor page faults of this process so far (all threads).
long minor_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// Seconds to start a thread that does nothing and join it (kdspace::detail::fork_join, as the
// two-thread checks start theirs): min of `reps`.
double thread_start_s(int reps) {
  std::vector<double> s;
  for (int r = 0; r < std::max(reps, 20); ++r) {
    const Clock::time_point start = Clock::now();
    kdspace::detail::fork_join([] {}, [] {});
    s.push_back(seconds_since(start));
  }
  return minimum(s);
}

// Seconds to map `path` and sum every 8-byte word of it: a mapped load's floor (it reads each byte). On
// two threads each sums half the words (the floor of a two-thread load, thread start included).
// advise_huge: madvise(MADV_HUGEPAGE) on the mapping first, as kdspace's loads do.
double read_mapped(const std::string& path, unsigned threads, bool advise_huge = true) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  const auto size = static_cast<std::size_t>(std::filesystem::file_size(path));
  const Clock::time_point start = Clock::now();
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  std::uint64_t sums[2] = {0, 0};
  if (map != MAP_FAILED) {
    if (advise_huge) (void)::madvise(map, size, MADV_HUGEPAGE);
    const auto* words = static_cast<const std::uint64_t*>(map);
    const std::size_t count = size / 8, half = threads > 1 ? count / 2 : count;
    const auto sum = [words](std::size_t begin, std::size_t end, std::uint64_t& out) {
      std::uint64_t total = 0;
      for (std::size_t i = begin; i < end; ++i) total += words[i];
      out = total;
    };
    if (threads > 1)
      kdspace::detail::fork_join([&] { sum(half, count, sums[1]); }, [&] { sum(0, half, sums[0]); });
    else
      sum(0, count, sums[0]);
  }
  const double s = seconds_since(start);
  if (sums[0] + sums[1] == 1)
    std::fprintf(stderr, "index-bench: %s sums to 1\n", path.c_str());  // keep the read
  if (map != MAP_FAILED) ::munmap(map, size);
  ::close(fd);
  if (map == MAP_FAILED) std::fprintf(stderr, "index-bench: could not map %s\n", path.c_str());
  return s;
}

// The parts of a mapped load, each alone on this thread: IndexFile::open without the checksums, the
// checksums, load_file(file) (the structural checks), and a read of every mapped byte.
template <class LoadFile>
void time_parts(LoadRow& row, const std::string& path, int reps, LoadFile load_file) {
  std::vector<double> open_s, checksums_s, structure_s, touch_s, touch2_s;
  for (int r = 0; r < reps; ++r) {
    Clock::time_point start = Clock::now();
    const auto file =
        kdspace::io::IndexFile::open(path, kdspace::io::LoadMode::map, kdspace::io::Checksums::deferred);
    open_s.push_back(seconds_since(start));
    start = Clock::now();
    file->verify_checksums();
    checksums_s.push_back(seconds_since(start));
    start = Clock::now();
    const auto loaded = load_file(file);
    structure_s.push_back(seconds_since(start));
    touch_s.push_back(read_mapped(path, 1));
    touch2_s.push_back(read_mapped(path, 2));
  }
  row.open_s = minimum(open_s);
  row.checksums_s = minimum(checksums_s);
  row.structure_s = minimum(structure_s);
  row.touch_s = minimum(touch_s);
  row.touch2_s = minimum(touch2_s);
}

// Times build() once, save(path) once, then `reps` interleaved loads of each mode; same(loaded)
// compares a loaded index's answers with the built one's.
template <class Index, class Build, class Load, class LoadFile, class Same>
LoadRow load_against_build(const std::string& what, std::size_t n, const std::string& path, int reps,
                           Build build, Load load, LoadFile load_file, Same same) {
  LoadRow row;
  row.what = what;
  row.n = n;
  std::fprintf(stderr, "index-bench: building %s\n", what.c_str());
  const long build_faults_before = minor_faults();
  Clock::time_point start = Clock::now();
  const Index built = build();
  row.build_s = seconds_since(start);
  row.build_faults = static_cast<double>(minor_faults() - build_faults_before);
  start = Clock::now();
  kdspace::io::save(path, built);
  row.save_s = seconds_since(start);
  row.file_mb = dbl(std::filesystem::file_size(path)) / 1e6;
  std::vector<double> map_s, read_s;
  row.same = true;
  long faults = 0;
  for (int r = 0; r < reps; ++r) {
    for (auto mode : {kdspace::io::LoadMode::map, kdspace::io::LoadMode::read}) {
      const long faults_before = minor_faults();
      start = Clock::now();
      const Index loaded = load(path, mode);
      (mode == kdspace::io::LoadMode::map ? map_s : read_s).push_back(seconds_since(start));
      if (mode == kdspace::io::LoadMode::map) faults += minor_faults() - faults_before;
      if (r == 0) row.same = row.same && same(built, loaded);
    }
  }
  row.faults = static_cast<double>(faults) / reps;
  row.map_s = median(map_s);
  row.read_s = median(read_s);
  time_parts(row, path, reps, load_file);
  all_agree = all_agree && row.same;
  std::filesystem::remove(path);
  json("\"part\": \"load\", \"index\": \"" + what + "\", \"n\": " + std::to_string(n) +
       ", \"build_s\": " + num(row.build_s) + ", \"build_faults\": " + num(row.build_faults) +
       ", \"save_s\": " + num(row.save_s) + ", \"file_mb\": " + num(row.file_mb) + ", \"load_map_s\": " +
       num(row.map_s) + ", \"load_read_s\": " + num(row.read_s) + ", \"open_s\": " + num(row.open_s) +
       ", \"checksums_s\": " + num(row.checksums_s) + ", \"structure_s\": " + num(row.structure_s) +
       ", \"read_mapped_s\": " + num(row.touch_s) + ", \"read_mapped_2_threads_s\": " + num(row.touch2_s) +
       ", \"faults\": " + num(row.faults) + ", \"same_answers\": " + (row.same ? "true" : "false"));
  return row;
}

// The point tree's build and mapped load as a user's process pays them. A process that builds a tree
// once gets its memory from the kernel page by page (glibc serves these large blocks by mmap, or from a
// heap it trims when they are freed), so its build pays about 9,000 minor page faults; a build repeated
// in one process can reuse pages malloc kept from the last one and pays none. So each figure here
// comes from a fresh process (this program run again with --child), and the repeated in-process
// figures are printed beside them; build and load each on one thread and on two (BuildParams::threads
// against load_point_tree(path, map, threads)), all interleaved, median of `reps` each.
struct Timed {
  double seconds = 0;
  double faults = 0;
  double verified = 0;  // ChildWork::load_pending: until every checksum was verified (seconds)
};

// Times work() (which returns what it made: freeing it is not timed) and counts its minor page faults.
template <class Work>
Timed timed(Work work) {
  const long faults_before = minor_faults();
  const Clock::time_point start = Clock::now();
  const auto made = work();
  return {seconds_since(start), static_cast<double>(minor_faults() - faults_before)};
}

using Tree3 = kdspace::PointTree<float>;

Tree3 build_tree(const std::vector<float>& base, std::size_t n, unsigned threads) {
  kdspace::BuildParams params;
  params.threads = threads;
  return Tree3(base.data(), n, 3, params);
}

Tree3 load_tree(const std::string& path, unsigned threads) {
  return kdspace::io::load_point_tree<float>(path, kdspace::io::LoadMode::map, kdspace::Verify::safety,
                                             threads);
}

// The load `kdspace knn --index` runs: the tree is ready once its structure is checked, the checksums
// left running on a thread of their own (PendingChecksums), waited for here at once.
Timed load_tree_pending(const std::string& path, unsigned threads) {
  namespace io = kdspace::io;
  const long faults_before = minor_faults();
  const Clock::time_point start = Clock::now();
  io::PendingChecksums pending;
  const Tree3 tree = io::load_point_tree_deferred<float>(
      io::IndexFile::open(path, io::LoadMode::map, io::Checksums::deferred), kdspace::Verify::safety, threads,
      &pending);
  Timed t{seconds_since(start), static_cast<double>(minor_faults() - faults_before)};
  pending.wait();
  t.verified = seconds_since(start);
  return t;
}

// What a child process times once.
enum class ChildWork { build, load, load_pending, read_plain, read_advised };
const char* const child_work_names[] = {"build", "load", "load-pending", "read-plain", "read-advised"};

// In the child: one build of the parent's points, one mapped load of `path` on `threads`, or one read
// of every byte of a mapping of `path` (read_mapped, on one thread) without or with the huge-page
// advice; prints its Timed.
int child_run(ChildWork work, unsigned threads, std::size_t n, const std::string& path) {
  Timed t;
  if (work == ChildWork::build) {
    const auto base = uniform_points(n, 3, 1);
    t = timed([&] { return build_tree(base, n, threads); });
  } else if (work == ChildWork::load) {
    t = timed([&] { return load_tree(path, threads); });
  } else if (work == ChildWork::load_pending) {
    t = load_tree_pending(path, threads);
  } else {
    const long faults_before = minor_faults();
    t.seconds = read_mapped(path, 1, work == ChildWork::read_advised);
    t.faults = static_cast<double>(minor_faults() - faults_before);
  }
  std::printf("%.9g %.0f %.9g\n", t.seconds, t.faults, t.verified);
  return 0;
}

std::string self_path() {
  std::vector<char> buf(4096);
  const ssize_t len = ::readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  if (len <= 0 || static_cast<std::size_t>(len) >= buf.size() - 1)
    throw std::runtime_error("cannot read /proc/self/exe (or its path is too long)");
  return std::string(buf.data(), static_cast<std::size_t>(len));
}

// Runs this program with --child and returns what it measured.
Timed in_fresh_process(ChildWork work, unsigned threads, std::size_t n, const std::string& path) {
  const std::string self = self_path();
  for (const std::string& name : {self, path})
    if (name.find('\'') != std::string::npos) throw std::runtime_error("a quote in " + name);
  const std::string command = "'" + self + "' --child " + child_work_names[static_cast<int>(work)] + " " +
                              std::to_string(threads) + " " + std::to_string(n) + " '" + path + "'";
  FILE* pipe = ::popen(command.c_str(), "r");
  Timed t;
  const bool ok = pipe && std::fscanf(pipe, "%lf %lf %lf", &t.seconds, &t.faults, &t.verified) == 3;
  if (!pipe || ::pclose(pipe) != 0 || !ok) throw std::runtime_error("the child run failed: " + command);
  return t;
}

// The median of one figure of the runs.
double median_of(const std::vector<Timed>& v, double Timed::*figure) {
  std::vector<double> x;
  for (const Timed& t : v) x.push_back(t.*figure);
  return median(x);
}
double seconds(const std::vector<Timed>& v) {
  return median_of(v, &Timed::seconds);
}
double faults(const std::vector<Timed>& v) {
  return median_of(v, &Timed::faults);
}

// Drops `path` (written and synced, mapped nowhere) from the page cache; returns the fraction of its
// pages still there afterwards (mincore), 1 where it could not be opened or mapped.
double evict_from_page_cache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 1;
  const auto size = static_cast<std::size_t>(std::filesystem::file_size(path));
  (void)::fdatasync(fd);
  (void)::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  double resident = 1;
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  if (map != MAP_FAILED) {
    const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE)),
                      pages = (size + page - 1) / page;
    std::vector<unsigned char> in(pages);
    if (::mincore(map, size, in.data()) == 0)
      resident = dbl(std::count_if(in.begin(), in.end(), [](unsigned char c) { return c & 1; })) / dbl(pages);
    ::munmap(map, size);
  }
  ::close(fd);
  return resident;
}

// A saved index is read back from storage once the system has dropped it from memory, and the page
// cache then holds it as that first read left it: in 4 KiB pages, or (for a mapping advised
// MADV_HUGEPAGE, as kdspace's loads are) in 2 MiB folios that later mappings take with one page-table
// entry each. Each repetition drops the file, then maps it in a fresh process twice, for kdspace's
// load on one thread and for a plain read of every byte without and with the advice.
void after_eviction(const std::string& path, int reps) {
  const ChildWork works[] = {ChildWork::load, ChildWork::read_plain, ChildWork::read_advised};
  const char* const labels[] = {"kdspace load_point_tree (mapped, 1 thread)", "read every byte, plain mmap",
                                "read every byte, mmap advised MADV_HUGEPAGE"};
  std::vector<Timed> first[3], second[3];
  std::vector<double> resident;
  for (int r = 0; r < reps; ++r)
    for (int w = 0; w < 3; ++w) {
      resident.push_back(evict_from_page_cache(path));
      first[w].push_back(in_fresh_process(works[w], 1, 0, path));
      second[w].push_back(in_fresh_process(works[w], 1, 0, path));
    }
  std::printf(
      "\n### The same file after the page cache dropped it (median of %d each, interleaved)\n\n"
      "Each repetition drops the file from the page cache (posix_fadvise DONTNEED; at most %.1f%% of its\n"
      "pages stayed), then maps it in a fresh process twice: the first mapping reads it from storage,\n"
      "the second finds it in the page cache as the first left it.\n\n"
      "| mapping | first, from storage ms | faults | second ms | faults |\n|---|---:|---:|---:|---:|\n",
      reps, 100 * *std::max_element(resident.begin(), resident.end()));
  for (int w = 0; w < 3; ++w) {
    std::printf("| %s | %.3f | %.0f | %.3f | %.0f |\n", labels[w], 1e3 * seconds(first[w]), faults(first[w]),
                1e3 * seconds(second[w]), faults(second[w]));
    json(std::string("\"part\": \"after_eviction\", \"work\": \"") +
         child_work_names[static_cast<int>(works[w])] + "\", \"first_s\": " + num(seconds(first[w])) +
         ", \"first_faults\": " + num(faults(first[w])) + ", \"second_s\": " + num(seconds(second[w])) +
         ", \"second_faults\": " + num(faults(second[w])));
  }
}

void point_tree_threads(std::size_t n, int reps, const std::string& dir) {
  const auto base = uniform_points(n, 3, 1);
  const std::string path = dir + "/bench-tree-threads.kdx";
  if (path.find('\'') != std::string::npos) throw std::runtime_error("a quote in " + path);
  kdspace::io::save(path, build_tree(base, n, 1));
  struct RemoveAtEnd {  // the file goes when this table ends, a failed child run included
    const std::string& path;
    ~RemoveAtEnd() {
      std::error_code ignored;
      std::filesystem::remove(path, ignored);
    }
  } remove_at_end{path};
  // One thread, two, and every hardware thread where there are more (the CLI's default for both).
  std::vector<unsigned> thread_counts = {1, 2};
  if (const unsigned all = std::thread::hardware_concurrency(); all > 2) thread_counts.push_back(all);
  // [i]: fresh-process and repeated in-process builds and loads on thread_counts[i] threads
  const std::size_t rows = thread_counts.size();
  std::vector<std::vector<Timed>> fresh_build(rows), fresh_load(rows), fresh_pending(rows), again_build(rows),
      again_load(rows);
  for (int r = 0; r < reps; ++r) {
    for (std::size_t i = 0; i < rows; ++i) {
      const unsigned threads = thread_counts[i];
      fresh_build[i].push_back(in_fresh_process(ChildWork::build, threads, n, path));
      fresh_load[i].push_back(in_fresh_process(ChildWork::load, threads, n, path));
      fresh_pending[i].push_back(in_fresh_process(ChildWork::load_pending, threads, n, path));
      again_build[i].push_back(timed([&] { return build_tree(base, n, threads); }));
      again_load[i].push_back(timed([&] { return load_tree(path, threads); }));
    }
  }
  std::printf(
      "\n### PointTree, %zu uniform 3-D float points: build and mapped load as a process pays them "
      "(median of %d each, interleaved)\n\n"
      "Fresh: each build or load the first in a new process (what `kdspace index` or a program that builds\n"
      "once pays, page faults of its new memory included); again: repeated in this process, where malloc\n"
      "may hand the build pages it already touched (the faults say how many it did not). The ratios use\n"
      "the fresh figures; \"÷ 1-thread build\" sets the load against the default build\n"
      "(BuildParams::threads = 1). Checksums pending: the load `kdspace knn --index` runs, the tree ready\n"
      "once its structure is checked, its checksums then taken on a thread of their own (PendingChecksums,\n"
      "waited for at once: \"verified\").\n\n"
      "| threads | build, fresh s | faults | build, again s | faults | load, fresh ms | faults | "
      "load, again ms | load ÷ build (same threads) | load ÷ 1-thread build | checksums pending: ready ms | "
      "verified ms | ready ÷ build |\n"
      "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
      n, reps);
  for (std::size_t i = 0; i < rows; ++i) {
    const unsigned t = thread_counts[i];
    const double build = seconds(fresh_build[i]), load = seconds(fresh_load[i]), ready = seconds(fresh_pending[i]);
    const double verified = median_of(fresh_pending[i], &Timed::verified);
    std::printf("| %u | %.4f | %.0f | %.4f | %.0f | %.3f | %.0f | %.3f | %.2f%% | %.2f%% | %.3f | %.3f | %.2f%% |\n",
                t, build, faults(fresh_build[i]), seconds(again_build[i]), faults(again_build[i]), 1e3 * load,
                faults(fresh_load[i]), 1e3 * seconds(again_load[i]), 100 * load / build,
                100 * load / seconds(fresh_build[0]), 1e3 * ready, 1e3 * verified, 100 * ready / build);
    json("\"part\": \"load_threads\", \"index\": \"PointTree, uniform 3-D float\", \"threads\": " +
         std::to_string(t) + ", \"build_fresh_s\": " + num(build) + ", \"build_fresh_faults\": " +
         num(faults(fresh_build[i])) + ", \"build_again_s\": " + num(seconds(again_build[i])) +
         ", \"build_again_faults\": " + num(faults(again_build[i])) + ", \"load_map_fresh_s\": " + num(load) +
         ", \"load_map_fresh_faults\": " + num(faults(fresh_load[i])) +
         ", \"load_map_again_s\": " + num(seconds(again_load[i])) + ", \"load_pending_fresh_s\": " + num(ready) +
         ", \"load_pending_verified_s\": " + num(verified));
  }
  after_eviction(path, reps);
}

void part_load(std::size_t scale, int reps, const std::string& dir) {
  std::vector<LoadRow> rows;
  const std::size_t n = 1000000 / scale, nq = 1000;
  {
    const auto base = uniform_points(n, 3, 1);
    const auto queries = uniform_points(nq, 3, 2);
    using Tree = kdspace::PointTree<float>;
    // The default load (Verify::safety) and the full check (Verify::full: every point against its
    // cell, the order a permutation), each against its own build.
    for (const kdspace::Verify verify : {kdspace::Verify::safety, kdspace::Verify::full})
      rows.push_back(load_against_build<Tree>(
          verify == kdspace::Verify::full ? "PointTree, uniform 3-D float (Verify::full)"
                                          : "PointTree, uniform 3-D float",
          n, dir + "/bench-tree.kdx", reps, [&] { return Tree(base.data(), n, 3); },
          [verify](const std::string& p, kdspace::io::LoadMode m) {
            return kdspace::io::load_point_tree<float>(p, m, verify);
          },
          [verify](const std::shared_ptr<const kdspace::io::IndexFile>& f) {
            return kdspace::io::load_point_tree<float>(f, verify);
          },
          [&](const Tree& a, const Tree& b) {
            return a.knn_batch(queries.data(), nq, 10, {}, 1).neighbors ==
                   b.knn_batch(queries.data(), nq, 10, {}, 1).neighbors;
          }));
  }
  {
    const std::size_t dim = 128;
    const auto base = byte_descriptors(n, dim, 3);
    const auto query_bytes = byte_descriptors(nq, dim, 4);
    const std::vector<float> queries(query_bytes.begin(), query_bytes.end());
    using Forest = kdspace::PointForest<float>;
    kdspace::ForestParams params;
    params.threads = 1;
    rows.push_back(load_against_build<Forest>(
        "PointForest, 128-D bytes (4 trees)", n, dir + "/bench-forest.kdx", reps,
        [&] { return Forest(base.data(), n, dim, params); },
        [](const std::string& p, kdspace::io::LoadMode m) {
          return kdspace::io::load_point_forest<float>(p, m);
        },
        [](const std::shared_ptr<const kdspace::io::IndexFile>& f) {
          return kdspace::io::load_point_forest<float>(f);
        },
        [&](const Forest& a, const Forest& b) {
          const kdspace::ForestSearchParams search{512, 0};
          return a.knn_batch(queries.data(), nq, 10, search, 1).neighbors ==
                 b.knn_batch(queries.data(), nq, 10, search, 1).neighbors;
        }));
  }
  {
    const auto boxes = kdspace::generate_boxes(n, kdspace::SceneKind::uniform, 5);
    const auto rays = kdspace::random_rays(10000, kdspace::Box3f{{0, 0, 0}, {1, 1, 1}}, 6);
    using kdspace::BoxTree;
    rows.push_back(load_against_build<BoxTree>(
        "BoxTree, uniform boxes (SAH, O(N log N))", n, dir + "/bench-boxes.kdx", reps,
        [&] { return BoxTree(boxes); },
        [](const std::string& p, kdspace::io::LoadMode m) { return kdspace::io::load_box_tree(p, m); },
        [](const std::shared_ptr<const kdspace::io::IndexFile>& f) { return kdspace::io::load_box_tree(f); },
        [&](const BoxTree& a, const BoxTree& b) {
          const auto x = a.closest_hit_batch(rays, 1), y = b.closest_hit_batch(rays, 1);
          for (std::size_t i = 0; i < rays.size(); ++i)
            if (x[i].box != y[i].box || !(x[i].t == y[i].t || !x[i].hit())) return false;
          return true;
        }));
  }
  std::printf("\n### Loading a saved index against building it (median of %d loads)\n\n", reps);
  std::printf(
      "| index | n | build s | build's page faults | save s | file MB | load, mapped s | mapped ÷ build | "
      "load, read s | same answers |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|:---:|\n");
  for (const LoadRow& r : rows)
    std::printf("| %s | %zu | %.3f | %.0f | %.3f | %.1f | %.4f | %.2f%% | %.4f | %s |\n", r.what.c_str(), r.n,
                r.build_s, r.build_faults, r.save_s, r.file_mb, r.map_s, 100 * r.map_s / r.build_s, r.read_s,
                r.same ? "yes" : "NO");
  std::printf(
      "\nWhere a mapped load's time goes: each part alone (min of %d), on one thread but for a large point\n"
      "tree's or box tree's structural checks, which run on two threads. Their loads checksum the\n"
      "arrays those threads read front to back (a point tree's nodes, points and order; a box tree's\n"
      "boxes, references and leaf blocks) just before they check them, and the other sections in\n"
      "chunks that both threads share; a forest checks its structure on one thread while a second\n"
      "takes the checksums, and both share what is left.\n\n",
      reps);
  const double thread_ms = 1e3 * thread_start_s(reps);
  std::printf(
      "| index | open and map ms | page faults a load | checksums ms | structural checks ms | "
      "thread start ms | read every mapped byte ms (floor) | the same on two threads ms |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const LoadRow& r : rows)
    std::printf("| %s | %.3f | %.0f | %.3f | %.3f | %.3f | %.3f | %.3f |\n", r.what.c_str(), 1e3 * r.open_s,
                r.faults, 1e3 * r.checksums_s, 1e3 * r.structure_s, thread_ms, 1e3 * r.touch_s,
                1e3 * r.touch2_s);
  json("\"part\": \"load\", \"thread_start_s\": " + num(thread_ms / 1e3));
  point_tree_threads(n, reps, dir);
}

// ---- 2. and 3. updates, and queries after churn ---------------------------------------------------------

// nanoflann's view of the points: every point ever added, by id (removed ones stay, marked in the index).
struct GrowingCloud {
  std::vector<float> coords;
  std::size_t kdtree_get_point_count() const { return coords.size() / 3; }
  float kdtree_get_pt(std::size_t i, std::size_t a) const { return coords[i * 3 + a]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using NanoDynamic =
    nanoflann::KDTreeSingleIndexDynamicAdaptor<nanoflann::L2_Simple_Adaptor<float, GrowingCloud>,
                                               GrowingCloud, 3, std::size_t>;

/// One library's updatable index of 3-D points, ids = positions in the stream of points.
class Updatable {
 public:
  virtual ~Updatable() = default;
  virtual const char* name() const = 0;
  virtual void insert(const float* rows, std::size_t first_id, std::size_t n, bool one_at_a_time) = 0;
  virtual void remove(const std::uint32_t* ids, std::size_t n) = 0;  // one at a time
  /// 10-NN of the queries; squared or true distances as `true_distances` says.
  virtual void knn10(const std::vector<float>& queries, std::vector<std::uint32_t>& ids,
                     std::vector<float>& dists) = 0;
  std::vector<double> seconds[3];  // insert one at a time, insert in batches, remove
  std::size_t ops[3] = {};
};

class KdspaceUpdatable : public Updatable {
 public:
  KdspaceUpdatable(const float* rows, std::size_t n) : tree_(rows, n, 3) {}
  const char* name() const override { return "kdspace DynamicPointTree"; }
  void insert(const float* rows, std::size_t, std::size_t n, bool one_at_a_time) override {
    if (!one_at_a_time) {
      tree_.insert(rows, n);
      return;
    }
    for (std::size_t i = 0; i < n; ++i) tree_.insert(rows + 3 * i, 1);
  }
  void remove(const std::uint32_t* ids, std::size_t n) override {
    for (std::size_t i = 0; i < n; ++i) tree_.remove(ids[i]);
  }
  void knn10(const std::vector<float>& q, std::vector<std::uint32_t>& ids,
             std::vector<float>& dists) override {
    answers(tree_.knn_batch(q.data(), q.size() / 3, 10, {}, 1), ids, dists);
  }
  static void answers(const kdspace::NeighborLists<float>& lists, std::vector<std::uint32_t>& ids,
                      std::vector<float>& dists) {
    ids.clear();
    dists.clear();
    for (const auto& nb : lists.neighbors) ids.push_back(nb.index), dists.push_back(nb.distance);
  }
  kdspace::DynamicPointTree<float> tree_;
};

class NanoflannUpdatable : public Updatable {
 public:
  NanoflannUpdatable(const float* rows, std::size_t n) {
    cloud_.coords.assign(rows, rows + 3 * n);
    index_ = std::make_unique<NanoDynamic>(3, cloud_, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  }
  const char* name() const override { return "nanoflann KDTreeSingleIndexDynamicAdaptor (leaf 10)"; }
  void insert(const float* rows, std::size_t first_id, std::size_t n, bool one_at_a_time) override {
    cloud_.coords.insert(cloud_.coords.end(), rows, rows + 3 * n);
    if (!one_at_a_time) {
      index_->addPoints(first_id, first_id + n - 1);
      return;
    }
    for (std::size_t i = 0; i < n; ++i) index_->addPoints(first_id + i, first_id + i);
  }
  void remove(const std::uint32_t* ids, std::size_t n) override {
    for (std::size_t i = 0; i < n; ++i) index_->removePoint(ids[i]);
  }
  void knn10(const std::vector<float>& q, std::vector<std::uint32_t>& ids,
             std::vector<float>& dists) override {
    const std::size_t nq = q.size() / 3;
    ids.assign(nq * 10, 0);
    dists.assign(nq * 10, 0);
    std::size_t found[10];
    float d2[10];
    for (std::size_t i = 0; i < nq; ++i) {
      nanoflann::KNNResultSet<float, std::size_t> result(10);
      result.init(found, d2);
      index_->findNeighbors(result, q.data() + 3 * i, nanoflann::SearchParams());
      for (std::size_t j = 0; j < 10; ++j)
        ids[i * 10 + j] = static_cast<std::uint32_t>(found[j]), dists[i * 10 + j] = std::sqrt(d2[j]);
    }
  }

 private:
  GrowingCloud cloud_;
  std::unique_ptr<NanoDynamic> index_;
};

class HnswUpdatable : public Updatable {
 public:
  HnswUpdatable(const float* rows, std::size_t n, std::size_t capacity) : space_(3) {
    index_ = std::make_unique<hnswlib::HierarchicalNSW<float>>(&space_, capacity, 16, 100);
    for (std::size_t i = 0; i < n; ++i) index_->addPoint(rows + 3 * i, i);
    index_->setEf(64);
  }
  const char* name() const override { return "hnswlib HierarchicalNSW (M 16, ef_construction 100, ef 64)"; }
  void insert(const float* rows, std::size_t first_id, std::size_t n, bool) override {
    for (std::size_t i = 0; i < n; ++i) index_->addPoint(rows + 3 * i, first_id + i);
  }
  void remove(const std::uint32_t* ids, std::size_t n) override {
    for (std::size_t i = 0; i < n; ++i) index_->markDelete(ids[i]);
  }
  void knn10(const std::vector<float>& q, std::vector<std::uint32_t>& ids,
             std::vector<float>& dists) override {
    const std::size_t nq = q.size() / 3;
    ids.assign(nq * 10, 0);
    dists.assign(nq * 10, 0);
    for (std::size_t i = 0; i < nq; ++i) {
      auto found = index_->searchKnn(q.data() + 3 * i, 10);
      for (std::size_t j = 10; j-- > 0 && !found.empty(); found.pop())
        ids[i * 10 + j] = static_cast<std::uint32_t>(found.top().second),
                     dists[i * 10 + j] = std::sqrt(found.top().first);
    }
  }

 private:
  hnswlib::L2Space space_;
  std::unique_ptr<hnswlib::HierarchicalNSW<float>> index_;
};

void part_updates(std::size_t scale, int reps) {
  const std::size_t n = 1000000 / scale, churn = n / 2, round = 50000 / scale,
                    nq = 10000 / (scale > 1 ? 10 : 1);
  const auto base = uniform_points(n, 3, 11);
  const auto fresh_points = uniform_points(churn, 3, 12);
  const auto queries = uniform_points(nq, 3, 13);
  std::vector<std::uint32_t> victims(n);
  std::iota(victims.begin(), victims.end(), 0u);
  std::shuffle(victims.begin(), victims.end(), std::mt19937(14));
  victims.resize(churn);

  std::vector<std::unique_ptr<Updatable>> libs;
  std::vector<double> initial_s;
  for (int l = 0; l < 3; ++l) {
    std::fprintf(stderr, "index-bench: initial build %d of 3\n", l + 1);
    const auto start = Clock::now();
    if (l == 0) libs.push_back(std::make_unique<KdspaceUpdatable>(base.data(), n));
    if (l == 1) libs.push_back(std::make_unique<NanoflannUpdatable>(base.data(), n));
    if (l == 2) libs.push_back(std::make_unique<HnswUpdatable>(base.data(), n, n + churn));
    initial_s.push_back(seconds_since(start));
  }
  // The churn, in rounds: each round removes `round` victims one at a time, then inserts `round` new
  // points (one at a time in the first half of the rounds, in batches of 1,000 in the second).
  std::size_t inserted = 0, removed = 0;
  while (removed < churn) {
    const std::size_t count = std::min(round, churn - removed);
    const bool one_at_a_time = inserted < churn / 2;
    std::fprintf(stderr, "index-bench: churn %zu / %zu\n", removed, churn);
    for (auto& lib : libs) {
      auto start = Clock::now();
      lib->remove(victims.data() + removed, count);
      lib->seconds[2].push_back(seconds_since(start));
      lib->ops[2] += count;
      const int kind = one_at_a_time ? 0 : 1;
      start = Clock::now();
      for (std::size_t b = 0; b < count; b += 1000) {
        const std::size_t m = std::min<std::size_t>(1000, count - b);
        lib->insert(fresh_points.data() + 3 * (inserted + b), n + inserted + b, m, one_at_a_time);
      }
      lib->seconds[kind].push_back(seconds_since(start));
      lib->ops[kind] += count;
    }
    removed += count;
    inserted += count;
  }

  // The points held after the churn, by id, and a PointTree built afresh over them (in id order).
  std::vector<bool> gone(n, false);
  for (std::uint32_t v : victims) gone[v] = true;
  std::vector<std::uint32_t> live_ids;
  std::vector<float> live;
  for (std::size_t i = 0; i < n + churn; ++i) {
    if (i < n && gone[i]) continue;
    live_ids.push_back(static_cast<std::uint32_t>(i));
    const float* p = i < n ? base.data() + 3 * i : fresh_points.data() + 3 * (i - n);
    live.insert(live.end(), p, p + 3);
  }
  auto* kd = static_cast<KdspaceUpdatable*>(libs[0].get());
  const std::size_t parts = kd->tree_.part_count(), pending = kd->tree_.removed_count();
  auto start = Clock::now();
  const kdspace::PointTree<float> fresh(live.data(), live_ids.size(), 3);
  const double fresh_build_s = seconds_since(start);
  start = Clock::now();
  kdspace::DynamicPointTree<float> copy = kdspace::io::load_dynamic_point_tree<float>(
      [&] {
        const std::string p = (std::filesystem::temp_directory_path() / "bench-churn.kdx").string();
        kdspace::io::save(p, kd->tree_);
        return p;
      }(),
      kdspace::io::LoadMode::read);
  copy.compact();
  const double compact_s = seconds_since(start);

  // Queries: reps interleaved across the five.
  const char* labels[5] = {"kdspace DynamicPointTree after the churn",
                           "kdspace DynamicPointTree after compact()", "kdspace PointTree built afresh",
                           "nanoflann dynamic after the churn", "hnswlib after the churn (ef 64)"};
  std::vector<double> query_s[5];
  std::vector<std::uint32_t> ids[5];
  std::vector<float> dists[5];
  for (int r = 0; r < reps; ++r) {
    for (int l = 0; l < 5; ++l) {
      start = Clock::now();
      if (l == 0) kd->knn10(queries, ids[l], dists[l]);
      if (l == 1) KdspaceUpdatable::answers(copy.knn_batch(queries.data(), nq, 10, {}, 1), ids[l], dists[l]);
      if (l == 2) KdspaceUpdatable::answers(fresh.knn_batch(queries.data(), nq, 10, {}, 1), ids[l], dists[l]);
      if (l == 3) libs[1]->knn10(queries, ids[l], dists[l]);
      if (l == 4) libs[2]->knn10(queries, ids[l], dists[l]);
      query_s[l].push_back(seconds_since(start));
    }
  }
  for (auto& i : ids[2]) i = live_ids[i];  // fresh tree's indices as ids
  const bool dynamic_exact =
      ids[0] == ids[2] && dists[0] == dists[2] && ids[1] == ids[2] && dists[1] == dists[2];
  std::size_t nano_off = 0, hnsw_found = 0;
  for (std::size_t i = 0; i < dists[2].size(); ++i) {
    const float ref = dists[2][i];
    nano_off += (dists[3][i] == ref || std::abs(dists[3][i] - ref) <= 1e-5f * ref) ? 0 : 1;
    hnsw_found += dists[4][i] <= dists[2][(i / 10) * 10 + 9] * (1 + 1e-5f) ? 1 : 0;
  }
  all_agree = all_agree && dynamic_exact && nano_off == 0;
  const double hnsw_recall = dbl(hnsw_found) / dbl(dists[2].size());

  const char* op_names[3] = {"insert, one at a time", "insert, batches of 1,000", "remove, one at a time"};
  std::printf(
      "\n### Updates: %zu points, then %zu removed and %zu inserted (ops/s; rounds of %zu, interleaved)\n\n",
      n, churn, churn, round);
  std::printf("| library | initial build s | %s | %s | %s |\n|---|---:|---:|---:|---:|\n", op_names[0],
              op_names[1], op_names[2]);
  for (std::size_t l = 0; l < libs.size(); ++l) {
    std::printf("| %s | %.2f", libs[l]->name(), initial_s[l]);
    std::string fields = "\"part\": \"updates\", \"library\": \"" + std::string(libs[l]->name()) +
                         "\", \"n\": " + std::to_string(n) + ", \"initial_build_s\": " + num(initial_s[l]);
    for (int k = 0; k < 3; ++k) {
      double total = 0;
      for (double s : libs[l]->seconds[k]) total += s;
      const double rate = dbl(libs[l]->ops[k]) / total;
      std::printf(" | %.0f", rate);
      fields += std::string(", \"") +
                (k == 0   ? "insert_one"
                 : k == 1 ? "insert_batch"
                          : "remove_one") +
                "_per_s\": " + num(rate);
    }
    std::printf(" |\n");
    json(fields);
  }
  std::printf(
      "\nkdspace after the churn: %zu parts, %zu removed points still held (tombstones); a PointTree over "
      "the "
      "%zu points held builds in %.3f s; save, load and compact() of the DynamicPointTree took %.3f s.\n",
      parts, pending, live_ids.size(), fresh_build_s, compact_s);
  std::printf("\n### Exact 10-NN after the churn (%zu queries, one thread, median of %d)\n\n", nq, reps);
  std::printf("| index | queries/s | ÷ fresh PointTree | answers |\n|---|---:|---:|---|\n");
  const double fresh_s = median(query_s[2]);
  for (int l = 0; l < 5; ++l) {
    const double s = median(query_s[l]);
    std::string note = l <= 2   ? (dynamic_exact ? "equal to the fresh tree's, bit for bit" : "DIFFER")
                       : l == 3 ? (nano_off == 0 ? "distances equal within 1e-5"
                                                 : std::to_string(nano_off) + " distances differ")
                                : "recall@10 " + num(hnsw_recall);
    std::printf("| %s | %.0f | %.2f | %s |\n", labels[l], dbl(nq) / s, fresh_s / s, note.c_str());
    json(std::string("\"part\": \"queries_after_churn\", \"index\": \"") + labels[l] +
         "\", \"queries_per_s\": " + num(dbl(nq) / s) +
         (l == 4 ? ", \"recall_at_10\": " + num(hnsw_recall) : std::string()));
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 6 && std::string(argv[1]) == "--child") {
    try {
      const auto named = std::find_if(std::begin(child_work_names), std::end(child_work_names),
                                      [&](const char* name) { return std::string(argv[2]) == name; });
      if (named == std::end(child_work_names)) throw std::runtime_error(std::string("no work ") + argv[2]);
      return child_run(static_cast<ChildWork>(named - std::begin(child_work_names)),
                       static_cast<unsigned>(std::atoi(argv[3])),
                       static_cast<std::size_t>(std::atoll(argv[4])), argv[5]);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "kdspace-index-bench --child: %s\n", e.what());
      return 1;
    }
  }
  std::size_t scale = 1;
  int reps = 5;
  std::string dir = std::filesystem::temp_directory_path().string(), only;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick")
      scale = 10;
    else if (a == "--reps" && i + 1 < argc)
      reps = std::max(1, std::atoi(argv[++i]));
    else if (a == "--dir" && i + 1 < argc)
      dir = argv[++i];
    else if (a == "--only" && i + 1 < argc)
      only = argv[++i];
    else {
      std::fprintf(
          stderr,
          "usage: kdspace-index-bench [--quick] [--reps R] [--dir DIR] [--only load|updates|process]\n");
      return 2;
    }
  }
  try {
    if (only.empty() || only == "load") part_load(scale, reps, dir);
    if (only.empty() || only == "updates") part_updates(scale, reps);
    if (only == "process") point_tree_threads(1000000 / scale, reps, dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-index-bench: %s\n", e.what());
    return 1;
  }
  std::printf("\n");
  for (const std::string& line : json_lines) std::printf("%s\n", line.c_str());
  if (!all_agree) std::fprintf(stderr, "kdspace-index-bench: ANSWERS DISAGREE (see the tables)\n");
  return all_agree ? 0 : 1;
}
