// Where the tests find the real data beside the clone (../shared/data: the
// city model, the animated glTF, the HDR environment).
#pragma once

#include <filesystem>

namespace vistream::testing {

inline const std::filesystem::path kSharedData =
    std::filesystem::path(VISTREAM_SHARED_DIR) / "data";

}  // namespace vistream::testing
