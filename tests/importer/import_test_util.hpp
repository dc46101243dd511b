#pragma once
// Helpers of the importer tests: writing MAT files with matio's own writer
// (the reader under test is matio's reader plus our conversion; the writer is
// the independent side, as MATLAB would be) and small text files.
#include <matio.h>

#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace manip::test_import {

// A numeric matrix to write: rows x cols, column-major (MATLAB's layout).
struct MatVar {
  std::string name;
  std::size_t rows{0}, cols{0};
  std::vector<double> data;
};

inline matvar_t* make_double(const MatVar& v) {
  std::size_t dims[2] = {v.rows, v.cols};
  // opt 0: matio copies the data, and Mat_VarFree frees its copy.
  matvar_t* m = Mat_VarCreate(v.name.c_str(), MAT_C_DOUBLE, MAT_T_DOUBLE, 2, dims,
                              const_cast<double*>(v.data.data()), 0);
  if (!m) throw std::runtime_error("Mat_VarCreate failed for " + v.name);
  return m;
}

// Writes top-level variables, and optionally one 1x1 struct holding `fields`.
inline void write_mat(const std::string& path, mat_ft version, const std::vector<MatVar>& vars,
                      const std::string& struct_name = "", const std::vector<MatVar>& fields = {}) {
  std::remove(path.c_str());
  mat_t* mat = Mat_CreateVer(path.c_str(), nullptr, version);
  if (!mat) throw std::runtime_error("Mat_CreateVer failed for " + path);
  for (const auto& v : vars) {
    matvar_t* m = make_double(v);
    const int rc = Mat_VarWrite(mat, m, MAT_COMPRESSION_NONE);
    Mat_VarFree(m);
    if (rc != 0) throw std::runtime_error("Mat_VarWrite failed for " + v.name);
  }
  if (!struct_name.empty()) {
    std::vector<const char*> names;
    for (const auto& f : fields) names.push_back(f.name.c_str());
    names.push_back(nullptr);
    std::size_t dims[2] = {1, 1};
    matvar_t* s = Mat_VarCreateStruct2(struct_name.c_str(), 2, dims, names.data());
    if (!s) throw std::runtime_error("Mat_VarCreateStruct2 failed");
    for (const auto& f : fields) Mat_VarSetStructFieldByName(s, f.name.c_str(), 0, make_double(f));
    const int rc = Mat_VarWrite(mat, s, MAT_COMPRESSION_NONE);
    Mat_VarFree(s);
    if (rc != 0) throw std::runtime_error("Mat_VarWrite failed for struct " + struct_name);
  }
  Mat_Close(mat);
}

inline void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  if (!f) throw std::runtime_error("cannot write " + path);
}

}  // namespace manip::test_import
