#include "vdyn/cli/errors.h"

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <cstdio>
#include <utility>

#include "vdyn/base/text.h"

namespace vdyn::cli {
namespace {

std::string_view WithoutDashes(std::string_view s) {
  while (!s.empty() && s.front() == '-') s.remove_prefix(1);
  return s;
}

char Lower(char c) {
  return static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
}

bool StartsWith(std::string_view s, std::string_view prefix) {
  if (prefix.size() > s.size()) return false;
  for (std::size_t i = 0; i < prefix.size(); ++i) {
    if (Lower(s[i]) != Lower(prefix[i])) return false;
  }
  return true;
}

std::string Quoted(std::string_view s) {
  return "'" + base::Quote(s, 60) + "'";
}

// "'a'", "'a' or 'b'", "'a', 'b' or 'c'".
std::string OneOf(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) out += i + 1 == names.size() ? " or " : ", ";
    out += Quoted(names[i]);
  }
  return out;
}

std::string Join(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

std::vector<const CLI::App*> NamedCommands(const CLI::App& app) {
  return app.get_subcommands([](const CLI::App* s) { return !s->get_name().empty(); });
}

std::vector<std::string> CommandNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* s : NamedCommands(app)) names.push_back(s->get_name());
  return names;
}

std::vector<std::string> OptionNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* o : app.get_options()) {
    for (const std::string& l : o->get_lnames()) names.push_back("--" + l);
    for (const std::string& s : o->get_snames()) names.push_back("-" + s);
  }
  return names;
}

// Every app of the tree, the top first.
void AllApps(const CLI::App& app, std::vector<const CLI::App*>& out) {
  out.push_back(&app);
  for (const CLI::App* s : NamedCommands(app)) AllApps(*s, out);
}

// The top app and the commands parsed, outermost first.
std::vector<const CLI::App*> ParsedChain(const CLI::App& app) {
  std::vector<const CLI::App*> chain{&app};
  for (;;) {
    const CLI::App* next = nullptr;
    for (const CLI::App* s : chain.back()->get_subcommands()) {
      if (!s->get_name().empty()) {
        next = s;
        break;
      }
    }
    if (next == nullptr) break;
    chain.push_back(next);
  }
  return chain;
}

// "vdyn-recorder info" for the chain top -> info.
std::string CommandPath(const std::string& program, const std::vector<const CLI::App*>& chain) {
  std::string path = program;
  for (std::size_t i = 1; i < chain.size(); ++i) path += " " + chain[i]->get_name();
  return path;
}

// The options taken where the command line ends up: the last command's own and, while commands
// fall through to their parent, the parent's.
std::vector<std::string> OptionsInScope(const std::vector<const CLI::App*>& chain) {
  std::vector<std::string> names;
  for (std::size_t i = chain.size(); i-- > 0;) {
    const std::vector<std::string> own = OptionNames(*chain[i]);
    names.insert(names.end(), own.begin(), own.end());
    if (!chain[i]->get_fallthrough()) break;
  }
  return names;
}

bool LooksLikeOption(const std::string& arg) {
  return arg.size() > 1 && arg[0] == '-' && !base::ParseNumber(arg).has_value();
}

// The arguments CLI11 could not place, each with its index in `args`, in command-line order.
std::vector<std::pair<std::size_t, std::string>> Unplaced(const std::vector<const CLI::App*>& chain,
                                                          const std::vector<std::string>& args) {
  std::vector<std::string> items;
  for (const CLI::App* a : chain) {
    const std::vector<std::string> r = a->remaining(false);
    items.insert(items.end(), r.begin(), r.end());
    // Unnamed option groups keep their own leftovers.
    for (const CLI::App* g :
         a->get_subcommands([](const CLI::App* s) { return s->get_name().empty(); })) {
      const std::vector<std::string> gr = g->remaining(false);
      items.insert(items.end(), gr.begin(), gr.end());
    }
  }
  std::vector<bool> used(args.size(), false);
  std::vector<std::pair<std::size_t, std::string>> out;
  std::size_t unknown_index = args.size();
  for (const std::string& item : items) {
    if (item == "--") continue;
    std::size_t at = unknown_index++;
    for (std::size_t i = 0; i < args.size(); ++i) {
      if (!used[i] && args[i] == item) {
        used[i] = true;
        at = i;
        break;
      }
    }
    out.emplace_back(at, item);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::string Upper(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](char c) {
    return static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  });
  return s;
}

// "FILE" for a command's positional arguments: what follows the command.
std::vector<std::string> PositionalNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* o : app.get_options()) {
    if (o->get_positional()) names.push_back(Upper(o->get_name(true)));
  }
  return names;
}

const CLI::Option* FindOption(const std::vector<const CLI::App*>& chain, const std::string& name) {
  for (std::size_t i = chain.size(); i-- > 0;) {
    for (const CLI::Option* o : chain[i]->get_options()) {
      if (o->get_name() == name || o->check_name(name)) return o;
    }
  }
  return nullptr;
}

// CLI11's wording of a few errors, as a person says it; "" when `what` is none of them.
std::string Reworded(const std::string& what, const std::vector<const CLI::App*>& chain,
                     const std::string& here) {
  // "Could not convert: --follow = -1": a value that is not of the option's type.
  const std::string convert = "Could not convert: ";
  if (what.rfind(convert, 0) == 0) {
    const std::size_t eq = what.find(" = ", convert.size());
    if (eq == std::string::npos) return {};
    const std::string name = what.substr(convert.size(), eq - convert.size());
    const std::string value = what.substr(eq + 3);
    const CLI::Option* o = FindOption(chain, name);
    const std::string type = o != nullptr ? o->get_type_name() : "";
    const bool whole = type.rfind("UINT", 0) == 0 || type.rfind("INT", 0) == 0;
    const bool digits =
        !value.empty() && value.find_first_not_of("0123456789") == std::string::npos;
    if (whole && digits) return name + ": " + Quoted(value) + " is too large";
    if (type.rfind("UINT", 0) == 0)
      return name + ": " + Quoted(value) + " is not a whole number, 0 or more";
    if (type.rfind("INT", 0) == 0) return name + ": " + Quoted(value) + " is not a whole number";
    if (type.rfind("FLOAT", 0) == 0) return name + ": " + Quoted(value) + " is not a number";
    return name + ": " + Quoted(value) + " is not a valid value";
  }
  // "--spawn: At least 3 required but received 2", "--world: 1 required TEXT missing".
  const std::size_t colon = what.find(": ");
  if (colon != std::string::npos && what.rfind("-", 0) == 0) {
    const std::string name = what.substr(0, colon);
    const std::string rest = what.substr(colon + 2);
    const CLI::Option* o = FindOption(chain, name);
    const std::string list =
        o != nullptr && o->get_delimiter() != '\0'
            ? std::string(" (written as a") + o->get_delimiter() + "b" + o->get_delimiter() + "c)"
            : "";
    unsigned want = 0, got = 0;
    if (std::sscanf(rest.c_str(), "At least %u required but received %u", &want, &got) == 2) {
      return name + " needs " + std::to_string(want) + " values" + list + ", got " +
             std::to_string(got);
    }
    char type[32] = {};
    if (std::sscanf(rest.c_str(), "%u required %31s missing", &want, type) == 2) {
      return want == 1 ? name + " needs a value"
                       : name + " needs " + std::to_string(want) + " values" + list;
    }
    // "--clock: Wall not in {server,wall}" (CLI::IsMember): the choices as a person writes them,
    // and the nearest one.
    const std::size_t set = rest.rfind(" not in {");
    if (set != std::string::npos && rest.back() == '}') {
      const std::string value = rest.substr(0, set);
      const std::string inside = rest.substr(set + 9, rest.size() - set - 10);
      std::vector<std::string> choices;
      for (std::size_t begin = 0;;) {
        const std::size_t end = inside.find(',', begin);
        std::string choice = inside.substr(begin, end == std::string::npos ? end : end - begin);
        choice.erase(0, choice.find_first_not_of(' '));
        if (!choice.empty()) choices.push_back(choice);
        if (end == std::string::npos) break;
        begin = end + 1;
      }
      std::string msg = name + ": " + Quoted(value) + " is not one of " + OneOf(choices);
      const std::vector<std::string> near = Nearest(value, choices);
      if (!near.empty()) msg += "; did you mean " + OneOf(near) + "?";
      return msg;
    }
  }
  // "file is required": a command's argument left out.
  const std::string required = " is required";
  if (what.size() > required.size() &&
      what.compare(what.size() - required.size(), required.size(), required) == 0 &&
      what[0] != '-') {
    const std::string name = what.substr(0, what.size() - required.size());
    std::string usage = here;
    for (const std::string& p : PositionalNames(*chain.back())) usage += " " + p;
    return Upper(name) + " is missing: " + usage;
  }
  return {};
}

std::string UnknownOption(const std::string& arg, const std::vector<const CLI::App*>& chain,
                          const CLI::App& top, const std::string& program) {
  const std::string name = arg.substr(0, arg.find('='));
  const std::string here = CommandPath(program, chain);
  const std::vector<std::string> scope = OptionsInScope(chain);
  // An option of the command given, written before the command.
  if (chain.size() > 1 && std::find(scope.begin(), scope.end(), name) != scope.end()) {
    return "option " + Quoted(name) + " goes after the command: " + here + " ... " + name;
  }
  // The exact name elsewhere: an option of other commands.
  std::vector<const CLI::App*> apps;
  AllApps(top, apps);
  std::vector<std::string> owners;
  for (const CLI::App* a : apps) {
    if (std::find(chain.begin(), chain.end(), a) != chain.end()) continue;
    const std::vector<std::string> names = OptionNames(*a);
    if (std::find(names.begin(), names.end(), name) == names.end()) continue;
    std::string path;
    for (const CLI::App* p = a; p->get_parent() != nullptr; p = p->get_parent()) {
      path = " " + p->get_name() + path;
    }
    owners.push_back(chain.size() == 1 ? a->get_name() : program + path);
  }
  if (!owners.empty()) {
    if (chain.size() == 1) {
      return "option " + Quoted(name) + " belongs to the command" +
             (owners.size() > 1 ? "s " : " ") + OneOf(owners) + ": write it after the command";
    }
    return "option " + Quoted(name) + " is not one of " + Quoted(here) + "; it belongs to " +
           OneOf(owners);
  }
  const std::vector<std::string> near = Nearest(name, scope);
  std::string msg = "unknown option " + Quoted(name);
  if (!near.empty()) msg += "; did you mean " + OneOf(near) + "?";
  return msg;
}

std::string UnexpectedArgument(const std::string& arg, const std::vector<const CLI::App*>& chain,
                               const std::string& program) {
  const CLI::App& ctx = *chain.back();
  const std::string here = CommandPath(program, chain);
  std::string msg = "unexpected argument " + Quoted(arg);
  // "world" for "--world": the dashes forgotten.
  const std::vector<std::string> near = Nearest(arg, OptionsInScope(chain));
  if (!near.empty() && EditDistance(WithoutDashes(near.front()), arg) == 0) {
    return msg + "; did you mean " + Quoted(near.front()) + "?";
  }
  const std::vector<std::string> takes = PositionalNames(ctx);
  if (takes.empty()) return msg + " (" + here + " takes options only)";
  return msg + " (" + here + " takes " + Join(takes) + " and options)";
}

}  // namespace

int EditDistance(std::string_view a, std::string_view b) {
  const std::size_t n = a.size(), m = b.size();
  // d[i][j]: distance between the first i letters of a and the first j of b.
  std::vector<std::vector<int>> d(n + 1, std::vector<int>(m + 1, 0));
  for (std::size_t i = 0; i <= n; ++i) d[i][0] = static_cast<int>(i);
  for (std::size_t j = 0; j <= m; ++j) d[0][j] = static_cast<int>(j);
  for (std::size_t i = 1; i <= n; ++i) {
    for (std::size_t j = 1; j <= m; ++j) {
      const int cost = Lower(a[i - 1]) == Lower(b[j - 1]) ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && Lower(a[i - 1]) == Lower(b[j - 2]) &&
          Lower(a[i - 2]) == Lower(b[j - 1])) {
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    }
  }
  return d[n][m];
}

std::vector<std::string> Nearest(std::string_view typed, const std::vector<std::string>& names) {
  const std::string_view t = WithoutDashes(typed);
  if (t.empty()) return {};
  const int allowed = t.size() <= 2 ? 0 : (t.size() <= 3 ? 1 : (t.size() <= 6 ? 2 : 3));
  std::vector<std::pair<int, std::string>> scored;
  for (const std::string& name : names) {
    const std::string_view n = WithoutDashes(name);
    int score = EditDistance(t, n);
    // A beginning of a longer name ("--lockstep-time") is as near as one letter wrong.
    if (score > allowed && t.size() >= 3 && StartsWith(n, t)) score = allowed;
    if (score > allowed) continue;
    if (std::any_of(scored.begin(), scored.end(),
                    [&](const auto& s) { return s.second == name; })) {
      continue;
    }
    scored.emplace_back(score, name);
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& x, const auto& y) { return x.first < y.first; });
  std::vector<std::string> out;
  for (const auto& [score, name] : scored) {
    if (score > scored.front().first || out.size() == 3) break;
    out.push_back(name);
  }
  return out;
}

std::string CheckLists(const CLI::App& app, const std::vector<std::string>& args) {
  std::vector<const CLI::App*> apps;
  AllApps(app, apps);
  struct ListOption {
    std::string name;
    char delimiter;
  };
  std::vector<ListOption> lists;
  for (const CLI::App* a : apps) {
    for (const CLI::Option* o : a->get_options()) {
      if (o->get_delimiter() == '\0') continue;
      for (const std::string& l : o->get_lnames()) lists.push_back({"--" + l, o->get_delimiter()});
      for (const std::string& s : o->get_snames()) lists.push_back({"-" + s, o->get_delimiter()});
    }
  }
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--") break;
    for (const ListOption& list : lists) {
      std::string value;
      bool next_is_value = false;
      if (args[i] == list.name) {
        if (i + 1 >= args.size()) break;  // CLI11 says the value is missing
        value = args[i + 1];
        next_is_value = true;
      } else if (args[i].rfind(list.name + "=", 0) == 0) {
        value = args[i].substr(list.name.size() + 1);
      } else {
        continue;
      }
      const std::string head = list.name + " " + Quoted(value) + ": ";
      if (value.find_first_not_of(" \t") == std::string::npos) {
        return head + "the list is empty";
      }
      std::size_t entry = 1, begin = 0;
      for (;;) {
        const std::size_t end = value.find(list.delimiter, begin);
        const std::string piece =
            value.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
        if (piece.find_first_not_of(" \t") == std::string::npos) {
          std::string why = head + "entry " + std::to_string(entry) + " of the list is empty";
          const std::size_t after = next_is_value ? i + 2 : i + 1;
          if (end == std::string::npos && after < args.size() && !LooksLikeOption(args[after])) {
            why += " (a space after a comma ends the list: write the list without spaces)";
          }
          return why;
        }
        if (end == std::string::npos) break;
        begin = end + 1;
        ++entry;
      }
      break;
    }
  }
  return {};
}

std::string Explain(const CLI::App& app, const CLI::ParseError& e, const std::string& program,
                    const std::vector<std::string>& args) {
  const std::vector<const CLI::App*> chain = ParsedChain(app);
  const std::string here = CommandPath(program, chain);
  std::vector<std::string> lines;
  const auto unplaced = Unplaced(chain, args);
  std::size_t consumed_value = args.size() + unplaced.size() + 1;  // no index yet
  for (const auto& [at, arg] : unplaced) {
    if (at == consumed_value) continue;
    if (LooksLikeOption(arg)) {
      lines.push_back(UnknownOption(arg, chain, app, program));
      // The word after an unknown option is its value, not a second problem.
      if (arg.find('=') == std::string::npos) consumed_value = at + 1;
      continue;
    }
    if (chain.size() == 1 && !NamedCommands(app).empty()) {
      const std::vector<std::string> commands = CommandNames(app);
      const std::vector<std::string> near = Nearest(arg, commands);
      std::string msg = "unknown command " + Quoted(arg);
      if (!near.empty()) msg += "; did you mean " + OneOf(near) + "?";
      lines.push_back(msg + " (the commands: " + Join(commands) + ")");
      break;  // what follows are that command's arguments
    }
    lines.push_back(UnexpectedArgument(arg, chain, program));
  }
  if (lines.empty()) {
    const auto* required = dynamic_cast<const CLI::RequiredError*>(&e);
    if (required != nullptr && chain.back()->get_require_subcommand_min() > 0 &&
        !NamedCommands(*chain.back()).empty()) {
      lines.push_back("choose a command: " + Join(CommandNames(*chain.back())));
    } else if (const std::string plain = Reworded(e.what(), chain, here); !plain.empty()) {
      lines.push_back(plain);
    } else {
      lines.push_back(e.what());
    }
  }
  std::string out;
  for (const std::string& l : lines) out += here + ": " + l + "\n";
  out += "Run '" + here + " --help' for more information.\n";
  return out;
}

}  // namespace vdyn::cli
