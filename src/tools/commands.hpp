// SPDX-License-Identifier: LGPL-2.1-or-later
// The subcommands of the `lftag` tool. Each registers itself on the app and, when it
// runs, stores its exit status in `status`.
#pragma once

#include <CLI/CLI.hpp>

namespace lftag::tools {

void add_generate_command(CLI::App& app, int& status);
void add_render_command(CLI::App& app, int& status);
void add_detect_command(CLI::App& app, int& status);

}  // namespace lftag::tools
