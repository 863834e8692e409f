// Compiles the joins of the common float PointTree types once, so programs that link kdspace
// do not (the list: KDSPACE_JOIN_INSTANCES_FLOAT in kdspace/joins/joins.hpp).
#include "kdspace/joins/joins.hpp"

namespace kdspace::detail {
KDSPACE_JOIN_INSTANCES_FLOAT(template)
}  // namespace kdspace::detail
