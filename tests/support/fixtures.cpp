#include "fixtures.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

#ifndef MANIP_FIXTURE_DIR
#define MANIP_FIXTURE_DIR "tests/fixtures"
#endif

namespace manip::testutil {

std::string fixture_path(const std::string& relative) { return std::string(MANIP_FIXTURE_DIR) + "/" + relative; }

std::vector<double> read_numbers(const std::string& relative) {
  const std::string path = fixture_path(relative);
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open fixture " + path);
  std::vector<double> out;
  std::string line;
  while (std::getline(in, line)) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::string tok;
    while (ls >> tok) {
      for (auto& c : tok)
        if (c == ',') c = ' ';
      std::istringstream ts(tok);
      double v;
      while (ts >> v) out.push_back(v);
    }
  }
  return out;
}

namespace {
// Every directory temp_dir() made, removed when the test process ends
// normally (a crashed or aborted test leaves its files for the post-mortem;
// MANIP_KEEP_TEST_DIRS=1 keeps them always). Without this each run of the
// suite left ~2 GB of logs in /tmp.
struct TempDirs {
  std::vector<std::filesystem::path> dirs;
  ~TempDirs() {
    const char* keep = std::getenv("MANIP_KEEP_TEST_DIRS");
    if (keep && *keep && std::string(keep) != "0") return;
    std::error_code ec;
    for (const auto& d : dirs) std::filesystem::remove_all(d, ec);
  }
};
TempDirs& temp_dirs() {
  static TempDirs t;
  return t;
}
}  // namespace

std::string temp_dir(const std::string& name) {
  // Per process: ctest -j runs test cases of one executable in parallel processes.
  const auto dir = std::filesystem::temp_directory_path() / ("manip_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  auto& t = temp_dirs();
  if (std::find(t.dirs.begin(), t.dirs.end(), dir) == t.dirs.end()) t.dirs.push_back(dir);
  return dir.string();
}

int run_command(const std::string& command, std::string* output) {
  const std::string out =
      (std::filesystem::temp_directory_path() / ("manip_test_cmd_" + std::to_string(::getpid()) + ".txt")).string();
  const int st = std::system((command + " >" + out + " 2>&1").c_str());
  if (output) {
    std::ifstream in(out);
    std::ostringstream os;
    os << in.rdbuf();
    *output = os.str();
  }
  std::filesystem::remove(out);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

}  // namespace manip::testutil
