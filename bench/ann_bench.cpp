// kdspace-ann-bench: approximate 10-NN, side by side in one process: kdspace (its graph and its trees),
// hnswlib, FAISS (HNSW and IVF-Flat) and FLANN's randomized kd-trees (ann_contenders.hpp), on real
// descriptors computed here and on synthetic clustered points (ann_datasets.hpp).
//
// For each data set every library builds its index on all threads (build seconds, bytes a point),
// then answers the same queries on one thread at each of its settings; repetitions are interleaved
// (each repetition runs every library's settings in turn) and the median time is kept. Recall@10 is
// measured against exact answers (kdspace's blocked scan, exact by construction), counting a returned
// point as found when its true distance is no larger than the true 10th (so ties count). Then, for
// recall@10 targets 0.9, 0.95 and 0.99: each library's fastest setting that reaches the target, its
// queries/s on one thread and on all threads, and kdspace's ratio to hnswlib. Last, kdspace's own
// tuning (PointForest::tune on the tuning queries, which the bench's queries are not among) for 0.9
// and 0.99: the setting it chose, its seconds, and that setting's recall and queries/s on the bench's
// queries; with the build, against hnswlib's build.
//
// usage: kdspace-ann-bench [--dataset NAME]... [--audio DIR] [--images DIR] [--libraries LIST]
//                          [--quick] [--reps R] [--n N] [--queries Q] [--threads T] [--cpu-time]
//   NAME: speech, music, images (these need --audio / --images: bench/run_all.sh unpacks the
//         recordings and photographs there), clustered8d, clustered16d, clustered32d, clustered64d,
//         clustered128d, clustered960d. Default: the real sets found, and clustered 64/128/960-D.
//   LIST: comma-separated among kdspace, hnswlib, faiss-hnsw, faiss-ivf, flann (default all).
//   --cpu-time: time 1-thread searches by the thread's CPU time, not wall time (for a busy machine).
// Output: per data set, markdown tables on stdout, then JSON lines ({"bench":"ann",...}); progress on
// stderr.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "ann_contenders.hpp"
#include "ann_datasets.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/point_forest.hpp"

namespace {

using namespace kdspace_bench;

const double kTargets[] = {0.9, 0.95, 0.99};

struct Options {
  std::vector<std::string> datasets;
  std::string audio, images;
  std::vector<std::string> libraries{"kdspace", "hnswlib", "faiss-hnsw", "faiss-ivf", "flann"};
  std::size_t n = 100000, nq = 1000, reps = 3;
  unsigned threads = std::max(1u, std::thread::hardware_concurrency());
};

/// Recall@10 of answers given as ids (ann_k a query), from true distances.
double recall_of(const AnnData& d, const std::vector<std::uint32_t>& ids, const kdspace::NeighborLists<float>& exact) {
  double hits = 0;
  for (std::size_t q = 0; q < d.nq(); ++q) {
    const float* query = d.queries.data() + q * d.dim;
    const float kth = exact.row(q)[ann_k - 1].distance;
    for (std::size_t i = 0; i < ann_k; ++i) {
      const std::uint32_t id = ids[q * ann_k + i];
      if (id >= d.n()) continue;  // a library that found fewer than k (FAISS marks them -1)
      const float dist = std::sqrt(kdspace::internal_distance<kdspace::L2>(query, d.base.data() + std::size_t{id} * d.dim, d.dim));
      if (dist <= kth) hits += 1;
    }
  }
  return hits / static_cast<double>(d.nq() * ann_k);
}

struct Point {  // one library at one setting
  Contender* library;
  AnnSetting setting;
  std::vector<double> seconds;  // one per repetition
  double recall = 0;
  double qps(std::size_t nq) const {
    std::vector<double> s = seconds;
    std::sort(s.begin(), s.end());
    return static_cast<double>(nq) / s[s.size() / 2];
  }
};

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

bool wanted(const Options& o, const std::string& library) {
  return std::find(o.libraries.begin(), o.libraries.end(), library) != o.libraries.end();
}

void run(const AnnData& d, const Options& o) {
  std::fprintf(stderr, "%s: %zu points, %zu queries, %zu-D\n", d.name.c_str(), d.n(), d.nq(), d.dim);
  std::vector<std::unique_ptr<Contender>> libraries;
  auto graph = std::make_unique<KdspaceGraph>();  // always: its index gives the exact answers
  const KdspaceGraph& kdspace_graph = *graph;
  libraries.push_back(std::move(graph));
  if (wanted(o, "kdspace")) libraries.push_back(std::make_unique<KdspaceForest>());
  if (wanted(o, "hnswlib")) libraries.push_back(std::make_unique<Hnswlib>());
  if (wanted(o, "faiss-hnsw")) libraries.push_back(std::make_unique<FaissHnsw>());
  if (wanted(o, "faiss-ivf")) libraries.push_back(std::make_unique<FaissIvf>());
  if (wanted(o, "flann")) libraries.push_back(std::make_unique<Flann>());
  for (auto& library : libraries) {
    library->build(d, o.threads);
    std::fprintf(stderr, "  %s built in %.2f s (%u threads)\n", library->name.c_str(), library->build_s, o.threads);
  }
  const kdspace::PointForest<float>& forest = kdspace_graph.index();
  const auto exact = forest.knn_exact_batch(d.queries.data(), d.nq(), ann_k, 0);
  const std::size_t nq = d.nq();

  // kdspace's own tuning, on the tuning queries.
  struct Tuned {
    double target;
    kdspace::ForestTuning tuning;
    double seconds;  // of tune(), timed like the builds
    double recall, qps;
  };
  std::vector<Tuned> tuned;
  for (double target : {0.9, 0.99}) {
    kdspace::TuneParams tp;
    tp.threads = o.threads;
    const BuildTimer tune_timer;
    const kdspace::ForestTuning t = forest.tune(target, ann_k, d.tuning_queries.data(), d.tuning_queries.size() / d.dim, tp);
    const double tune_s = tune_timer.seconds();
    double best = 1e300, recall = 0;
    for (std::size_t rep = 0; rep < o.reps; ++rep) {
      const BatchTimer timer(1);
      const auto found = forest.knn_batch(d.queries.data(), nq, ann_k, t.search(), 1);
      best = std::min(best, timer.seconds());
      recall = kdspace::recall_at_k(found, exact);
    }
    tuned.push_back({target, t, tune_s, recall, static_cast<double>(nq) / best});
    std::fprintf(stderr, "  kdspace tune(%.2f): %s in %.2f s\n", target,
                 t.ef ? ("ef " + std::to_string(t.ef)).c_str()
                      : ("trees " + std::to_string(t.trees) + ", checks " + std::to_string(t.checks)).c_str(),
                 tune_s);
  }

  // The curves: every library's settings on one thread, repetitions interleaved. A library's settings
  // stop at the first that reaches recall 0.999 in the first repetition (the rest are only slower).
  std::vector<Point> points;
  std::vector<std::uint32_t> ids;
  for (auto& library : libraries) {
    if (library->name == "kdspace graph" && !wanted(o, "kdspace")) continue;
    for (const AnnSetting& s : library->settings()) {
      Point p{library.get(), s, {}, 0};
      p.seconds.push_back(library->search(d, s, 1, ids));
      p.recall = recall_of(d, ids, exact);
      points.push_back(p);
      if (p.recall >= 0.999) break;
    }
  }
  for (std::size_t rep = 1; rep < o.reps; ++rep) {
    std::fprintf(stderr, "  repetition %zu of %zu\n", rep + 1, o.reps);
    for (Point& p : points) p.seconds.push_back(p.library->search(d, p.setting, 1, ids));
  }

  // Each library's fastest setting at each target, then on all threads.
  struct Best {
    const Point* point = nullptr;
    double qps_all = 0;
  };
  std::map<std::pair<double, Contender*>, Best> best;
  for (double target : kTargets)
    for (const Point& p : points) {
      if (p.recall < target) continue;
      Best& b = best[{target, p.library}];
      if (!b.point || p.qps(nq) > b.point->qps(nq)) b.point = &p;
    }
  for (auto& [key, b] : best) {
    double fastest = 1e300;
    for (std::size_t rep = 0; rep < o.reps; ++rep)
      fastest = std::min(fastest, b.point->library->search(d, b.point->setting, o.threads, ids));
    b.qps_all = static_cast<double>(nq) / fastest;
  }

  // ---- tables ----
  const Contender* hnsw = nullptr;
  for (auto& library : libraries)
    if (library->name == "hnswlib") hnsw = library.get();
  std::printf("\n### %s (%s; %zu points, %zu queries, %zu-D)\n\n", d.name.c_str(), d.description.c_str(), d.n(), nq, d.dim);
  std::printf("| library | build s (%u threads%s) | bytes a point |\n|---|---:|---:|\n", o.threads,
              g_cpu_time ? ", CPU time of all threads" : "");
  for (auto& library : libraries) {
    if (library->name == "kdspace graph" && !wanted(o, "kdspace")) continue;
    std::printf("| %s | %.2f | %.0f |\n", library->name.c_str(), library->build_s,
                static_cast<double>(library->memory_bytes()) / static_cast<double>(d.n()));
  }
  std::printf("\nkdspace: graph of degree %zu, %zu principal directions, points kept as %s.\n", forest.graph_degree(),
              forest.projected_dims(), forest.compact() ? "bytes" : "floats");

  std::printf("\n| recall@10 at least | library | setting | recall@10 | q/s, 1 thread | q/s, %u threads | ÷ hnswlib (1 thread) |\n"
              "|---:|---|---|---:|---:|---:|---:|\n", o.threads);
  for (double target : kTargets) {
    const auto hnsw_best = hnsw ? best.find({target, const_cast<Contender*>(hnsw)}) : best.end();
    const double hnsw_qps = hnsw_best != best.end() ? hnsw_best->second.point->qps(nq) : 0;
    for (auto& library : libraries) {
      const auto it = best.find({target, library.get()});
      if (it == best.end()) {
        if (library->name != "kdspace graph" || wanted(o, "kdspace"))
          std::printf("| %.2f | %s | not reached | | | | |\n", target, library->name.c_str());
        continue;
      }
      const Point& p = *it->second.point;
      const std::string ratio = hnsw_qps > 0 ? fmt("%.2f", p.qps(nq) / hnsw_qps) : "-";
      std::printf("| %.2f | %s | %s | %.4f | %.0f | %.0f | %s |\n", target, library->name.c_str(), p.setting.label.c_str(),
                  p.recall, p.qps(nq), it->second.qps_all, ratio.c_str());
      std::printf("{\"bench\":\"ann\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"op\":\"target\",\"target_recall10\":%.2f,"
                  "\"library\":\"%s\",\"setting\":\"%s\",\"recall10\":%.4f,\"qps\":%.1f,\"qps_all_threads\":%.1f,"
                  "\"threads\":%u,\"hnswlib_qps\":%.1f}\n",
                  d.name.c_str(), d.dim, d.n(), target, library->name.c_str(), p.setting.label.c_str(), p.recall,
                  p.qps(nq), it->second.qps_all, o.threads, hnsw_qps);
    }
  }

  std::printf("\n| kdspace tune for | chose | tune s | build + tune s | ÷ hnswlib build | recall@10 on the queries | q/s, 1 thread |\n"
              "|---:|---|---:|---:|---:|---:|---:|\n");
  for (const Tuned& t : tuned) {
    const std::string chose = t.tuning.ef ? "graph, ef " + std::to_string(t.tuning.ef)
                                          : "trees " + std::to_string(t.tuning.trees) + ", checks " + std::to_string(t.tuning.checks);
    const double total = kdspace_graph.build_s + t.seconds;
    const std::string ratio = hnsw ? fmt("%.3f", total / hnsw->build_s) : "-";
    std::printf("| %.2f | %s | %.2f | %.2f | %s | %.4f | %.0f |\n", t.target, chose.c_str(), t.seconds, total,
                ratio.c_str(), t.recall, t.qps);
    std::printf("{\"bench\":\"ann\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"op\":\"tune\",\"target_recall10\":%.2f,"
                "\"ef\":%zu,\"trees\":%zu,\"checks\":%zu,\"tune_s\":%.3f,\"build_s\":%.3f,\"hnswlib_build_s\":%.3f,"
                "\"validation_recall\":%.4f,\"recall10\":%.4f,\"qps\":%.1f}\n",
                d.name.c_str(), d.dim, d.n(), t.target, t.tuning.ef, t.tuning.trees, t.tuning.checks, t.seconds,
                kdspace_graph.build_s, hnsw ? hnsw->build_s : 0.0, t.tuning.validation_recall, t.recall, t.qps);
  }

  std::printf("\n<details><summary>all settings (1 thread, median of %zu)</summary>\n\n| library | setting | recall@10 | q/s |\n"
              "|---|---|---:|---:|\n", o.reps);
  for (const Point& p : points)
    std::printf("| %s | %s | %.4f | %.0f |\n", p.library->name.c_str(), p.setting.label.c_str(), p.recall, p.qps(nq));
  std::printf("\n</details>\n\n");
  for (auto& library : libraries)
    std::printf("{\"bench\":\"ann\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"op\":\"build\",\"library\":\"%s\","
                "\"build_s\":%.3f,\"threads\":%u,\"bytes_per_point\":%.1f}\n",
                d.name.c_str(), d.dim, d.n(), library->name.c_str(), library->build_s, o.threads,
                static_cast<double>(library->memory_bytes()) / static_cast<double>(d.n()));
  for (const Point& p : points)
    std::printf("{\"bench\":\"ann\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"queries\":%zu,\"op\":\"curve\","
                "\"library\":\"%s\",\"setting\":\"%s\",\"recall10\":%.4f,\"qps\":%.1f,\"reps\":%zu}\n",
                d.name.c_str(), d.dim, d.n(), nq, p.library->name.c_str(), p.setting.label.c_str(), p.recall, p.qps(nq), o.reps);
  std::fflush(stdout);
}

std::vector<std::string> split(const std::string& list) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = list.find(',', start);
    out.push_back(list.substr(start, comma - start));
    if (comma == std::string::npos) return out;
    start = comma + 1;
  }
}

int usage() {
  std::fprintf(stderr, "usage: kdspace-ann-bench [--dataset speech|music|images|clustered8d|clustered16d|clustered32d|"
                       "clustered64d|clustered128d|clustered960d]... [--audio DIR] [--images DIR]\n"
                       "                         [--libraries kdspace,hnswlib,faiss-hnsw,faiss-ivf,flann] [--quick] "
                       "[--reps R] [--n N] [--queries Q] [--threads T] [--cpu-time]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--quick") o.n = 20000, o.nq = 200, o.reps = 1;
    else if (a == "--dataset" && has_value) o.datasets.push_back(argv[++i]);
    else if (a == "--audio" && has_value) o.audio = argv[++i];
    else if (a == "--images" && has_value) o.images = argv[++i];
    else if (a == "--libraries" && has_value) o.libraries = split(argv[++i]);
    else if (a == "--reps" && has_value) o.reps = static_cast<std::size_t>(std::max(1, std::atoi(argv[++i])));
    else if (a == "--n" && has_value) o.n = static_cast<std::size_t>(std::max(100, std::atoi(argv[++i])));
    else if (a == "--queries" && has_value) o.nq = static_cast<std::size_t>(std::max(10, std::atoi(argv[++i])));
    else if (a == "--cpu-time") g_cpu_time = true;
    else if (a == "--threads" && has_value) o.threads = static_cast<unsigned>(std::max(1, std::atoi(argv[++i])));
    else return usage();
  }
  for (const std::string& library : o.libraries)
    if (library != "kdspace" && library != "hnswlib" && library != "faiss-hnsw" && library != "faiss-ivf" && library != "flann")
      return usage();
  if (o.datasets.empty()) {
    if (!o.audio.empty()) o.datasets = {"speech", "music"};
    else std::fprintf(stderr, "kdspace-ann-bench: no --audio DIR: the speech and music data sets are skipped\n");
    if (!o.images.empty()) o.datasets.push_back("images");
    else std::fprintf(stderr, "kdspace-ann-bench: no --images DIR: the image descriptor data set is skipped\n");
    for (const char* name : {"clustered64d", "clustered128d", "clustered960d"}) o.datasets.push_back(name);
  }
  std::printf("# kdspace-ann-bench: approximate 10-NN; kdspace, hnswlib, FAISS, FLANN; queries/s on 1 thread (median of %zu%s) "
              "and on %u threads\n", o.reps, g_cpu_time ? ", thread CPU time" : "", o.threads);
  try {
    for (const std::string& name : o.datasets) {
      if (name == "speech" || name == "music") {
        if (o.audio.empty()) throw std::runtime_error("the " + name + " data set needs --audio DIR");
        run(name == "speech" ? speech(o.audio, o.n, o.nq) : music(o.audio, o.n, o.nq), o);
      } else if (name == "images") {
        if (o.images.empty()) throw std::runtime_error("the images data set needs --images DIR");
        run(photos(o.images, o.n, o.nq), o);
      } else if (name.rfind("clustered", 0) == 0 && name.size() > 10 && name.back() == 'd') {
        const int dim = std::atoi(name.c_str() + 9);
        if (dim < 1) return usage();
        run(clustered(o.n, o.nq, static_cast<std::size_t>(dim)), o);
      } else {
        std::fprintf(stderr, "kdspace-ann-bench: unknown data set %s\n", name.c_str());
        return 2;
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-ann-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
