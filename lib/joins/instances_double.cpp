// Compiles the joins of the common double PointTree types once, so programs that link kdspace
// do not (the list: KDSPACE_JOIN_INSTANCES_DOUBLE in kdspace/joins/joins.hpp).
#include "kdspace/joins/joins.hpp"

namespace kdspace::detail {
KDSPACE_JOIN_INSTANCES_DOUBLE(template)
}  // namespace kdspace::detail
