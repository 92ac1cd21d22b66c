// What a person is told when a command line is wrong, for every vdyn program: an unknown option
// or command is named with the nearest one ("unknown option '--wrold'; did you mean '--world'?"),
// an option given to the wrong command says where it belongs, and a list option with an empty
// entry ("--vehicle-ids 1,,2", which CLI11 would read as 1,2) is refused with the reason.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

namespace vdyn::cli {

// Damerau-Levenshtein distance (optimal string alignment): insertions, deletions, substitutions
// and swaps of neighbours count one each ("wrold" -> "world" is 1). ASCII case is ignored.
int EditDistance(std::string_view a, std::string_view b);

// The names in `names` nearest to `typed`, best first, at most three: those within an edit
// distance that grows with the length (0 up to 2 letters, 1 for 3, 2 up to 6, else 3), or that
// `typed` (3 letters or more) begins. Leading dashes are ignored. Empty when nothing is close.
std::vector<std::string> Nearest(std::string_view typed, const std::vector<std::string>& names);

// Checks the text of every list option (an option with a delimiter, in `app` and its commands)
// in `args` (argv without the program): "" when each list is well formed, else the reason, e.g.
// "--vehicle-ids '1,,2': entry 2 of the list is empty (write a list as 1,2)".
std::string CheckLists(const CLI::App& app, const std::vector<std::string>& args);

// The message for a failed parse of `args` (argv without the program) by `app`, one problem per
// line, each beginning with `program`, and a last line pointing at the right --help. The caller
// prints it; the exit code is 2.
std::string Explain(const CLI::App& app, const CLI::ParseError& e, const std::string& program,
                    const std::vector<std::string>& args);

}  // namespace vdyn::cli
