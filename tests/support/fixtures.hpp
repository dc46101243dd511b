#pragma once
// Reading reference vectors produced by the Python scripts in tests/fixtures/.
// Format: plain text, one number per whitespace-separated token, '#' comments.
#include <string>
#include <vector>

namespace manip::testutil {

std::string fixture_path(const std::string& relative);
// All numbers of a fixture file, in order. Throws std::runtime_error naming the file.
std::vector<double> read_numbers(const std::string& relative);
// A fresh empty directory (per test process, under the system temp dir) for one test's outputs.
std::string temp_dir(const std::string& name);
// Runs a shell command with stdout and stderr captured together into *output
// (if given); returns its exit status, -1 if it did not exit normally.
int run_command(const std::string& command, std::string* output = nullptr);

}  // namespace manip::testutil
