// minemap's version (cli.hpp), from the header cmake/WriteVersion.cmake writes at build time.
#include "minemap/cli/cli.hpp"
#include "minemap/version_info.hpp"

namespace minemap::cli {

const char* version() { return kMinemapVersion; }

}  // namespace minemap::cli
