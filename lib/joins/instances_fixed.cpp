// Compiles the joins of the common fixed-dimension (2-D, 3-D) PointTree types once, so programs
// that link kdspace do not (the list: KDSPACE_JOIN_INSTANCES_FIXED in kdspace/joins/joins.hpp).
#include "kdspace/joins/joins.hpp"

namespace kdspace::detail {
KDSPACE_JOIN_INSTANCES_FIXED(template)
}  // namespace kdspace::detail
