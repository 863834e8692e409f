// Fuzz target of one scene file reader (kdspace/io/scene.hpp): .boxes, .rays or .hits, chosen at
// build time by KDSPACE_FUZZ_EXTENSION. What is read must be what the reader promises: valid boxes,
// usable rays, box indices >= -1.
#include <cstdint>
#include <cstdlib>

#include "fuzz_file.hpp"
#include "kdspace/io/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string extension = KDSPACE_FUZZ_EXTENSION;
  kdspace_fuzz::with_file(data, size, extension, [&](const std::string& path) {
    if (extension == ".boxes") {
      for (const kdspace::Box3f& b : kdspace::io::read_boxes(path))
        if (!kdspace::box_problem(b).empty()) std::abort();
    } else if (extension == ".rays") {
      for (const kdspace::Ray& r : kdspace::io::read_rays(path))
        if (!kdspace::ray_problem(r).empty()) std::abort();
    } else {
      for (const kdspace::Hit& h : kdspace::io::read_hits(path))
        if (h.box < -1) std::abort();
    }
  });
  return 0;
}
