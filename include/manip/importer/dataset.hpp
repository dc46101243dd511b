#pragma once
// A recording made with another rig, as named numeric matrices: the variables
// of a MAT file (v5 or v7.3, read with Debian's libmatio; fields of 1x1
// structs appear as "struct.field", recursively) or the columns of a CSV file
// with a header line (each column an N x 1 variable). Everything is converted
// to double once; the mapping (mapping.hpp) then says which variable is what.
#include <cstddef>
#include <map>
#include <string>
#include <vector>

namespace manip::importer {

struct Variable {
  std::string name;
  std::size_t rows{0}, cols{0};
  std::vector<double> data;  // column-major (MATLAB's layout): element (r, c) at data[c * rows + r]
  [[nodiscard]] double at(std::size_t r, std::size_t c) const { return data[c * rows + r]; }
  [[nodiscard]] std::size_t numel() const { return data.size(); }
  [[nodiscard]] std::string dims() const { return std::to_string(rows) + " x " + std::to_string(cols); }
};

struct Dataset {
  std::string path;
  std::string format;  // "CSV", "MAT v5", "MAT v7.3"
  std::map<std::string, Variable> variables;
  std::vector<std::string> order;  // names as they appear in the file (for messages)
  // Variables present but not numeric matrices (cell, char, sparse, complex,
  // struct arrays, N-d): name -> what they are, so a mapping that names one
  // is told why it cannot be used rather than "not found".
  std::map<std::string, std::string> unusable;

  [[nodiscard]] const Variable* find(const std::string& name) const;
  // "a, b, c" (first 30 names, in file order) for messages.
  [[nodiscard]] std::string names() const;
};

// By extension (.mat, .csv, case-insensitive). Throws manip::InputError naming
// the file (and for CSV the line and column) if it cannot be read.
Dataset read_dataset(const std::string& path);
Dataset read_csv(const std::string& path);
Dataset read_mat(const std::string& path);

}  // namespace manip::importer
