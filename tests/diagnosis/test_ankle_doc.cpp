// docs/diagnosis-ankle.md quotes diagnose_model's full reports on the two
// measured ankle records (issue 11's required report): they must be what the
// tool prints today, or the document describes a tool that no longer exists.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/common/exit_codes.hpp"

namespace {

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream is(text);
  for (std::string l; std::getline(is, l);) out.push_back(l);
  return out;
}

// The fenced block after "### <record>", without its first line (the input's
// path, as the reader typed it) and the timing line.
std::vector<std::string> comparable(std::vector<std::string> lines) {
  std::vector<std::string> out;
  for (std::size_t i = 1; i < lines.size(); ++i)
    if (lines[i].rfind("diagnosis took ", 0) != 0) out.push_back(lines[i]);
  return out;
}

std::vector<std::string> quoted_report(const std::vector<std::string>& doc, const std::string& record) {
  std::size_t i = 0;
  while (i < doc.size() && doc[i] != "### " + record) ++i;
  while (i < doc.size() && doc[i] != "```") ++i;
  std::vector<std::string> out;
  for (++i; i < doc.size() && doc[i] != "```"; ++i) out.push_back(doc[i]);
  return out;
}

}  // namespace

TEST_CASE("docs/diagnosis-ankle.md: the full reports are what diagnose_model --single-joint prints on the two ankle records") {
  const std::filesystem::path data = std::filesystem::path(MANIP_SOURCE_DIR) / ".." / "shared" / "data" / "ankle-reklab";
  if (!std::filesystem::exists(data)) {
    WARN("no " << data.string() << " beside the repository: the quoted reports are not checked");
    return;
  }
  std::ifstream df(std::string(MANIP_SOURCE_DIR) + "/docs/diagnosis-ankle.md");
  REQUIRE(df);
  std::stringstream ss;
  ss << df.rdbuf();
  const auto doc = lines_of(ss.str());
  for (const std::string r : {"z_pf2", "z_df3"}) {
    const auto quoted = quoted_report(doc, r);
    REQUIRE(quoted.size() > 40);
    std::string out;
    const int rc = manip::testutil::run_command(std::string(MANIP_BINARY_DIR) + "/apps/diagnose_model -q --single-joint " +
                                                    (data / ("experimental_data__" + r + ".csv")).string(),
                                                &out);
    REQUIRE(rc == manip::exit_code::kOk);
    const auto want = comparable(quoted), got = comparable(lines_of(out));
    INFO(r << ": regenerate the block in docs/diagnosis-ankle.md with the command at its top");
    for (std::size_t i = 0; i < std::min(want.size(), got.size()); ++i) {
      INFO("line " << i + 2 << " of the report");
      REQUIRE(got[i] == want[i]);
    }
    CHECK(got.size() == want.size());
  }
}
