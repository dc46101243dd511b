#include "manip/estimation/report/render.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <system_error>

#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"

extern char** environ;

namespace manip::estimation {
namespace {

namespace fs = std::filesystem;

std::string env_or(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : fallback;
}

// <build> = the directory two levels above the running tool (<build>/apps/x),
// if it holds a CMakeCache.txt; <source> is then read from that cache.
struct Trees {
  std::string source, build;
};

Trees trees() {
  Trees t;
  t.source = env_or("MANIP_SOURCE_DIR", "");
  t.build = env_or("MANIP_BUILD_DIR", "");
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    for (fs::path d = exe.parent_path(); !d.empty() && d != d.root_path(); d = d.parent_path()) {
      if (fs::exists(d / "CMakeCache.txt", ec)) {
        if (t.build.empty()) t.build = d.string();
        if (t.source.empty()) {
          std::ifstream in(d / "CMakeCache.txt");
          for (std::string line; std::getline(in, line);)
            if (line.rfind("CMAKE_HOME_DIRECTORY:INTERNAL=", 0) == 0) t.source = line.substr(line.find('=') + 1);
        }
        break;
      }
    }
  }
  return t;
}

struct Child {
  int exit_code{-1};  // -1: could not start or killed by a signal
  std::string err;    // stderr (and the spawn error)
};

// Runs argv with the manipplot environment; stdout discarded, stderr captured.
Child run(const std::vector<std::string>& argv) {
  Child c;
  const Trees t = trees();
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e) {
    const std::string kv = *e;
    if (kv.rfind("PYTHONPATH=", 0) == 0 || kv.rfind("MPLBACKEND=", 0) == 0) continue;
    env.push_back(kv);
  }
  std::string pp = "PYTHONPATH=" + (t.source.empty() ? std::string() : t.source + "/python") +
                   (t.build.empty() ? std::string() : ":" + t.build + "/python");
  if (const char* old = std::getenv("PYTHONPATH"); old && *old) pp += std::string(":") + old;
  env.push_back(pp);
  env.push_back("MPLBACKEND=Agg");
  std::vector<char*> av, ev;
  for (const auto& a : argv) av.push_back(const_cast<char*>(a.c_str()));
  av.push_back(nullptr);
  for (const auto& e : env) ev.push_back(const_cast<char*>(e.c_str()));
  ev.push_back(nullptr);
  int pipefd[2];
  if (::pipe2(pipefd, O_CLOEXEC) != 0) {
    c.err = std::string("pipe: ") + std::strerror(errno);
    return c;
  }
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, pipefd[1], 2);
  pid_t pid = 0;
  const int rc = ::posix_spawnp(&pid, av[0], &fa, nullptr, av.data(), ev.data());
  posix_spawn_file_actions_destroy(&fa);
  ::close(pipefd[1]);
  if (rc != 0) {
    ::close(pipefd[0]);
    c.err = argv[0] + ": cannot run (" + std::strerror(rc) + ")";
    return c;
  }
  char buf[4096];
  for (ssize_t n; (n = ::read(pipefd[0], buf, sizeof buf)) != 0;) {
    if (n < 0) {
      if (errno == EINTR) continue;
      break;
    }
    c.err.append(buf, static_cast<std::size_t>(n));
  }
  ::close(pipefd[0]);
  int st = 0;
  while (::waitpid(pid, &st, 0) < 0 && errno == EINTR) {
  }
  c.exit_code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return c;
}

std::vector<std::string> lines(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  for (std::string l; std::getline(in, l);)
    if (!l.empty()) out.push_back(l);
  return out;
}

// The last non-empty line of a Python traceback is the error itself.
std::string last_line(const std::string& s) {
  const auto ls = lines(s);
  return ls.empty() ? std::string("no message") : ls.back();
}

void require_python(const std::string& what) {
  const std::string why = python_unavailable_reason();
  if (!why.empty()) throw manip::OutputError(what + ": not written: " + why);
}

void add_inputs(std::vector<std::string>& a, const RenderInputs& in) {
  if (!in.signals_dir.empty()) a.insert(a.end(), {"--signals", in.signals_dir});
  if (!in.log.empty()) a.insert(a.end(), {"--log", in.log});
  if (!in.validation_json.empty()) a.insert(a.end(), {"--validation", in.validation_json});
}

RenderResult finish(const Child& c, const std::string& module, const std::string& what) {
  if (c.exit_code == 0 || c.exit_code == 1) return {c.exit_code, lines(c.err)};
  throw manip::OutputError(what + ": not written: " + module + " failed (exit " + std::to_string(c.exit_code) +
                           "): " + last_line(c.err));
}

}  // namespace

std::string python_interpreter() {
  if (const char* v = std::getenv("MANIP_PYTHON"); v && *v) return v;
  const Trees t = trees();
  std::error_code ec;
  if (!t.source.empty() && fs::exists(t.source + "/.venv/bin/python", ec)) return t.source + "/.venv/bin/python";
  return "python3";
}

std::string python_unavailable_reason() {
  const std::string py = python_interpreter();
  const Child c = run({py, "-c", "import numpy, matplotlib, manipplot.plots, manipplot.report"});
  if (c.exit_code == 0) return {};
  if (c.exit_code < 0 || c.err.find("cannot run") != std::string::npos)
    return "Python interpreter '" + py + "' cannot be run (set MANIP_PYTHON or run scripts/setup.sh)";
  return "Python '" + py + "' cannot import the plotting package (" + last_line(c.err) +
         "; needs python3-matplotlib and python/manipplot: set MANIP_PYTHON or run scripts/setup.sh)";
}

RenderResult render_plots(const RenderInputs& in, const std::string& out_dir, bool force) {
  std::vector<std::string> args{in.results_json};
  add_inputs(args, in);
  return render_module_into("manipplot.plots", args, "png,pdf,svg", out_dir, force);
}

RenderResult render_module_into(const std::string& module, const std::vector<std::string>& args, const std::string& formats,
                                const std::string& out_dir, bool force) {
  const std::string what = "--plots " + out_dir;
  require_python(what);
  // Drawn into a fresh sibling directory; the files are moved into out_dir
  // only when manipplot succeeded and none would replace an existing file
  // (unless force), so a failure leaves out_dir as it was.
  std::error_code ec;
  const fs::path target = fs::absolute(out_dir, ec);
  fs::create_directories(target, ec);
  if (ec) throw manip::OutputError(out_dir + ": cannot create directory (" + ec.message() + ")");
  std::mt19937_64 rng(std::random_device{}());
  const fs::path tmp = target.parent_path() /
                       ("." + target.filename().string() + ".partial-" + std::to_string(rng() % 1000000000));
  fs::create_directory(tmp, ec);
  if (ec) throw manip::OutputError(tmp.string() + ": cannot create directory (" + ec.message() + ")");
  struct Cleanup {
    fs::path p;
    ~Cleanup() {
      std::error_code e;
      fs::remove_all(p, e);
    }
  } cleanup{tmp};
  std::vector<std::string> a{python_interpreter(), "-m", module};
  a.insert(a.end(), args.begin(), args.end());
  a.insert(a.end(), {"-o", tmp.string(), "--format", formats});
  RenderResult r = finish(run(a), module, what);
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(tmp, ec))
    if (e.is_regular_file()) files.push_back(fs::relative(e.path(), tmp));
  if (!force)
    for (const auto& f : files)
      if (fs::exists(target / f, ec))
        throw manip::OutputError((target / f).string() + ": exists (pass --force to overwrite it)");
  for (const auto& f : files) {
    fs::create_directories((target / f).parent_path(), ec);
    fs::rename(tmp / f, target / f, ec);
    if (ec) throw manip::OutputError((target / f).string() + ": cannot move into place (" + ec.message() + ")");
  }
  return r;
}

RenderResult render_report(const std::vector<std::string>& results_json, const RenderInputs& extra,
                           const std::string& html_path, bool force) {
  const std::string what = "--report " + html_path;
  AtomicOutput out(html_path, force);  // refuses an existing file without force, before any work
  require_python(what);
  std::vector<std::string> a{python_interpreter(), "-m", "manipplot.report"};
  a.insert(a.end(), results_json.begin(), results_json.end());
  add_inputs(a, extra);
  // manipplot writes the temporary (its own write-then-rename lands on the
  // same name); commit() renames it onto the target.
  a.insert(a.end(), {"-o", out.temp_path()});
  RenderResult r = finish(run(a), "manipplot.report", what);
  out.commit();
  return r;
}

}  // namespace manip::estimation

#include "manip/estimation/report/json.hpp"
#include "manip/estimation/report/signals.hpp"
#include "manip/version.hpp"

namespace manip::estimation {

RenderResult write_plots(const Report& r, const std::string& log, const std::string& dir, bool force) {
  std::error_code ec;
  std::mt19937_64 rng(std::random_device{}());
  const fs::path tmp = fs::temp_directory_path(ec) / ("manip_plots_" + std::to_string(rng() % 1000000000));
  fs::create_directories(tmp / "signals", ec);
  if (ec) throw manip::OutputError(tmp.string() + ": cannot create a temporary directory (" + ec.message() + ")");
  struct Cleanup {
    fs::path p;
    ~Cleanup() {
      std::error_code e;
      fs::remove_all(p, e);
    }
  } cleanup{tmp};
  nlohmann::json all = {{"manip_version", manip::kVersion},
                        {"default_method", default_method()},
                        {"settings", settings_to_json(r.settings)},
                        {"sessions", nlohmann::json::array({to_json(r, log)})}};
  const std::string results = (tmp / "results.json").string();
  write_file_atomically(results, all.dump(1) + "\n", true);
  RenderInputs in{results, "", log, ""};
  if (!r.windows.empty()) {
    export_signals(r, (tmp / "signals").string());
    in.signals_dir = (tmp / "signals").string();
  }
  if (fs::exists(fs::path(dir) / "validation.json", ec)) in.validation_json = (fs::path(dir) / "validation.json").string();
  return render_plots(in, dir, force);
}

// As the SVG writer did: manip_sim owns its --validate directory and decides
// there what may be replaced, so the figures in it are redrawn.
void write_plots(const Report& r, const std::string& dir) { write_plots(r, "", dir, true); }

}  // namespace manip::estimation
