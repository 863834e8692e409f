// Compiles the joins of the common PointTree types once, so programs that link kdspace do not.
#include "kdspace/joins/joins.hpp"

namespace kdspace::detail {
KDSPACE_JOIN_INSTANCES(template)
}  // namespace kdspace::detail
