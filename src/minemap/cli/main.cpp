// The `minemap` program: the command line of cli.hpp. See README.md; exit codes in
// cli/exit_codes.hpp, the bad-input cases in docs/bad-input.md.
#include <string>
#include <vector>

#include "minemap/cli/cli.hpp"

int main(int argc, char** argv) { return minemap::cli::run(std::vector<std::string>(argv + 1, argv + argc)); }
