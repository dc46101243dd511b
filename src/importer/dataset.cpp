#include "manip/importer/dataset.hpp"

#include <matio.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <sstream>

#include "manip/common/errors.hpp"

namespace manip::importer {

const Variable* Dataset::find(const std::string& name) const {
  const auto it = variables.find(name);
  return it == variables.end() ? nullptr : &it->second;
}

std::string Dataset::names() const {
  std::string s;
  int n = 0;
  for (const auto& k : order) {
    if (!variables.count(k)) continue;
    if (n++ == 30) return s + ", ...";
    s += (s.empty() ? "" : ", ") + k;
  }
  return s.empty() ? std::string("no numeric variables") : s;
}

namespace {

std::string lower_ext(const std::string& path) {
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) return "";
  std::string e = path.substr(dot + 1);
  for (auto& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

// ---------------------------------------------------------------- CSV

std::string trim(std::string_view s) {
  std::size_t b = 0, e = s.size();
  while (b < e && (s[b] == ' ' || s[b] == '\t' || s[b] == '\r')) ++b;
  while (e > b && (s[e - 1] == ' ' || s[e - 1] == '\t' || s[e - 1] == '\r')) --e;
  std::string t(s.substr(b, e - b));
  if (t.size() >= 2 && t.front() == '"' && t.back() == '"') t = t.substr(1, t.size() - 2);
  return t;
}

std::vector<std::string_view> split(std::string_view line, char sep) {
  std::vector<std::string_view> out;
  std::size_t b = 0;
  for (std::size_t i = 0; i <= line.size(); ++i) {
    if (i == line.size() || line[i] == sep) {
      out.push_back(line.substr(b, i - b));
      b = i + 1;
    }
  }
  return out;
}

// Empty cells and NaN spellings (MATLAB writes "NaN", pandas "nan" or "")
// are NaN: a recording may leave a channel empty outside trials.
bool parse_cell(std::string_view cell, double& v) {
  std::size_t b = 0, e = cell.size();
  while (b < e && (cell[b] == ' ' || cell[b] == '\t' || cell[b] == '\r')) ++b;
  while (e > b && (cell[e - 1] == ' ' || cell[e - 1] == '\t' || cell[e - 1] == '\r')) --e;
  cell = cell.substr(b, e - b);
  if (cell.empty() || cell == "NaN" || cell == "nan" || cell == "NAN" || cell == "NA") {
    v = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  if (cell.front() == '+') cell.remove_prefix(1);
  const auto r = std::from_chars(cell.data(), cell.data() + cell.size(), v);
  return r.ec == std::errc() && r.ptr == cell.data() + cell.size();
}

}  // namespace

Dataset read_csv(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open the file (" + std::strerror(errno) + ")");
  Dataset ds;
  ds.path = path;
  ds.format = "CSV";
  std::string line;
  long lineno = 0;
  std::vector<std::string> header;
  std::vector<std::vector<double>> cols;
  char sep = ',';
  while (std::getline(f, line)) {
    ++lineno;
    if (lineno == 1 && line.size() >= 3 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);  // UTF-8 BOM
    if (trim(line).empty() || line[0] == '#') continue;
    if (header.empty()) {
      // Comma unless the header has none and has semicolons or tabs (European
      // spreadsheets write ';').
      if (line.find(',') == std::string::npos) {
        if (line.find(';') != std::string::npos) sep = ';';
        else if (line.find('\t') != std::string::npos) sep = '\t';
      }
      for (const auto& h : split(line, sep)) header.push_back(trim(h));
      for (std::size_t i = 0; i < header.size(); ++i) {
        if (header[i].empty())
          throw InputError(path + ":" + std::to_string(lineno) + ": header: column " + std::to_string(i + 1) +
                           " has no name (the first line must name every column)");
        for (std::size_t j = 0; j < i; ++j)
          if (header[j] == header[i])
            throw InputError(path + ":" + std::to_string(lineno) + ": header: column name '" + header[i] +
                             "' appears twice (columns " + std::to_string(j + 1) + " and " + std::to_string(i + 1) +
                             ")");
      }
      cols.resize(header.size());
      continue;
    }
    const auto cells = split(line, sep);
    if (cells.size() != header.size())
      throw InputError(path + ":" + std::to_string(lineno) + ": expected " + std::to_string(header.size()) +
                       " fields (as in the header), found " + std::to_string(cells.size()));
    for (std::size_t i = 0; i < cells.size(); ++i) {
      double v{};
      if (!parse_cell(cells[i], v))
        throw InputError(path + ":" + std::to_string(lineno) + ": column '" + header[i] + "': not a number ('" +
                         trim(cells[i]) + "')");
      cols[i].push_back(v);
    }
  }
  if (f.bad()) throw InputError(path + ": read error");
  if (header.empty()) throw InputError(path + ": empty file (expected a header line naming the columns)");
  for (std::size_t i = 0; i < header.size(); ++i) {
    Variable v;
    v.name = header[i];
    v.rows = cols[i].size();
    v.cols = 1;
    v.data = std::move(cols[i]);
    ds.order.push_back(v.name);
    ds.variables.emplace(v.name, std::move(v));
  }
  return ds;
}

// ---------------------------------------------------------------- MAT

namespace {

// matio reports problems through a global log hook (by default to stderr);
// keep the last message so our error can carry it, and stay quiet otherwise.
std::mutex g_matio_mutex;
std::string g_matio_last;
void matio_log(int /*level*/, char* message) { g_matio_last = message ? message : ""; }

struct MatCloser {
  void operator()(mat_t* m) const { Mat_Close(m); }
};
struct VarFree {
  void operator()(matvar_t* v) const { Mat_VarFree(v); }
};

const char* class_name(matio_classes c) {
  switch (c) {
    case MAT_C_EMPTY: return "empty";
    case MAT_C_CELL: return "a cell array";
    case MAT_C_STRUCT: return "a struct";
    case MAT_C_OBJECT: return "an object";
    case MAT_C_CHAR: return "a char array";
    case MAT_C_SPARSE: return "a sparse matrix";
    case MAT_C_FUNCTION: return "a function handle";
    case MAT_C_OPAQUE: return "an opaque object (e.g. a table or timeseries; convert it to a numeric matrix)";
    default: return "numeric";
  }
}

template <class T>
void copy_as_double(const void* p, std::size_t n, std::vector<double>& out) {
  const T* t = static_cast<const T*>(p);
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<double>(t[i]);
}

bool to_double(const matvar_t* v, std::size_t n, std::vector<double>& out) {
  if (n == 0) {
    out.clear();
    return true;
  }
  if (!v->data) return false;
  switch (v->data_type) {
    case MAT_T_DOUBLE: copy_as_double<double>(v->data, n, out); return true;
    case MAT_T_SINGLE: copy_as_double<float>(v->data, n, out); return true;
    case MAT_T_INT8: copy_as_double<std::int8_t>(v->data, n, out); return true;
    case MAT_T_UINT8: copy_as_double<std::uint8_t>(v->data, n, out); return true;
    case MAT_T_INT16: copy_as_double<std::int16_t>(v->data, n, out); return true;
    case MAT_T_UINT16: copy_as_double<std::uint16_t>(v->data, n, out); return true;
    case MAT_T_INT32: copy_as_double<std::int32_t>(v->data, n, out); return true;
    case MAT_T_UINT32: copy_as_double<std::uint32_t>(v->data, n, out); return true;
    case MAT_T_INT64: copy_as_double<std::int64_t>(v->data, n, out); return true;
    case MAT_T_UINT64: copy_as_double<std::uint64_t>(v->data, n, out); return true;
    default: return false;
  }
}

void add_variable(Dataset& ds, const std::string& name, matvar_t* v, int depth) {
  if (v == nullptr) {
    ds.unusable[name] = "unreadable";
    return;
  }
  if (v->class_type == MAT_C_STRUCT) {
    std::size_t numel = 1;
    for (int i = 0; i < v->rank; ++i) numel *= v->dims[i];
    if (numel != 1) {
      ds.unusable[name] = "a struct array (" + std::to_string(numel) + " elements; only 1x1 structs are read)";
      return;
    }
    if (depth > 8) {
      ds.unusable[name] = "a struct nested too deeply";
      return;
    }
    const unsigned nf = Mat_VarGetNumberOfFields(v);
    char* const* fields = Mat_VarGetStructFieldnames(v);
    for (unsigned i = 0; i < nf && fields; ++i) {
      if (!fields[i]) continue;
      add_variable(ds, name + "." + fields[i], Mat_VarGetStructFieldByName(v, fields[i], 0), depth + 1);
    }
    return;
  }
  const char* cls = class_name(v->class_type);
  if (std::strcmp(cls, "numeric") != 0) {
    ds.unusable[name] = cls;
    return;
  }
  if (v->isComplex) {
    ds.unusable[name] = "complex";
    return;
  }
  if (v->rank != 2) {
    ds.unusable[name] = "an " + std::to_string(v->rank) + "-d array (expected a 2-d matrix)";
    return;
  }
  Variable out;
  out.name = name;
  out.rows = v->dims[0];
  out.cols = v->dims[1];
  if (!to_double(v, out.rows * out.cols, out.data)) {
    ds.unusable[name] = "numeric of a type that cannot be read";
    return;
  }
  ds.order.push_back(name);
  ds.variables.emplace(name, std::move(out));
}

}  // namespace

Dataset read_mat(const std::string& path) {
  std::lock_guard<std::mutex> lock(g_matio_mutex);  // matio's log hook is global
  Mat_LogInitFunc("manip_import", matio_log);
  g_matio_last.clear();
  std::unique_ptr<mat_t, MatCloser> mat(Mat_Open(path.c_str(), MAT_ACC_RDONLY));
  if (!mat) {
    std::ifstream probe(path);
    if (!probe) throw InputError(path + ": cannot open the file (" + std::strerror(errno) + ")");
    throw InputError(path + ": not a MAT file matio can read (v5 or v7.3 expected)" +
                     (g_matio_last.empty() ? std::string() : ": " + g_matio_last));
  }
  Dataset ds;
  ds.path = path;
  switch (Mat_GetVersion(mat.get())) {
    case MAT_FT_MAT73: ds.format = "MAT v7.3"; break;
    case MAT_FT_MAT5: ds.format = "MAT v5"; break;
    case MAT_FT_MAT4: ds.format = "MAT v4"; break;
    default: ds.format = "MAT";
  }
  // Names first (info only), then each variable read whole by name.
  std::vector<std::string> names;
  Mat_Rewind(mat.get());
  while (matvar_t* info = Mat_VarReadNextInfo(mat.get())) {
    if (info->name) names.emplace_back(info->name);
    Mat_VarFree(info);
  }
  for (const auto& n : names) {
    std::unique_ptr<matvar_t, VarFree> v(Mat_VarRead(mat.get(), n.c_str()));
    add_variable(ds, n, v.get(), 0);
  }
  if (ds.variables.empty() && ds.unusable.empty())
    throw InputError(path + ": " + ds.format + " file without any variable" +
                     (g_matio_last.empty() ? std::string() : " (" + g_matio_last + ")"));
  return ds;
}

Dataset read_dataset(const std::string& path) {
  const std::string e = lower_ext(path);
  if (e == "mat") return read_mat(path);
  if (e == "csv" || e == "txt") return read_csv(path);
  throw InputError(path + ": unknown input type '." + e + "' (expected .mat or .csv)");
}

}  // namespace manip::importer
