// The libraries kdspace-ann-bench runs side by side, behind one small interface: build on some
// threads, then answer a batch of queries (10-NN) with one of their settings on some threads.
//
//   kdspace graph    PointForest (4 trees and the neighbour graph, degree 32), searched by its graph;
//                    setting: ef
//   kdspace forest   PointForest without the graph (the same 4 trees); settings: trees 1 or 4, checks
//   hnswlib          HierarchicalNSW, M 16, efConstruction 200, built by parallel addPoint calls (as its
//                    Python binding does); setting: ef
//   faiss HNSW       IndexHNSWFlat, M 16, efConstruction 200; setting: efSearch
//   faiss IVF-Flat   IndexIVFFlat, 4 sqrt(n) lists, k-means on the base; setting: nprobe
//   FLANN            KDTreeIndex, 4 randomized kd-trees (its default); setting: checks
#pragma once

#include <faiss/IndexFlat.h>
#include <faiss/IndexHNSW.h>
#include <faiss/IndexIVFFlat.h>
#include <flann/flann.hpp>
#include <hnswlib/hnswlib.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "ann_datasets.hpp"
#include "kdspace/points/point_forest.hpp"

namespace kdspace_bench {

inline constexpr std::size_t ann_k = 10;

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// With --cpu-time, single-thread searches are timed by the CPU time of the calling thread (every
/// library answers a 1-thread batch on it): on a busy machine that leaves out the time the thread
/// waited for a core, which wall time counts.
inline bool g_cpu_time = false;

/// Seconds of the calling thread's CPU time.
inline double thread_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Seconds of CPU time of the whole process (all its threads).
inline double process_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Times a build: wall seconds, or with g_cpu_time the CPU seconds of all the process's threads
/// (their sum: what one thread would take if the build divided its work perfectly).
class BuildTimer {
 public:
  BuildTimer() : wall_(Clock::now()), cpu_(process_cpu_seconds()) {}
  double seconds() const { return g_cpu_time ? process_cpu_seconds() - cpu_ : seconds_since(wall_); }

 private:
  Clock::time_point wall_;
  double cpu_;
};

/// Times one batch: wall seconds, or with g_cpu_time and one thread, CPU seconds of this thread.
class BatchTimer {
 public:
  explicit BatchTimer(unsigned threads) : cpu_(g_cpu_time && threads <= 1) { start(); }
  void start() {
    wall_ = Clock::now();
    cpu_start_ = cpu_ ? thread_cpu_seconds() : 0;
  }
  double seconds() const { return cpu_ ? thread_cpu_seconds() - cpu_start_ : seconds_since(wall_); }

 private:
  bool cpu_;
  Clock::time_point wall_;
  double cpu_start_ = 0;
};

/// One setting of a library: a name for the tables and up to two numbers.
struct AnnSetting {
  std::string label;  // "ef 32", "trees 4, checks 256", ...
  std::size_t a = 0, b = 0;
};

/// The search widths every graph index is swept over (kdspace's graph, hnswlib, FAISS HNSW), so
/// their curves share their points; `name` is the library's word for it ("ef", "efSearch").
inline std::vector<AnnSetting> ef_settings(const std::string& name) {
  std::vector<AnnSetting> out;
  for (std::size_t ef : {10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 64, 80, 96, 128, 192, 256, 384, 512})
    out.push_back({name + " " + std::to_string(ef), ef, 0});
  return out;
}

class Contender {
 public:
  virtual ~Contender() = default;
  /// Builds the index on `threads` threads; build_s is its wall time.
  virtual void build(const AnnData& d, unsigned threads) = 0;
  virtual std::vector<AnnSetting> settings() const = 0;
  /// Answers d.queries (ann_k ids a query into `ids`) on `threads` threads; returns wall seconds.
  virtual double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) = 0;
  /// Bytes the index holds, the points included.
  virtual std::size_t memory_bytes() const = 0;
  std::string name;
  double build_s = 0;
};

/// Calls body(q) for q in [0, nq) on `threads` threads.
template <class Body>
void for_queries(std::size_t nq, unsigned threads, Body&& body) {
  if (threads <= 1) {
    for (std::size_t q = 0; q < nq; ++q) body(q);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::vector<std::thread> pool;
  auto run = [&] {
    for (std::size_t q; (q = next.fetch_add(16)) < nq;)
      for (std::size_t i = q; i < std::min(nq, q + 16); ++i) body(i);
  };
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(run);
  run();
  for (auto& t : pool) t.join();
}

// ---- kdspace --------------------------------------------------------------------------------------------

/// kdspace's index with its graph (the default from dimension 8 on), searched by the graph.
class KdspaceGraph : public Contender {
 public:
  KdspaceGraph() { name = "kdspace graph"; }
  void build(const AnnData& d, unsigned threads) override { make(d, threads, kdspace::GraphMode::on); }
  const kdspace::PointForest<float>& index() const { return *forest_; }
  std::vector<AnnSetting> settings() const override { return ef_settings("ef"); }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    return run(d, kdspace::ForestSearchParams{kdspace::unlimited_checks, 0, s.a}, threads, ids);
  }
  std::size_t memory_bytes() const override { return forest_->memory_bytes(); }

 protected:
  void make(const AnnData& d, unsigned threads, kdspace::GraphMode graph) {
    kdspace::ForestParams params;
    params.threads = threads;
    params.graph = graph;
    const BuildTimer timer;
    forest_ = std::make_unique<kdspace::PointForest<float>>(d.base.data(), d.n(), d.dim, params);
    build_s = timer.seconds();
  }
  double run(const AnnData& d, const kdspace::ForestSearchParams& p, unsigned threads, std::vector<std::uint32_t>& ids) {
    const BatchTimer timer(threads);
    const auto found = forest_->knn_batch(d.queries.data(), d.nq(), ann_k, p, threads);
    const double s = timer.seconds();
    ids.resize(found.neighbors.size());
    for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = found.neighbors[i].index;
    return s;
  }
  std::unique_ptr<kdspace::PointForest<float>> forest_;
};

/// kdspace's index without its graph (the same trees), searched by the trees.
class KdspaceForest : public KdspaceGraph {
 public:
  KdspaceForest() { name = "kdspace forest"; }
  void build(const AnnData& d, unsigned threads) override { make(d, threads, kdspace::GraphMode::off); }
  std::vector<AnnSetting> settings() const override {
    std::vector<AnnSetting> out;
    for (std::size_t trees : {1, 4})
      for (std::size_t checks : {16, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, 4096})
        out.push_back({"trees " + std::to_string(trees) + ", checks " + std::to_string(checks), trees, checks});
    return out;
  }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    return run(d, kdspace::ForestSearchParams{s.b, s.a, 0}, threads, ids);
  }
};

// ---- hnswlib ---------------------------------------------------------------------------------------------

class Hnswlib : public Contender {
 public:
  Hnswlib() { name = "hnswlib"; }
  void build(const AnnData& d, unsigned threads) override {
    space_ = std::make_unique<hnswlib::L2Space>(d.dim);
    const BuildTimer timer;
    index_ = std::make_unique<hnswlib::HierarchicalNSW<float>>(space_.get(), d.n(), 16, 200, 100);
    index_->addPoint(d.base.data(), 0);  // the first point alone, as its Python binding does
    std::atomic<std::size_t> next{1};
    std::vector<std::thread> pool;
    auto run = [&] {
      for (std::size_t i; (i = next.fetch_add(1)) < d.n();) index_->addPoint(d.base.data() + i * d.dim, i);
    };
    for (unsigned t = 1; t < threads; ++t) pool.emplace_back(run);
    run();
    for (auto& t : pool) t.join();
    build_s = timer.seconds();
  }
  std::vector<AnnSetting> settings() const override { return ef_settings("ef"); }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    index_->setEf(s.a);
    ids.assign(d.nq() * ann_k, 0);
    const BatchTimer timer(threads);
    for_queries(d.nq(), threads, [&](std::size_t q) {
      auto found = index_->searchKnn(d.queries.data() + q * d.dim, ann_k);
      for (std::size_t i = ann_k; i-- > 0 && !found.empty(); found.pop())
        ids[q * ann_k + i] = static_cast<std::uint32_t>(found.top().second);
    });
    return timer.seconds();
  }
  std::size_t memory_bytes() const override {
    // The base layer (links, vector and label of every point), the upper layers' links, and per
    // point its level, its upper-layer pointer and its entry in the label table (about 32 bytes).
    std::size_t upper = 0;
    for (std::size_t i = 0; i < index_->cur_element_count; ++i)
      upper += static_cast<std::size_t>(index_->element_levels_[i]) * index_->size_links_per_element_;
    return index_->cur_element_count * (index_->size_data_per_element_ + sizeof(int) + sizeof(void*) + 32) + upper;
  }

 private:
  std::unique_ptr<hnswlib::L2Space> space_;
  std::unique_ptr<hnswlib::HierarchicalNSW<float>> index_;
};

// ---- FAISS ----------------------------------------------------------------------------------------------

/// FAISS answers a batch with OpenMP over the queries.
inline double faiss_search(const faiss::Index& index, const AnnData& d, unsigned threads, std::vector<std::uint32_t>& ids) {
  omp_set_num_threads(static_cast<int>(threads));
  std::vector<float> dist(d.nq() * ann_k);
  std::vector<faiss::Index::idx_t> labels(d.nq() * ann_k);
  const BatchTimer timer(threads);
  index.search(static_cast<faiss::Index::idx_t>(d.nq()), d.queries.data(), static_cast<faiss::Index::idx_t>(ann_k),
               dist.data(), labels.data());
  const double s = timer.seconds();
  ids.assign(labels.begin(), labels.end());
  return s;
}

class FaissHnsw : public Contender {
 public:
  FaissHnsw() { name = "faiss HNSW"; }
  void build(const AnnData& d, unsigned threads) override {
    omp_set_num_threads(static_cast<int>(threads));
    const BuildTimer timer;
    index_ = std::make_unique<faiss::IndexHNSWFlat>(static_cast<int>(d.dim), 16);
    index_->hnsw.efConstruction = 200;
    index_->add(static_cast<faiss::Index::idx_t>(d.n()), d.base.data());
    build_s = timer.seconds();
  }
  std::vector<AnnSetting> settings() const override { return ef_settings("efSearch"); }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    index_->hnsw.efSearch = static_cast<int>(s.a);
    return faiss_search(*index_, d, threads, ids);
  }
  std::size_t memory_bytes() const override {
    const faiss::HNSW& h = index_->hnsw;
    return static_cast<std::size_t>(index_->ntotal) * static_cast<std::size_t>(index_->d) * sizeof(float) +
           h.neighbors.size() * sizeof(faiss::HNSW::storage_idx_t) + h.offsets.size() * sizeof(std::size_t) +
           h.levels.size() * sizeof(int);
  }

 private:
  std::unique_ptr<faiss::IndexHNSWFlat> index_;
};

class FaissIvf : public Contender {
 public:
  FaissIvf() { name = "faiss IVF-Flat"; }
  void build(const AnnData& d, unsigned threads) override {
    omp_set_num_threads(static_cast<int>(threads));
    lists_ = std::max<std::size_t>(1, static_cast<std::size_t>(4 * std::sqrt(static_cast<double>(d.n()))));
    const BuildTimer timer;
    quantizer_ = std::make_unique<faiss::IndexFlatL2>(static_cast<int>(d.dim));
    index_ = std::make_unique<faiss::IndexIVFFlat>(quantizer_.get(), d.dim, lists_);
    index_->cp.seed = 1234;
    index_->train(static_cast<faiss::Index::idx_t>(d.n()), d.base.data());
    index_->add(static_cast<faiss::Index::idx_t>(d.n()), d.base.data());
    build_s = timer.seconds();
  }
  std::vector<AnnSetting> settings() const override {
    std::vector<AnnSetting> out;
    for (std::size_t probes : {1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 256})
      if (probes <= lists_) out.push_back({"nprobe " + std::to_string(probes), probes, 0});
    return out;
  }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    index_->nprobe = s.a;
    return faiss_search(*index_, d, threads, ids);
  }
  std::size_t memory_bytes() const override {
    // Every vector and its 8-byte id in the lists, and the centroids.
    return static_cast<std::size_t>(index_->ntotal) * (static_cast<std::size_t>(index_->d) * sizeof(float) + 8) +
           lists_ * static_cast<std::size_t>(index_->d) * sizeof(float);
  }

 private:
  std::size_t lists_ = 0;
  std::unique_ptr<faiss::IndexFlatL2> quantizer_;
  std::unique_ptr<faiss::IndexIVFFlat> index_;
};

// ---- FLANN ----------------------------------------------------------------------------------------------

class Flann : public Contender {
 public:
  Flann() { name = "FLANN"; }
  void build(const AnnData& d, unsigned) override {
    flann::Matrix<float> data(const_cast<float*>(d.base.data()), d.n(), d.dim);
    const BuildTimer timer;
    index_ = std::make_unique<Index>(data, flann::KDTreeIndexParams(4));
    index_->buildIndex();
    build_s = timer.seconds();
    points_bytes_ = d.base.size() * sizeof(float);
  }
  std::vector<AnnSetting> settings() const override {
    std::vector<AnnSetting> out;
    for (std::size_t checks : {16, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, 4096})
      out.push_back({"checks " + std::to_string(checks), checks, 0});
    return out;
  }
  double search(const AnnData& d, const AnnSetting& s, unsigned threads, std::vector<std::uint32_t>& ids) override {
    flann::Matrix<float> q(const_cast<float*>(d.queries.data()), d.nq(), d.dim);
    std::vector<std::size_t> found(d.nq() * ann_k);
    std::vector<float> dists(d.nq() * ann_k);
    flann::Matrix<std::size_t> id_matrix(found.data(), d.nq(), ann_k);
    flann::Matrix<float> dist_matrix(dists.data(), d.nq(), ann_k);
    flann::SearchParams params(static_cast<int>(s.a), 0.0f, true);
    params.cores = static_cast<int>(threads);
    const BatchTimer timer(threads);
    index_->knnSearch(q, id_matrix, dist_matrix, ann_k, params);
    const double seconds = timer.seconds();
    ids.assign(found.begin(), found.end());
    return seconds;
  }
  /// FLANN searches the caller's points without a copy; they count here, as they must stay.
  std::size_t memory_bytes() const override { return index_->usedMemory() + points_bytes_; }

 private:
  using Index = flann::Index<flann::L2<float>>;
  std::unique_ptr<Index> index_;
  std::size_t points_bytes_ = 0;
};

}  // namespace kdspace_bench
