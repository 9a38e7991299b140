// `pvcgel`: the command-line tool for PVC gel actuator rigs.
#include <CLI/CLI.hpp>
#include <iostream>

#include "control/config_error.hpp"
#include "tools/bench_command.hpp"
#include "tools/client_commands.hpp"
#include "tools/diagnose_command.hpp"
#include "tools/ident_command.hpp"
#include "tools/record_command.hpp"
#include "tools/serve/serve_command.hpp"
#include "tools/show_command.hpp"

int main(int argc, char** argv) {
  CLI::App app{"pvcgel: identification, diagnosis, benchmarks and rig control for PVC gel actuators"};
  app.require_subcommand(1);
  pvcgel::tools::add_bench_command(app);
  pvcgel::tools::add_show_command(app);
  pvcgel::tools::add_record_command(app);
  pvcgel::tools::add_ident_command(app);
  pvcgel::tools::add_client_commands(app);
  pvcgel::tools::add_diagnose_command(app);
  pvcgel::tools::add_serve_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const pvcgel::control::ConfigError& e) {
    std::cerr << "pvcgel: configuration error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "pvcgel: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
