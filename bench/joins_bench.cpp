// kdspace-joins-bench: the dual-tree joins beside kdspace's single-tree batch, SciPy's cKDTree
// (workers=1) and, for all-kNN, pykdtree, on one thread, on the same double-precision 3-D points.
//
// For each data set: all-kNN (each point's k nearest other points; the single-tree batch and the
// peers ask for k + 1 and find the point itself among them), every pair within r (r: the median
// distance of a point's k-th nearest neighbour, so about k pairs a point), and pair counts at 20
// radii from r / 10 to 3 r (geometric) in one call. The peers run in a separate process
// (bench/joins_peers.py through /usr/bin/python3); repetitions alternate kdspace and the peers, and
// the median is reported. Every answer is cross-checked: the dual-tree and single-tree k-NN bit for
// bit, SciPy's and pykdtree's k-NN distances within 1e-12 relative (indices may differ only between
// equal distances), SciPy's pairs equal to kdspace's, its counts equal; a disagreement makes the exit
// status 1.
//
// usage: kdspace-joins-bench [--n N] [--k K] [--reps R] [--real DIR] [--only NAME]... [--no-peers]
//                            [--python PATH] [--scratch DIR] [--clock wall|cpu]
//   --n N        points of the synthetic sets (default 1000000)
//   --k K        neighbours a point (default 10)
//   --reps R     repetitions (default 3)
//   --real DIR   also the real scans in DIR (the data/ folder of libcgal-demo's data.tar.gz:
//                points_3/building.ply, points_3/b9_training.ply, meshes/bunny00.off); see README
//   --only NAME  only this data set (repeatable): uniform3d, clustered3d, building, b9_training, bunny00
//   --no-peers   kdspace only
//   --clock C    wall (default) or cpu: kdspace's times in the process's CPU time (busy machines)
//
// Output: a markdown table on stdout, then one JSON line per data set; progress on stderr.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "kdspace/io/vectors.hpp"
#include "kdspace/joins/joins.hpp"
#include "kdspace/points/point_tree.hpp"
#include "real_points.hpp"

#ifndef KDSPACE_SOURCE_DIR
#define KDSPACE_SOURCE_DIR "."
#endif

namespace {

using Tree = kdspace::PointTree<double, 3>;

// The clock of kdspace's measurements: wall time (steady_clock), or with --clock cpu the process's
// CPU time, which other work on a busy machine disturbs less (the peers time themselves, in wall time).
bool g_cpu_clock = false;

double now_seconds() {
  if (g_cpu_clock) {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double seconds_since(double start) { return now_seconds() - start; }

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Options {
  std::size_t n = 1000000, k = 10, reps = 3;
  std::string real_dir, python = "/usr/bin/python3", scratch;
  std::vector<std::string> only;
  bool peers = true;
};

struct DataSet {
  std::string name, source;
  std::vector<double> xyz;
  std::size_t n() const { return xyz.size() / 3; }
};

// Uniform in [0, 1)^3, or 64 Gaussian blobs (standard deviation 0.03) with centres uniform in [0, 1)^3.
DataSet synthetic(const std::string& name, std::size_t n, bool clustered) {
  std::mt19937 rng(clustered ? 2 : 1);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::normal_distribution<double> spread(0, 0.03);
  std::vector<double> centres(64 * 3);
  for (double& c : centres) c = uniform(rng);
  DataSet d{name, clustered ? "64 Gaussian blobs" : "uniform in the unit cube", std::vector<double>(n * 3)};
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t blob = rng() % 64;
    for (std::size_t a = 0; a < 3; ++a) d.xyz[i * 3 + a] = clustered ? centres[blob * 3 + a] + spread(rng) : uniform(rng);
  }
  return d;
}

// Repeated coordinates are kept: scans and meshes have them, and the joins must handle them.
DataSet real(const std::string& dir, const std::string& name, const std::string& file) {
  const bench::Cloud cloud = bench::read_cloud(dir + "/" + file);
  return DataSet{name, file, cloud.xyz};
}

struct Times {
  std::vector<double> build, dual, single, pairs, count;
};

struct PeerTimes {
  std::vector<double> scipy_build, scipy_knn, scipy_pairs, scipy_count, pyk_build, pyk_knn;
  std::string scipy_version;
  std::uint64_t scipy_pair_count = 0;
  std::vector<std::uint64_t> scipy_counts;
};

// A number after "key": in a one-line JSON object (the peers' output); NAN when absent.
double json_number(const std::string& json, const std::string& key) {
  const std::size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return NAN;
  return std::strtod(json.c_str() + at + key.size() + 3, nullptr);
}

std::vector<std::uint64_t> json_integers(const std::string& json, const std::string& key) {
  std::vector<std::uint64_t> out;
  std::size_t at = json.find("\"" + key + "\": [");
  if (at == std::string::npos) return out;
  const char* p = json.c_str() + at + key.size() + 5;
  while (*p && *p != ']') {
    char* end = nullptr;
    out.push_back(std::strtoull(p, &end, 10));
    p = end;
    while (*p == ',' || *p == ' ') ++p;
  }
  return out;
}

std::string run_peers(const Options& o, const std::string& npy, std::size_t k, double r, const std::vector<double>& radii,
                      const std::string& save_prefix) {
  std::string radii_text;
  char buf[64];
  for (double x : radii) {
    std::snprintf(buf, sizeof buf, "%.17g", x);
    radii_text += (radii_text.empty() ? "" : ",") + std::string(buf);
  }
  std::snprintf(buf, sizeof buf, "%.17g", r);
  std::string command = o.python + " " + KDSPACE_SOURCE_DIR + "/bench/joins_peers.py " + npy + " --k " +
                        std::to_string(k) + " --r " + buf + " --radii " + radii_text;
  if (!save_prefix.empty()) command += " --save " + save_prefix;
  std::FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return "";
  std::string out;
  char chunk[4096];
  while (std::fgets(chunk, sizeof chunk, pipe)) out += chunk;
  if (pclose(pipe) != 0) {
    std::fprintf(stderr, "peers failed: %s\n", command.c_str());
    return "";
  }
  return out;
}

template <class T>
kdspace::io::Matrix<T> load(const std::string& path) {
  return kdspace::io::read_points<T>(path);
}

int failures = 0;

void fail(const std::string& what) {
  std::fprintf(stderr, "MISMATCH: %s\n", what.c_str());
  ++failures;
}

// A peer's k+1 nearest (the point itself among them) against kdspace's k nearest others: the same
// distances within 1e-12 relative at every rank, the same indices except between equal distances.
void check_peer_knn(const std::string& peer, const std::string& prefix, const kdspace::NeighborLists<double>& ours,
                    std::size_t k) {
  const auto ids = load<double>(prefix + "." + peer + "_ids.npy");
  const auto dists = load<double>(prefix + "." + peer + "_dists.npy");
  std::size_t index_swaps = 0, bad = 0;
  for (std::size_t i = 0; i < ours.rows(); ++i) {
    std::size_t o = 0;
    bool self_seen = false;
    for (std::size_t j = 0; j < k + 1 && o < k; ++j) {
      const auto id = static_cast<std::uint32_t>(ids.row(i)[j]);
      if (id == i && !self_seen) {
        self_seen = true;
        continue;
      }
      const auto& nb = ours.row(i)[o++];
      if (std::abs(nb.distance - dists.row(i)[j]) > 1e-12 * std::max(1.0, nb.distance)) ++bad;
      else if (nb.index != id) ++index_swaps;
    }
  }
  if (bad > 0) fail(peer + " k-NN: " + std::to_string(bad) + " distances differ");
  std::fprintf(stderr, "  %s k-NN agrees (%zu indices differ only between equal distances)\n", peer.c_str(), index_swaps);
}

void check_scipy_pairs(const std::string& prefix, const std::vector<kdspace::IndexPair>& ours) {
  const auto pairs = load<double>(prefix + ".scipy_pairs.npy");
  bool same = pairs.rows == ours.size();
  for (std::size_t i = 0; same && i < ours.size(); ++i)
    same = static_cast<std::uint32_t>(pairs.row(i)[0]) == ours[i].a && static_cast<std::uint32_t>(pairs.row(i)[1]) == ours[i].b;
  if (!same) fail("SciPy pairs differ: " + std::to_string(pairs.rows) + " vs " + std::to_string(ours.size()));
  else std::fprintf(stderr, "  SciPy pairs agree (%zu)\n", ours.size());
}

void run(const Options& o, const DataSet& data) {
  const std::size_t n = data.n(), k = o.k;
  std::fprintf(stderr, "%s: %zu points (%s)\n", data.name.c_str(), n, data.source.c_str());
  kdspace::JoinParams one_thread;
  one_thread.threads = 1;
  kdspace::BuildParams build;
  build.threads = 1;

  // r and the radii come from the data (an untimed first join, which also warms the caches).
  const Tree probe(data.xyz.data(), n, 3, build);
  const auto first = kdspace::self_knn_join(probe, k, one_thread);
  std::vector<double> kth(n);
  for (std::size_t i = 0; i < n; ++i) kth[i] = first.row(i)[k - 1].distance;
  const double r = median(kth);
  std::vector<double> radii;
  for (int j = 0; j < 20; ++j) radii.push_back(r / 10 * std::pow(30.0, j / 19.0));

  const std::string npy = o.scratch + "/" + data.name + ".npy";
  if (o.peers) kdspace::io::write_points<double>(npy, kdspace::io::Matrix<double>{n, 3, data.xyz});

  Times ours;
  PeerTimes peers;
  kdspace::NeighborLists<double> dual;
  std::vector<kdspace::IndexPair> pairs;
  std::vector<std::uint64_t> counts;
  kdspace::JoinStats knn_stats, pair_stats, count_stats;
  for (std::size_t rep = 0; rep < o.reps; ++rep) {
    std::fprintf(stderr, "  repetition %zu: kdspace", rep + 1);
    double start = now_seconds();
    const Tree tree(data.xyz.data(), n, 3, build);
    ours.build.push_back(seconds_since(start));
    knn_stats = pair_stats = count_stats = {};
    start = now_seconds();
    dual = kdspace::self_knn_join(tree, k, one_thread, &knn_stats);
    ours.dual.push_back(seconds_since(start));
    kdspace::SearchParams single_params;
    single_params.batch_method = kdspace::BatchMethod::tree;
    start = now_seconds();
    const auto single = tree.knn_batch(data.xyz.data(), n, k + 1, single_params, 1);
    ours.single.push_back(seconds_since(start));
    start = now_seconds();
    pairs = kdspace::pairs_within(tree, r, one_thread, &pair_stats);
    ours.pairs.push_back(seconds_since(start));
    start = now_seconds();
    counts = kdspace::count_pairs(tree, radii, one_thread, &count_stats);
    ours.count.push_back(seconds_since(start));
    if (rep == 0) {  // the single-tree answers, self removed, are the dual-tree answers bit for bit
      std::size_t bad = 0;
      for (std::size_t i = 0; i < n; ++i) {
        std::size_t out = 0;
        for (std::size_t j = 0; j < k + 1 && out < k; ++j) {
          if (single.row(i)[j].index == i) continue;  // the point itself (absent among k + 1 duplicates)
          if (!(single.row(i)[j] == dual.row(i)[out++])) ++bad;
        }
      }
      if (bad) fail("single-tree and dual-tree k-NN differ in " + std::to_string(bad) + " places");
      if (counts.size() != radii.size()) fail("count size");
    }
    if (!o.peers) {
      std::fprintf(stderr, "\n");
      continue;
    }
    std::fprintf(stderr, ", peers\n");
    const std::string prefix = o.scratch + "/" + data.name;
    const std::string json = run_peers(o, npy, k, r, radii, rep == 0 ? prefix : "");
    if (json.empty()) {
      fail("the peers did not run");
      continue;
    }
    peers.scipy_build.push_back(json_number(json, "scipy_build_s"));
    peers.scipy_knn.push_back(json_number(json, "scipy_knn_s"));
    peers.scipy_pairs.push_back(json_number(json, "scipy_pairs_s"));
    peers.scipy_count.push_back(json_number(json, "scipy_count_s"));
    peers.pyk_build.push_back(json_number(json, "pykdtree_build_s"));
    peers.pyk_knn.push_back(json_number(json, "pykdtree_knn_s"));
    if (rep == 0) {
      const std::size_t v = json.find("\"scipy_version\": \"");
      if (v != std::string::npos) peers.scipy_version = json.substr(v + 18, json.find('"', v + 18) - v - 18);
      check_peer_knn("scipy", prefix, dual, k);
      if (!std::isnan(peers.pyk_knn.back())) check_peer_knn("pykdtree", prefix, dual, k);
      check_scipy_pairs(prefix, pairs);
      if (json_integers(json, "scipy_counts") != counts) fail("SciPy counts differ");
      else std::fprintf(stderr, "  SciPy counts agree (largest radius: %llu pairs)\n", static_cast<unsigned long long>(counts.back()));
    }
  }

  const double dual_s = median(ours.dual), single_s = median(ours.single), pairs_s = median(ours.pairs),
               count_s = median(ours.count);
  const double scipy_knn = median(peers.scipy_knn), scipy_pairs = median(peers.scipy_pairs),
               scipy_count = median(peers.scipy_count), pyk_knn = median(peers.pyk_knn);
  std::printf("| %s | %zu | %.3f | %.3f | %.3f | %.3f | **%.2f** | **%.2f** | %.3f | %.3f | **%.2f** | %.3f | %.3f | **%.2f** | %.2f |\n",
              data.name.c_str(), n, median(ours.build), dual_s, single_s, scipy_knn, single_s / dual_s, scipy_knn / dual_s,
              pyk_knn, pairs_s, scipy_pairs / pairs_s, count_s, scipy_count, scipy_count / count_s, pyk_knn / dual_s);
  std::fflush(stdout);
  std::fprintf(stderr,
               "{\"bench\": \"joins\", \"data\": \"%s\", \"n\": %zu, \"k\": %zu, \"r\": %.9g, \"pairs\": %zu, "
               "\"count_at_largest_radius\": %llu, \"build_s\": %.4f, \"dual_knn_s\": %.4f, \"single_knn_s\": %.4f, "
               "\"pairs_s\": %.4f, \"count_s\": %.4f, \"scipy_build_s\": %.4f, \"scipy_knn_s\": %.4f, \"scipy_pairs_s\": %.4f, "
               "\"scipy_count_s\": %.4f, \"pykdtree_build_s\": %.4f, \"pykdtree_knn_s\": %.4f, \"scipy\": \"%s\", "
               "\"knn_node_pairs\": %llu, \"knn_distances\": %llu, \"pairs_distances\": %llu, \"count_distances\": %llu, "
               "\"count_bulk_pairs\": %llu}\n",
               data.name.c_str(), n, k, r, pairs.size(), static_cast<unsigned long long>(counts.back()), median(ours.build),
               dual_s, single_s, pairs_s, count_s, median(peers.scipy_build), scipy_knn, scipy_pairs, scipy_count,
               median(peers.pyk_build), pyk_knn, peers.scipy_version.c_str(),
               static_cast<unsigned long long>(knn_stats.node_pairs), static_cast<unsigned long long>(knn_stats.distances),
               static_cast<unsigned long long>(pair_stats.distances), static_cast<unsigned long long>(count_stats.distances),
               static_cast<unsigned long long>(count_stats.bulk_pairs));
}

bool wanted(const Options& o, const std::string& name) {
  return o.only.empty() || std::find(o.only.begin(), o.only.end(), name) != o.only.end();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--n" && has_value) o.n = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--k" && has_value) o.k = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--reps" && has_value) o.reps = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--real" && has_value) o.real_dir = argv[++i];
    else if (a == "--only" && has_value) o.only.push_back(argv[++i]);
    else if (a == "--python" && has_value) o.python = argv[++i];
    else if (a == "--scratch" && has_value) o.scratch = argv[++i];
    else if (a == "--no-peers") o.peers = false;
    else if (a == "--clock" && has_value) {
      const std::string clock = argv[++i];
      if (clock != "wall" && clock != "cpu") {
        std::fprintf(stderr, "--clock: wall or cpu\n");
        return 2;
      }
      g_cpu_clock = clock == "cpu";
    }
    else {
      std::fprintf(stderr, "usage: kdspace-joins-bench [--n N] [--k K] [--reps R] [--real DIR] [--only NAME]... "
                           "[--no-peers] [--python PATH] [--scratch DIR] [--clock wall|cpu]\n");
      return 2;
    }
  }
  if (o.k == 0 || o.reps == 0 || o.n < o.k + 1) {
    std::fprintf(stderr, "need k >= 1, reps >= 1, n > k\n");
    return 2;
  }
  if (o.scratch.empty()) o.scratch = (std::filesystem::temp_directory_path() / "kdspace-joins-bench").string();
  std::filesystem::create_directories(o.scratch);

  std::printf("All-kNN (k = %zu, each point's nearest others), pairs within r (r: median k-th neighbour distance), "
              "counts at 20 radii r/10 .. 3r; one thread; seconds (%s), median of %zu.\n\n",
              o.k, g_cpu_clock ? "kdspace: CPU time" : "wall", o.reps);
  std::printf("| data | n | build | all-kNN dual | all-kNN single-tree | all-kNN SciPy | single ÷ dual | SciPy ÷ dual | "
              "all-kNN pykdtree | pairs | SciPy ÷ kdspace | counts | counts SciPy | SciPy ÷ kdspace | pykdtree ÷ dual |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  try {
    if (wanted(o, "uniform3d")) run(o, synthetic("uniform3d", o.n, false));
    if (wanted(o, "clustered3d")) run(o, synthetic("clustered3d", o.n, true));
    if (!o.real_dir.empty()) {
      if (wanted(o, "building")) run(o, real(o.real_dir, "building", "points_3/building.ply"));
      if (wanted(o, "b9_training")) run(o, real(o.real_dir, "b9_training", "points_3/b9_training.ply"));
      if (wanted(o, "bunny00")) run(o, real(o.real_dir, "bunny00", "meshes/bunny00.off"));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  if (failures) std::fprintf(stderr, "%d mismatches\n", failures);
  return failures ? 1 : 0;
}
