// rays_scaling: measures the BoxTree builds and traversal on generated scenes.
//
//   rays_scaling [--sizes N,N,...] [--threads T] [--repeat R] [--rays M] [--no-scaling] [--no-probability]
//                [--no-binning] [--tune]
//
// 1. Build scaling of sah_nlogn (the default, binned above binning_threshold boxes), of sah_nlogn
//    exact at every node (threshold 0), and of sah up to 400k boxes, on uniform scenes: the best of
//    R builds per size (default 3), and t(2N) / t(N). For N log N that ratio is 2 (1 + 1/log2 N),
//    about 2.12 at N = 1e5; N log^2 N adds another factor (1 + 1/log2 N), about 2.24. "same" checks
//    that the exact sah_nlogn and sah trees are identical.
// 2. Surface area against volume probability on 1e5-box scenes: SAH cost of the trees (always
//    measured by surface area), references, leaves, and trace speed for random rays and for the
//    primary rays of a 1024 x 768 camera.
// 3. Binning: the default threshold against the exact sweep everywhere and binning at every node, on
//    1e5 and 1e6 uniform and clustered boxes: build time on 1 and on all threads, SAH cost, and trace
//    speed (primary and random rays, 1 thread), so that the tree quality binning gives up is seen.
// 4. With --tune, the trace speed for a range of K_i / K_t ratios and empty bonuses.
// One thread unless --threads says otherwise. Prints plain text tables.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/scene_gen.hpp"

using namespace kdspace;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Options {
  std::vector<std::size_t> sizes{100000, 200000, 400000, 800000, 1600000};
  unsigned threads = 1;
  int repeat = 3;
  std::size_t rays = 1000000;
  bool scaling = true;
  bool probability = true;
  bool binning = true;
  bool tune = false;
};

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "rays_scaling: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--sizes") {
      o.sizes.clear();
      const std::string list = next();
      std::size_t pos = 0;
      while (pos < list.size()) {
        const std::size_t comma = std::min(list.find(',', pos), list.size());
        o.sizes.push_back(static_cast<std::size_t>(std::stod(list.substr(pos, comma - pos))));
        pos = comma + 1;
      }
    } else if (a == "--threads") {
      o.threads = static_cast<unsigned>(std::stoul(next()));
    } else if (a == "--repeat") {
      o.repeat = std::max(1, std::stoi(next()));
    } else if (a == "--rays") {
      o.rays = std::stoul(next());
    } else if (a == "--no-scaling") {
      o.scaling = false;
    } else if (a == "--no-probability") {
      o.probability = false;
    } else if (a == "--no-binning") {
      o.binning = false;
    } else if (a == "--tune") {
      o.tune = true;
    } else {
      std::fprintf(stderr,
                   "usage: rays_scaling [--sizes N,N,...] [--threads T] [--repeat R] [--rays M] "
                   "[--no-scaling] [--no-probability] [--no-binning] [--tune]\n");
      std::exit(2);
    }
  }
  return o;
}

double best_build_seconds(const std::vector<Box3f>& boxes, const BoxBuildParams& params, int runs) {
  double best = 1e300;
  for (int r = 0; r < runs; ++r) best = std::min(best, BoxTree(boxes, params).stats().build_seconds);
  return best;
}

struct TraceResult {
  double mrays_per_s;
  RayStats stats;
};

/// Best of two runs.
TraceResult trace(const BoxTree& tree, const std::vector<Ray>& rays, unsigned threads) {
  TraceResult best{0, {}};
  for (int r = 0; r < 2; ++r) {
    RayStats stats;
    const auto start = Clock::now();
    tree.closest_hit_batch(rays, threads, &stats);
    const double mrays = static_cast<double>(rays.size()) / seconds_since(start) / 1e6;
    if (mrays > best.mrays_per_s) best = TraceResult{mrays, stats};
  }
  return best;
}

void build_scaling(const Options& o) {
  std::printf("== build time on uniform scenes, %u thread(s), best of %d ==\n", o.threads, o.repeat);
  std::printf("%10s  %12s %8s  %12s %8s  %10s %8s  %9s %7s %6s\n", "boxes", "sah_nlogn s", "ratio", "exact s",
              "ratio", "sah s", "ratio", "refs/box", "depth", "same");
  double previous[3] = {0, 0, 0};
  for (const std::size_t n : o.sizes) {
    const std::vector<Box3f> boxes = generate_boxes(n, SceneKind::uniform, 1);
    BoxBuildParams p;
    p.threads = o.threads;
    p.method = BoxBuildMethod::sah_nlogn;
    const int runs = o.repeat;
    const double fast = best_build_seconds(boxes, p, runs);
    const BoxTree tree(boxes, p);
    p.binning_threshold = 0;
    const double exact = best_build_seconds(boxes, p, runs);
    const BoxTree exact_tree(boxes, p);
    double slow = 0;
    bool same = true;
    if (n <= 400000) {
      p.method = BoxBuildMethod::sah;
      slow = best_build_seconds(boxes, p, runs);
      const BoxTree slow_tree(boxes, p);
      same = slow_tree.nodes() == exact_tree.nodes() && slow_tree.references() == exact_tree.references();
    }
    const double now[3] = {fast, exact, slow};
    char ratio[3][32] = {"", "", ""}, slow_text[32] = "-";
    for (int k = 0; k < 3; ++k)
      if (previous[k] > 0 && now[k] > 0)
        std::snprintf(ratio[k], sizeof ratio[k], "%.3f", now[k] / previous[k]);
    if (slow > 0) std::snprintf(slow_text, sizeof slow_text, "%.3f", slow);
    std::printf("%10zu  %12.3f %8s  %12.3f %8s  %10s %8s  %9.3f %7zu %6s\n", n, fast, ratio[0], exact,
                ratio[1], slow_text, ratio[2], tree.stats().references_per_box, tree.stats().depth,
                n <= 400000 ? (same ? "yes" : "NO") : "-");
    std::fflush(stdout);
    for (int k = 0; k < 3; ++k) previous[k] = now[k];
  }
}

void probability_comparison(const Options& o) {
  std::printf("\n== surface area vs volume probability, 100000 boxes, sah_nlogn, %u thread(s) ==\n",
              o.threads);
  std::printf(
      "(sah_cost always by surface area; random: %zu rays from inside the grown bounds; primary: 1024x768)\n",
      o.rays);
  std::printf("%-10s %-13s %9s %9s %8s %6s %8s  %10s %8s %8s  %10s\n", "scene", "probability", "sah_cost",
              "refs/box", "leaves", "depth", "build s", "random Mr/s", "nodes/r", "boxes/r", "primary Mr/s");
  for (const SceneKind kind : {SceneKind::uniform, SceneKind::clustered}) {
    const std::vector<Box3f> boxes = generate_boxes(100000, kind, 1);
    for (const HitProbability prob : {HitProbability::surface_area, HitProbability::volume}) {
      BoxBuildParams p;
      p.threads = o.threads;
      p.probability = prob;
      const BoxTree tree(boxes, p);
      const std::vector<Ray> random = random_rays(o.rays, tree.bounds(), 2);
      const std::vector<Ray> primary = primary_rays(fit_camera(tree.bounds(), 4.0 / 3.0), 1024, 768);
      const TraceResult r = trace(tree, random, o.threads);
      const TraceResult pr = trace(tree, primary, o.threads);
      const BoxTreeStats& s = tree.stats();
      std::printf("%-10s %-13s %9.2f %9.3f %8zu %6zu %8.3f  %10.3f %8.2f %8.2f  %10.3f\n",
                  kind == SceneKind::uniform ? "uniform" : "clustered",
                  prob == HitProbability::surface_area ? "surface_area" : "volume", s.sah_cost,
                  s.references_per_box, s.leaves, s.depth, s.build_seconds, r.mrays_per_s,
                  r.stats.nodes_visited_per_ray(), r.stats.boxes_tested_per_ray(), pr.mrays_per_s);
      std::fflush(stdout);
    }
  }
}

void binning_comparison(const Options& o) {
  std::printf("\n== binning: build and trace, best of %d builds; trace 1 thread ==\n", o.repeat);
  std::printf(
      "(threshold: nodes with more boxes place their plane by binning; 0 = exact sweep everywhere)\n");
  std::printf("%-10s %8s %10s %9s %9s %9s %10s  %11s %11s\n", "scene", "boxes", "threshold", "build s",
              "all thr s", "sah_cost", "refs/box", "primary Mr/s", "random Mr/s");
  const unsigned all = std::max(1u, std::thread::hardware_concurrency());
  for (const std::size_t n : {std::size_t{100000}, std::size_t{1000000}})
    for (const SceneKind kind : {SceneKind::uniform, SceneKind::clustered}) {
      const std::vector<Box3f> boxes = generate_boxes(n, kind, 1);
      for (const std::size_t threshold :
           {std::size_t{0}, std::size_t{1}, std::size_t{256}, std::size_t{4096}}) {
        BoxBuildParams p;
        p.binning_threshold = threshold;
        p.threads = 1;
        const double one = best_build_seconds(boxes, p, o.repeat);
        p.threads = all;
        const double many = best_build_seconds(boxes, p, o.repeat);
        p.threads = 1;
        const BoxTree tree(boxes, p);
        const std::vector<Ray> random = random_rays(o.rays, tree.bounds(), 2);
        const std::vector<Ray> primary = primary_rays(fit_camera(tree.bounds(), 4.0 / 3.0), 1024, 768);
        const TraceResult r = trace(tree, random, 1);
        const TraceResult pr = trace(tree, primary, 1);
        std::printf("%-10s %8zu %10zu %9.3f %9.3f %9.2f %10.3f  %11.3f %11.3f\n",
                    kind == SceneKind::uniform ? "uniform" : "clustered", n, threshold, one, many,
                    tree.stats().sah_cost, tree.stats().references_per_box, pr.mrays_per_s, r.mrays_per_s);
        std::fflush(stdout);
      }
    }
}

void tune(const Options& o) {
  std::printf("\n== K_i / K_t and empty bonus (K_t = 1), 100000 boxes, %u thread(s) ==\n", o.threads);
  std::printf("%-10s %6s %6s %9s %9s %8s  %10s %10s\n", "scene", "K_i", "bonus", "sah_cost", "refs/box",
              "leaves", "random Mr/s", "primary Mr/s");
  for (const SceneKind kind : {SceneKind::uniform, SceneKind::clustered}) {
    const std::vector<Box3f> boxes = generate_boxes(100000, kind, 1);
    for (const float k_i : {0.1f, 0.15f, 0.25f, 0.35f, 0.5f, 0.75f, 1.0f})
      for (const float bonus : {0.0f, 0.1f, 0.2f, 0.5f}) {
        BoxBuildParams p;
        p.threads = o.threads;
        p.K_t = 1;
        p.K_i = k_i;
        p.empty_bonus = bonus;
        const BoxTree tree(boxes, p);
        const std::vector<Ray> random = random_rays(o.rays, tree.bounds(), 2);
        const std::vector<Ray> primary = primary_rays(fit_camera(tree.bounds(), 4.0 / 3.0), 1024, 768);
        const TraceResult r = trace(tree, random, o.threads);
        const TraceResult pr = trace(tree, primary, o.threads);
        std::printf("%-10s %6.2f %6.2f %9.2f %9.3f %8zu  %10.3f %10.3f\n",
                    kind == SceneKind::uniform ? "uniform" : "clustered", k_i, bonus, tree.stats().sah_cost,
                    tree.stats().references_per_box, tree.stats().leaves, r.mrays_per_s, pr.mrays_per_s);
        std::fflush(stdout);
      }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  if (o.scaling) build_scaling(o);
  if (o.probability) probability_comparison(o);
  if (o.binning) binning_comparison(o);
  if (o.tune) tune(o);
  return 0;
}
