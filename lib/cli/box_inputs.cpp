#include "box_inputs.hpp"

#include <chrono>
#include <filesystem>
#include <system_error>

#include "kdspace/error.hpp"
#include "kdspace/io/scene.hpp"
#include "progress.hpp"

namespace kdspace::cli {

BoxBuildMethod build_method(const std::string& name) {
  if (name == "median") return BoxBuildMethod::median;
  if (name == "sah") return BoxBuildMethod::sah;
  if (name == "binned") return BoxBuildMethod::binned;
  return BoxBuildMethod::sah_nlogn;
}

void check_output_folder(const std::string& path) {
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!folder.empty() && !std::filesystem::is_directory(folder, ec))
    throw Error(path + ": cannot open for writing: no folder " + folder.string());
}

std::vector<Box3f> read_boxes_with_progress(const std::string& path) {
  Progress progress("reading " + path, Progress::Kind::elapsed);
  return io::read_boxes(path);
}

BoxTree build_with_progress(const std::vector<Box3f>& boxes, const BoxBuildParams& params, double& seconds) {
  Progress progress("building the tree", Progress::Kind::elapsed);
  const auto start = std::chrono::steady_clock::now();
  BoxTree tree(boxes, params);
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return tree;
}

}  // namespace kdspace::cli
