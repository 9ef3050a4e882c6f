// examples/msgs_main.cpp: entry point of the `msgs` tool; dispatches to the registered subcommands.
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "commands.hpp"
#include "msgs/large_page_new.hpp"  // large arrays in large pages (this program's one inclusion)

int main(int argc, char** argv) {
  auto& reg = msgs::cli::registry();
  auto usage = [&](std::FILE* f) {
    std::fprintf(f, "usage: msgs <command> [options]\n\ncommands:\n");
    for (const auto& [name, cmd] : reg) std::fprintf(f, "  %-10s %s\n", name.c_str(), cmd.summary.c_str());
    std::fprintf(f, "\n`msgs <command> --help` describes a command's options.\n");
  };
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  auto it = reg.find(name);
  if (it == reg.end()) {
    std::fprintf(stderr, "msgs: unknown command '%s'\n\n", name.c_str());
    usage(stderr);
    return 2;
  }
  std::vector<std::string> args(argv + 2, argv + argc);
  try {
    return it->second.run(args);
  } catch (const msgs::cli::UsageError& e) {
    std::fprintf(stderr, "msgs %s: %s (see `msgs %s --help`)\n", name.c_str(), e.what(), name.c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "msgs %s: error: %s\n", name.c_str(), e.what());
    return 1;
  }
}
