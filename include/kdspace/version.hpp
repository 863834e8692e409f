#pragma once

#define KDSPACE_VERSION_MAJOR 0
#define KDSPACE_VERSION_MINOR 1
#define KDSPACE_VERSION_PATCH 0

namespace kdspace {
inline constexpr const char* version = "0.1.0";
}
