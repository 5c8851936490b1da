// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag: generate printable markers, render synthetic scenes, detect markers in images
// (and, built with GStreamer, annotate videos).
#include <CLI/CLI.hpp>
#include <opencv2/core/utils/logger.hpp>

#include "commands.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "LFTag fiducial markers: print them, render test scenes, detect them in images"
#ifdef LFTAG_WITH_GST
      " and videos"
#endif
      "."};
  app.require_subcommand(1);
  // Our own messages say what went wrong with a file; OpenCV's warnings would repeat it.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  int status = 0;
  lftag::tools::add_generate_command(app, status);
  lftag::tools::add_render_command(app, status);
  lftag::tools::add_detect_command(app, status);
#ifdef LFTAG_WITH_GST
  lftag::tools::add_annotate_command(app, status);
#endif
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help exits 0; every mistake in the options exits 2, whatever CLI11 calls it.
    return app.exit(e) == 0 ? 0 : 2;
  }
  return status;
}
