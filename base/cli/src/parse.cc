#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "vdyn/base/text.h"
#include "vdyn/cli/errors.h"
#include "vdyn/cli/options.h"

namespace vdyn::cli {
namespace {

// CLI11 reads whole numbers with strtoll's base 0: "010" would be 8 and "1e3" no number. Every
// whole-number option of every program reads them as a person writes them instead: in decimal,
// "1e3" as 1000, "1.5" refused, and no minus for an unsigned one.
constexpr const char* kWholeNumber = "vdyn whole number";

void WholeNumbersAsWritten(CLI::App& app) {
  for (CLI::Option* o : app.get_options()) {
    if (o->get_items_expected_max() == 0) continue;  // a flag
    const std::string type = o->get_type_name();
    const bool is_unsigned = type.rfind("UINT", 0) == 0;
    if (!is_unsigned && type.rfind("INT", 0) != 0) continue;
    // After the option's own checks (which leave the text alone), and allowed to change the text:
    // its decimal form is what CLI11 converts.
    o->check(CLI::Validator(
                 [is_unsigned](std::string& text) -> std::string {
                   const auto v = base::ParseNumber(text);
                   const std::string quoted = "'" + base::Quote(text, 40) + "'";
                   if (!v) return quoted + " is not a number";
                   if (*v != std::trunc(*v)) return quoted + " is not a whole number";
                   if (is_unsigned && *v < 0) return quoted + " is not a whole number, 0 or more";
                   if (std::abs(*v) >= 0x1p63) return quoted + " is too large";
                   text = std::to_string(static_cast<long long>(*v));
                   return {};
                 },
                 ""),
             kWholeNumber);
    o->get_validator(kWholeNumber)->non_modifying(false);
  }
  for (CLI::App* s : app.get_subcommands([](CLI::App*) { return true; })) WholeNumbersAsWritten(*s);
}

}  // namespace

int Parse(CLI::App& app, int argc, char** argv, std::ostream& err) {
  const std::string program = argc > 0 && argv[0] != nullptr
                                  ? std::filesystem::path(argv[0]).filename().string()
                                  : app.get_name();
  const std::vector<std::string> args(argv + (argc > 0 ? 1 : 0), argv + argc);
  // Before CLI11 splits the lists (it drops empty entries without a word).
  if (const std::string why = CheckLists(app, args); !why.empty()) {
    err << program << ": " << why << "\nRun '" << program << " --help' for more information.\n";
    return 2;
  }
  WholeNumbersAsWritten(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    err << Explain(app, e, program, args) << std::flush;
    return 2;
  }
  return -1;
}

}  // namespace vdyn::cli
