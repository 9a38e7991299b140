// `pvcgel`: the command-line tool for PVC gel actuator rigs.
#include <CLI/CLI.hpp>
#include <iostream>

#include "control/config_error.hpp"
#include "tools/bench_command.hpp"
#include "tools/client_commands.hpp"
#include "tools/diagnose_command.hpp"
#include "tools/exit_codes.hpp"
#include "tools/ident_command.hpp"
#include "tools/record_command.hpp"
#include "tools/serve/serve_command.hpp"
#include "tools/show_command.hpp"

int main(int argc, char** argv) {
  CLI::App app{"pvcgel: identification, diagnosis, benchmarks and rig control for PVC gel actuators"};
  app.require_subcommand(1);
  app.footer(pvcgel::tools::kExitCodeHelp);
  pvcgel::tools::add_bench_command(app);
  pvcgel::tools::add_show_command(app);
  pvcgel::tools::add_record_command(app);
  pvcgel::tools::add_ident_command(app);
  pvcgel::tools::add_client_commands(app);
  pvcgel::tools::add_diagnose_command(app);
  pvcgel::tools::add_serve_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError& e) {
    return e.get_exit_code();  // a subcommand's own code (3, 4, 5), its message already printed
  } catch (const CLI::ParseError& e) {
    // --help and --version are "errors" with code 0; everything else is a usage error.
    const int printed = app.exit(e);
    return printed == 0 ? pvcgel::tools::kExitOk : pvcgel::tools::kExitUsage;
  } catch (const pvcgel::control::ConfigError& e) {
    std::cerr << "pvcgel: configuration error: " << e.what() << "\n";
    return pvcgel::tools::kExitConfiguration;
  } catch (const std::exception& e) {
    std::cerr << "pvcgel: " << e.what() << "\n";
    return pvcgel::tools::kExitFailure;
  }
  return pvcgel::tools::kExitOk;
}
