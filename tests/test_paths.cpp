// The build-specific paths of test_support.h. The only test source compiled with them (tests/CMakeLists.txt): the
// other objects do not depend on where the checkout lives, so ccache shares them between clones.
#include <cstdlib>
#include <filesystem>
#include <string>

#include "test_support.h"

namespace lidef::test {

std::string shared_data() {
  if (const char* env = std::getenv("LIDEF_SHARED_DATA")) return env;
  const std::string d = LIDEF_SHARED_DATA_DIR;
  return std::filesystem::is_directory(d) ? d : std::string();
}
std::string project_data() { return LIDEF_DATA_DIR; }
std::string cli() { return LIDEF_CLI; }

}  // namespace lidef::test
