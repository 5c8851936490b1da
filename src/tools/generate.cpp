// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag generate: one marker, or a sheet of many, as SVG, PDF or PNG.
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <stdexcept>

#include "commands.hpp"
#include "lftag/render.hpp"

namespace lftag::tools {
namespace {

// "100mm", "10cm", "0.1m", "4in" -> metres. A bare number is refused: read as
// millimetres, "--size 0.1" (meant as metres, like --tag-size) made a 2x2 px marker.
double parse_length(const std::string& text) {
  std::size_t end = 0;
  double value = 0;
  try {
    value = std::stod(text, &end);
  } catch (const std::exception&) {
    throw std::invalid_argument("size '" + text + "' is not a length such as 100mm, 10cm, 0.1m or 4in");
  }
  const std::string unit = text.substr(end);
  double scale = 0;
  if (unit.empty())
    throw std::invalid_argument("size '" + text + "' has no unit: give mm, cm, m or in, such as 100mm or 0.1m");
  if (unit == "mm")
    scale = 0.001;
  else if (unit == "cm")
    scale = 0.01;
  else if (unit == "m")
    scale = 1.0;
  else if (unit == "in")
    scale = 0.0254;
  else
    throw std::invalid_argument("size '" + text + "' has an unknown unit: use mm, cm, m or in");
  if (!(value > 0) || !std::isfinite(value)) throw std::invalid_argument("size '" + text + "' must be positive");
  return value * scale;
}

}  // namespace

void add_generate_command(CLI::App& app, int& status) {
  struct Options {
    std::string family, ids, size = "100mm", output, paper = "a4";
    double margin = 2.0, dpi = 300;
    bool no_caption = false, sheet = false;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd =
      app.add_subcommand("generate", "Write a printable marker (or a sheet of markers) as SVG, PDF or PNG.");
  cmd->add_option("--family", opt->family, "Marker family: 2x2, 3x3, 4x4, 5x5, 6x6, 7x7 or 8x8")->required();
  cmd->add_option("--id", opt->ids,
                  "Marker id, decimal or 0x-hexadecimal; for a sheet a list with ranges, e.g. 0-11,40 or '0-11, 40'")
      ->required();
  cmd->add_option(
         "--size", opt->size,
         "Outer edge of the black border, with its unit (mm, cm, m or in): 100mm, 10cm, 0.1m, 4in (default 100mm)")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            try {
              const double m = parse_length(text);
              return m >= 1e-4 && m <= 100 ? "" : "size '" + text + "' must be from 0.1 mm to 100 m";
            } catch (const std::exception& e) {
              return e.what();
            }
          },
          "LENGTH"));
  cmd->add_option("--margin", opt->margin, "White margin around the border, in marker units (default 2)")
      ->check(finite_in(0, 100));
  cmd->add_option("--dpi", opt->dpi, "PNG resolution in pixels per inch (default 300)")->check(finite_in(1, 10000));
  cmd->add_flag("--no-caption", opt->no_caption, "Leave out the caption (family, id, size) under the marker");
  cmd->add_flag("--sheet", opt->sheet, "Lay the ids out on pages for printing (implied by several ids)");
  cmd->add_option("--paper", opt->paper, "Sheet paper size: a4 or letter (default a4)");
  cmd->add_option("--output,-o", opt->output, "Output file; .svg, .pdf or .png")->required();
  cmd->callback([opt, &status] {
    // A mistake in the options exits 2, as in detect and annotate; a file that cannot be
    // written, 1.
    std::optional<Family> family;
    std::vector<TagId> ids;
    PrintOptions print;
    Paper paper = Paper::a4;
    try {
      family = Family::parse(opt->family);
      ids = parse_id_list(opt->ids);
      for (const TagId& id : ids) family->require(id);
      print.size_m = parse_length(opt->size);
      print.margin_units = opt->margin;
      print.caption = !opt->no_caption;
      print.dpi = opt->dpi;
      paper = parse_paper(opt->paper);
    } catch (const std::exception& e) {
      std::cerr << "lftag generate: " << e.what() << "\n";
      status = 2;
      return;
    }
    try {
      if (opt->sheet || ids.size() > 1) {
        const int pages = write_sheet(opt->output, *family, ids, print, paper);
        std::cerr << "wrote " << ids.size() << " markers on " << pages << " page" << (pages > 1 ? "s" : "") << " to "
                  << opt->output << "\n";
      } else {
        write_marker(opt->output, *family, ids.front(), print);
      }
      status = 0;
    } catch (const std::exception& e) {
      std::cerr << "lftag generate: " << e.what() << "\n";
      status = 1;
    }
  });
}

}  // namespace lftag::tools
