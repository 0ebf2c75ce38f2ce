// artrace: ray traces virtual objects into recorded RGBD video. One program, many subcommands.
#include "commands.h"

#include "artrace/io/parse_error.h"

#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{"artrace: real-time ray tracing of virtual objects into RGBD recordings"};
  app.require_subcommand(1);
  artrace::tools::add_render_command(app);
  artrace::tools::add_bench_core_command(app);
  artrace::tools::add_bench_dynamic_command(app);
  artrace::tools::add_recording_commands(app);
  artrace::tools::add_bench_occlusion_command(app);
  artrace::tools::add_export_command(app);
  artrace::tools::add_replay_command(app);
  artrace::tools::add_bench_bart_command(app);
  artrace::tools::add_bench_ar_command(app);
  artrace::tools::add_join_command(app);
  artrace::tools::add_batch_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    std::cerr << "artrace: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
